use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::*;
use std::time::Instant;

fn main() {
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    for ss in [1u32, 2, 3, 4, 8, 16, 32] {
        let sensor = SensorModel {
            supersampling: ss,
            bit_depth: 16,
            ..SensorModel::noiseless()
        };
        let r = RoiRenderer::new(camera.clone(), target.clone(), sensor).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let opts = CentroidOptions {
            threshold: Threshold::Fixed((0.0925 * sensor.max_dn() as f64) as u16),
            ..Default::default()
        };
        let (mut maxe, mut sq, mut area_sum) = (0.0f64, 0.0, 0.0);
        let n = 400;
        let start = Instant::now();
        for k in 0..n {
            let dx = k as f64 / n as f64 * 0.0008;
            let mut s = bench_state();
            s.cam_t_obj_m += Vector3::new(dx, 0.37 * dx, 0.0);
            let st = |_t: f64| -> MotionState { s };
            let e = r.disk_image_centre_px(&s, 5).unwrap();
            let roi = Roi::centred(e.x, e.y, 32, 1024, 1024).unwrap();
            let mut out = vec![0u16; roi.len()];
            r.render_roi(&st, &roi, 0.0, &mut rng, &mut out);
            let c = measure_blob(&out, &roi, &opts).unwrap();
            let (du, dv) = (c.u_px - e.x, c.v_px - e.y);
            maxe = maxe.max(du.abs().max(dv.abs()));
            sq += du * du + dv * dv;
            area_sum += c.sum;
        }
        println!(
            "ss {ss}: 16-bit noiseless low-threshold: max {:.5} rms {:.5} mean sum {:.1} [{:.1} us/roi]",
            maxe,
            (sq / n as f64).sqrt(),
            area_sum / n as f64,
            start.elapsed().as_secs_f64() * 1e6 / n as f64
        );
    }
}
