//! Steady-state ROI rendering (with a kept `RenderScratch`) and blob measurement allocate nothing (counted through a
//! counting global allocator, per thread: the test harness's own thread may allocate meanwhile).

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::{CentroidOptions, Roi, measure_blob};
use roitrack_sim::{RenderScratch, RoiRenderer, SensorModel};
use roitrack_testkit::alloc::{CountingAllocator, allocations_on_this_thread as allocations};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn steady_state_rendering_and_measuring_do_not_allocate() {
    let target = Target::grid4x4();
    let renderer = RoiRenderer::new(
        CameraModel::canonical(),
        target.clone(),
        SensorModel::default(),
    )
    .unwrap();
    let state = MotionState {
        velocity_mps: Vector3::new(0.8, -0.4, 0.1),
        angular_velocity_radps: Vector3::new(1.0, -2.0, 0.5),
        ..MotionState::bench()
    };
    let state_at = |t: f64| state.predicted(t);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut scratch = RenderScratch::new();
    let mut pixels = vec![0u16; 24 * 24];
    let opts = CentroidOptions::default();
    let run = |rng: &mut ChaCha8Rng, scratch: &mut RenderScratch, pixels: &mut [u16]| {
        let mut measured = 0;
        for (k, point) in target.points().iter().enumerate() {
            let t_s = k as f64 * 250e-6;
            let p = state.point_in_cam_at(&point.point_in_obj_m, t_s);
            let c = renderer.camera().raw_pixel_from_cam(&p).unwrap();
            let roi = Roi::centred(c.x, c.y, 24, 1024, 1024).unwrap();
            renderer.render_roi_with_scratch(&state_at, &roi, t_s, rng, scratch, pixels);
            measured += usize::from(measure_blob(pixels, &roi, &opts).is_ok());
        }
        measured
    };
    // Warm-up: the scratch buffers grow to their working size.
    run(&mut rng, &mut scratch, &mut pixels);
    let before = allocations();
    let mut measured = 0;
    for _ in 0..20 {
        measured += run(&mut rng, &mut scratch, &mut pixels);
    }
    assert_eq!(allocations() - before, 0);
    // The counter does see this thread's allocations.
    let before = allocations();
    let heap = std::hint::black_box(vec![0u8; 100]);
    assert!(allocations() > before && heap.len() == 100);
    // All but the key blob (too big for 24 px).
    assert_eq!(measured, 20 * 15);
}
