//! Every kind of camera file read (tests/data/cameras: OpenCV's files written by OpenCV 4 and 5 themselves, ROS and
//! Kalibr files as their tools write them), each camera projecting like OpenCV (roitrack-core's
//! tests/data/opencv_projections.csv), and the errors of each reader naming the file and the field.

use std::path::PathBuf;

use nalgebra::{Vector2, Vector3};
use roitrack_core::CameraModel;
use roitrack_formats::{CameraFileFormat, CameraFileOptions, parse_camera_file, read_camera_file};

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/cameras")
        .join(name)
}

/// OpenCV's projections of the camera with these parameters: (point in the camera frame, raw pixel).
fn opencv_projections(camera: &CameraModel) -> Vec<(Vector3<f64>, Vector2<f64>)> {
    let text = include_str!("../../roitrack-core/tests/data/opencv_projections.csv");
    let k = &camera.intrinsics;
    let mut out = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let n = |i: usize| f[i].parse::<f64>().unwrap();
        let coefficients: Vec<f64> = f[6]
            .split_whitespace()
            .map(|c| c.parse().unwrap())
            .collect();
        let mut ours = camera.distortion.coefficients();
        // A 4-coefficient plumb_bob file is read as 5 with k3 = 0.
        if f[0] == "plumb_bob" && coefficients.len() == 4 && ours.len() == 5 && ours[4] == 0.0 {
            ours.truncate(4);
        }
        if f[0] == camera.distortion.model_name()
            && (n(1), n(2), n(3), n(4), n(5)) == (k.fx_px, k.fy_px, k.skew_px, k.cx_px, k.cy_px)
            && coefficients == ours
        {
            out.push((Vector3::new(n(7), n(8), n(9)), Vector2::new(n(10), n(11))));
        }
    }
    out
}

fn assert_projects_like_opencv(camera: &CameraModel, file: &str) {
    let rows = opencv_projections(camera);
    assert!(
        rows.len() >= 60,
        "{file}: {} OpenCV rows for {camera:?}",
        rows.len()
    );
    for (p, opencv_px) in rows {
        let px = camera.raw_pixel_from_cam(&p).unwrap();
        assert!(
            (px - opencv_px).norm() < 1e-9,
            "{file}: {p:?} -> {px:?}, OpenCV {opencv_px:?}"
        );
    }
}

/// A file, the options it is read with, the format and model it has, its image size.
type Case = (
    &'static str,
    CameraFileOptions,
    CameraFileFormat,
    &'static str,
    (u32, u32),
);

