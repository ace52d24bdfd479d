use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::*;
use std::hint::black_box;

fn main() {
    let what = std::env::args().nth(1).unwrap_or_default();
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    let renderer =
        RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut scratch = RenderScratch::new();
    let state = MotionState {
        velocity_mps: Vector3::new(
            if std::env::args().nth(2).is_some() {
                1.0
            } else {
                0.0
            },
            0.0,
            0.0,
        ),
        ..bench_state()
    };
    let state_at = |t: f64| state.predicted(t);
    let p = state.point_in_cam_at(&target.points()[5].point_in_obj_m, 0.0);
    let c = camera.raw_pixel_from_cam(&p).unwrap();
    let roi = Roi::centred(c.x, c.y, 24, 1024, 1024).unwrap();
    let mut out = vec![0u16; roi.len()];
    renderer.render_roi_with_scratch(&state_at, &roi, 0.0, &mut rng, &mut scratch, &mut out);
    if what == "render" {
        for _ in 0..std::env::var("N").map_or(20000, |n| n.parse().unwrap()) {
            renderer.render_roi_with_scratch(
                &state_at,
                &roi,
                0.0,
                &mut rng,
                &mut scratch,
                &mut out,
            );
        }
    } else {
        let opts = CentroidOptions::default();
        for _ in 0..5_000_000 {
            black_box(measure_blob(black_box(&out), &roi, &opts).ok());
        }
    }
}
