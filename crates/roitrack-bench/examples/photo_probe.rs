use nalgebra::{Rotation3, Vector3};
use roitrack_core::camera::{PinholeIntrinsics, PlumbBob};
use roitrack_core::target::{CircleGrid, GridLayout};
use roitrack_core::{CameraModel, Target};
use roitrack_image::{PhotoScratch, Polarity, detect_photo_blobs};
use roitrack_pipeline::photo::{PhotoOptions, PolarityChoice, detect_target};
use roitrack_sim::photo::{PhotoScene, render_photo};
fn main() {
    let intrinsics = PinholeIntrinsics {
        fx_px: 620.0,
        fy_px: 620.0,
        skew_px: 0.0,
        cx_px: 319.5,
        cy_px: 239.5,
    };
    let distortion = PlumbBob::from_coefficients([-0.12, 0.05, 0.0, 0.0, 0.0]);
    let camera = CameraModel::new("bench 640x480", 640, 480, intrinsics, distortion).unwrap();
    let grid = CircleGrid {
        rows: 8,
        cols: 10,
        spacing_m: 0.025,
        diameter_m: 0.015,
        layout: GridLayout::Square,
    };
    let target = Target::circle_grid(&grid).unwrap();
    let tilt = Rotation3::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians());
    let scene = PhotoScene::facing(camera.clone(), target.clone(), 0.45, tilt)
        .harsh()
        .with_seed(7);
    let frame = render_photo(&scene).unwrap().frame;
    let mut scratch = PhotoScratch::default();
    let mut results = Vec::new();
    for threads in [1usize, 2] {
        let mut dark = PhotoOptions {
            polarity: PolarityChoice::Dark,
            ..PhotoOptions::default()
        };
        dark.blobs.threads = threads;
        let mut auto = PhotoOptions::default();
        auto.blobs.threads = threads;
        let mut best = [f64::INFINITY; 3];
        for _ in 0..60 {
            for (k, best) in best.iter_mut().enumerate() {
                let t = std::time::Instant::now();
                for _ in 0..4 {
                    match k {
                        0 => {
                            std::hint::black_box(detect_photo_blobs(
                                &frame.pixels,
                                frame.width,
                                frame.height,
                                frame.bit_depth,
                                Polarity::Dark,
                                &dark.blobs,
                                &mut scratch,
                            ));
                        }
                        1 => {
                            std::hint::black_box(
                                detect_target(&camera, &target, &frame, &dark).unwrap(),
                            );
                        }
                        _ => {
                            std::hint::black_box(
                                detect_target(&camera, &target, &frame, &auto).unwrap(),
                            );
                        }
                    }
                }
                *best = best.min(t.elapsed().as_secs_f64() / 4.0 * 1e3);
            }
        }
        println!(
            "threads {threads}: min ms: blobs {:.3} dark {:.3} auto {:.3}",
            best[0], best[1], best[2]
        );
        results.push(detect_target(&camera, &target, &frame, &dark).unwrap());
    }
    assert_eq!(results[0], results[1]);
}