#[test]
fn every_format_and_model_reads_and_projects_like_opencv() {
    let wxh = |w, h| CameraFileOptions {
        image_size: Some((w, h)),
        camera_name: None,
    };
    let cam1 = CameraFileOptions {
        image_size: None,
        camera_name: Some("cam1".to_string()),
    };
    let none = CameraFileOptions::default();
    let cases: Vec<Case> = vec![
        (
            "ros2_topic_echo.yaml",
            none.clone(),
            CameraFileFormat::RosMessage,
            "rational_polynomial",
            (1280, 1024),
        ),
        (
            "ros1_rostopic_echo.yaml",
            none.clone(),
            CameraFileFormat::RosMessage,
            "plumb_bob",
            (1024, 1024),
        ),
        (
            "ros_camera_info_equidistant.yaml",
            none.clone(),
            CameraFileFormat::RosYaml,
            "equidistant",
            (848, 800),
        ),
        (
            "kalibr_camchain.yaml",
            none.clone(),
            CameraFileFormat::Kalibr,
            "plumb_bob",
            (640, 480),
        ),
        (
            "kalibr_camchain.yaml",
            cam1,
            CameraFileFormat::Kalibr,
            "equidistant",
            (848, 800),
        ),
        (
            "opencv4_calibration.yaml",
            none.clone(),
            CameraFileFormat::OpenCvYaml,
            "plumb_bob",
            (640, 480),
        ),
        (
            "opencv5_calibration.yaml",
            none.clone(),
            CameraFileFormat::OpenCvYaml,
            "plumb_bob",
            (640, 480),
        ),
        (
            "opencv4_calibration.xml",
            none.clone(),
            CameraFileFormat::OpenCvXml,
            "plumb_bob",
            (640, 480),
        ),
        (
            "opencv5_calibration.xml",
            none.clone(),
            CameraFileFormat::OpenCvXml,
            "plumb_bob",
            (640, 480),
        ),
        (
            "opencv4_rational.yaml",
            none.clone(),
            CameraFileFormat::OpenCvYaml,
            "rational_polynomial",
            (1280, 1024),
        ),
        (
            "opencv5_rational.xml",
            none.clone(),
            CameraFileFormat::OpenCvXml,
            "rational_polynomial",
            (1280, 1024),
        ),
        (
            "opencv4_fisheye.yaml",
            wxh(1280, 960),
            CameraFileFormat::OpenCvYaml,
            "equidistant",
            (1280, 960),
        ),
        (
            "opencv5_fisheye.yaml",
            wxh(1280, 960),
            CameraFileFormat::OpenCvYaml,
            "equidistant",
            (1280, 960),
        ),
        (
            "opencv4_fisheye.xml",
            wxh(1280, 960),
            CameraFileFormat::OpenCvXml,
            "equidistant",
            (1280, 960),
        ),
        (
            "opencv5_fisheye.xml",
            wxh(1280, 960),
            CameraFileFormat::OpenCvXml,
            "equidistant",
            (1280, 960),
        ),
    ];
    for (file, options, format, model, size) in cases {
        let path = data(file);
        let text = std::fs::read_to_string(&path).unwrap();
        let (camera, found) = parse_camera_file(&text, &path, &options).unwrap();
        assert_eq!(found, format, "{file}");
        assert_eq!(camera.distortion.model_name(), model, "{file}");
        assert_eq!((camera.width_px, camera.height_px), size, "{file}");
        assert_eq!(read_camera_file(&path, &options).unwrap(), camera, "{file}");
        assert_projects_like_opencv(&camera, file);
    }
    // The names: the frame of a message, the key of a camchain, the stem of an OpenCV file.
    let name = |file: &str| {
        read_camera_file(data(file), &CameraFileOptions::default())
            .unwrap()
            .name
    };
    assert_eq!(name("ros2_topic_echo.yaml"), "camera_optical_frame");
    assert_eq!(name("kalibr_camchain.yaml"), "cam0");
    assert_eq!(name("opencv4_calibration.yaml"), "opencv4_calibration");
}

fn err(text: &str, options: &CameraFileOptions) -> String {
    parse_camera_file(text, "cam.yaml", options)
        .unwrap_err()
        .to_string()
}

