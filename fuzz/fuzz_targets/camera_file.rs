//! The camera file reader (every format, recognised by content) on arbitrary bytes: an `Ok` or an error naming the
//! file, never a panic or a hang. The first byte picks the options (image size given or not, a Kalibr camera name).
#![no_main]
use libfuzzer_sys::fuzz_target;
use roitrack_formats::CameraFileOptions;

fuzz_target!(|data: &[u8]| {
    let (options, rest) = match data.split_first() {
        Some((&b, rest)) => (
            CameraFileOptions {
                image_size: (b & 1 == 1).then_some((640, 480)),
                camera_name: (b & 2 == 2).then(|| "cam1".to_string()),
            },
            rest,
        ),
        None => (CameraFileOptions::default(), data),
    };
    let text = String::from_utf8_lossy(rest);
    if let Err(e) = roitrack_formats::parse_camera_file(&text, "c.cam", &options) {
        assert!(e.to_string().starts_with("c.cam"), "{e}");
    }
});