#[test]
fn errors_name_the_file_and_the_field() {
    let none = CameraFileOptions::default();
    let opencv = std::fs::read_to_string(data("opencv4_calibration.yaml")).unwrap();
    let fisheye = std::fs::read_to_string(data("opencv4_fisheye.yaml")).unwrap();
    let kalibr = std::fs::read_to_string(data("kalibr_camchain.yaml")).unwrap();
    let echo = std::fs::read_to_string(data("ros2_topic_echo.yaml")).unwrap();
    let xml = std::fs::read_to_string(data("opencv5_calibration.xml")).unwrap();
    let cases: Vec<(String, CameraFileOptions, &str)> = vec![
        // OpenCV: no image size, and the way past; a size that contradicts the file's.
        (
            fisheye.clone(),
            none.clone(),
            "cam.yaml: field 'image_width': missing: give the image size with --image-size WxH",
        ),
        (
            opencv.clone(),
            CameraFileOptions {
                image_size: Some((1280, 960)),
                camera_name: None,
            },
            "cam.yaml: field 'image_width': the file says 640x480 px, --image-size says 1280x960",
        ),
        // Four coefficients without a model are ambiguous.
        (
            fisheye.replace("distortion_model: equidistant\n", ""),
            CameraFileOptions {
                image_size: Some((1280, 960)),
                camera_name: None,
            },
            "cam.yaml: field 'D': 4 coefficients could be plumb_bob",
        ),
        (
            opencv.replace("   rows: 3\n   cols: 3", "   rows: 3\n   cols: 2"),
            none.clone(),
            "cam.yaml: field 'camera_matrix': rows x cols = 3 x 2",
        ),
        (
            opencv.replace("data: [ 812.5,", "data: [ -812.5,"),
            none.clone(),
            "cam.yaml: field 'camera_matrix[0]': fx must be positive",
        ),
        (
            opencv.replace("0., 0., 1. ]", "0., 0., 2. ]"),
            none.clone(),
            "cam.yaml: field 'camera_matrix[8]': must be 1",
        ),
        (
            opencv
                .replace("   cols: 5", "   cols: 6")
                .replace("0.01 ]", "0.01, 0.3 ]"),
            none.clone(),
            "cam.yaml: field 'distortion_coefficients': OpenCV's distortion vectors have 4, 5, 8, 12 or 14",
        ),
        (
            xml.replace(
                "<image_width>640</image_width>",
                "<image_width>wide</image_width>",
            ),
            none.clone(),
            "cam.yaml: field 'image_width': expected a positive image size",
        ),
        (
            xml.replace("</camera_matrix>", ""),
            none.clone(),
            "cam.yaml:",
        ),
        // Kalibr: a camera that is not there, a model roitrack does not have.
        (
            kalibr.clone(),
            CameraFileOptions {
                image_size: None,
                camera_name: Some("cam2".to_string()),
            },
            "cam.yaml: field 'cam2': no such camera in the camchain (it has cam0, cam1)",
        ),
        (
            kalibr.replace(
                "camera_model: pinhole\n  distortion_coeffs: [-0.12",
                "camera_model: omni\n  distortion_coeffs: [-0.12",
            ),
            none.clone(),
            "cam.yaml: field 'cam0.camera_model': unsupported camera model \"omni\"",
        ),
        (
            kalibr.replace("distortion_model: radtan", "distortion_model: fov"),
            none.clone(),
            "cam.yaml: field 'cam0.distortion_model': unsupported distortion model \"fov\"",
        ),
        (
            kalibr.replace(
                "intrinsics: [812.5, 810.25, 320.5, 241.75]",
                "intrinsics: [812.5, 810.25, 320.5]",
            ),
            none.clone(),
            "cam.yaml: field 'cam0.intrinsics': expected 4 numbers",
        ),
        // A camera_info message.
        (
            echo.replace(
                "distortion_model: rational_polynomial",
                "distortion_model: plumb_bob",
            ),
            none.clone(),
            "cam.yaml: field 'd': plumb_bob takes 4 or 5 numbers",
        ),
        (
            echo.replacen("- 1210.0", "- .nan", 1),
            none.clone(),
            "cam.yaml: field 'k[0]': must be a finite number",
        ),
        (
            echo.replace("width: 1280", "width: 0"),
            none.clone(),
            "cam.yaml: field 'width': expected a positive image size",
        ),
        // --camera-name is for camchains only; unknown content is named as such.
        (
            echo.clone(),
            CameraFileOptions {
                image_size: None,
                camera_name: Some("cam0".to_string()),
            },
            "cam.yaml: --camera-name picks a camera of a Kalibr camchain",
        ),
        (
            "a: 1\nb: 2\n".to_string(),
            none.clone(),
            "cam.yaml: not a camera file roitrack knows",
        ),
        ("".to_string(), none.clone(), "cam.yaml: empty file"),
        ("k: [1, 2\n".to_string(), none.clone(), "cam.yaml:"),
    ];
    for (text, options, want) in cases {
        let e = err(&text, &options);
        assert!(e.starts_with(want), "got:  {e}\nwant: {want}");
    }
}

/// Every file above mutated byte by byte and truncated anywhere: an `Ok` or an error naming the file, never a panic.
#[test]
fn mutated_and_truncated_files_never_panic() {
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        state.wrapping_mul(0x2545_f491_4f6c_dd1d)
    };
    const INTERESTING: &[u8] = b",.:-+eE0123456789 \t\n\r#[]{}<>/!?&;'\"\\_naNIf%";
    let options = [
        CameraFileOptions::default(),
        CameraFileOptions {
            image_size: Some((640, 480)),
            camera_name: None,
        },
    ];
    let mut count = 0;
    for entry in std::fs::read_dir(data("")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "py") {
            continue;
        }
        let valid = std::fs::read(&path).unwrap();
        let mut inputs: Vec<Vec<u8>> = (0..=valid.len())
            .step_by(7)
            .map(|n| valid[..n].to_vec())
            .collect();
        for _ in 0..300 {
            let mut bytes = valid.clone();
            for _ in 0..1 + next() % 3 {
                let at = (next() % bytes.len() as u64) as usize;
                let b = INTERESTING[(next() % INTERESTING.len() as u64) as usize];
                match next() % 3 {
                    0 => bytes[at] = b,
                    1 => bytes.insert(at, b),
                    _ => {
                        bytes.remove(at);
                    }
                }
            }
            inputs.push(bytes);
        }
        for bytes in inputs {
            let text = String::from_utf8_lossy(&bytes);
            for o in &options {
                if let Err(e) = parse_camera_file(&text, "c.yaml", o) {
                    assert!(e.to_string().starts_with("c.yaml"), "{e}");
                }
                count += 1;
            }
        }
    }
    assert!(count > 10_000, "{count}");
}
