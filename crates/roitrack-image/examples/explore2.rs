use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::*;

/// Centroid over pixels > bg + f * (peak - bg), weighted by (v - bg - g * (peak - bg)).
fn centroid(px: &[u16], w: usize, f: f64, g: f64, dilate: bool) -> (f64, f64) {
    let h = px.len() / w;
    let mut border = 0.0;
    let mut nb = 0.0;
    for j in 0..h {
        for i in 0..w {
            if i == 0 || j == 0 || i == w - 1 || j == h - 1 {
                border += px[j * w + i] as f64;
                nb += 1.0;
            }
        }
    }
    let bg = border / nb;
    let peak = *px.iter().max().unwrap() as f64;
    let thr = bg + f * (peak - bg);
    let sub = bg + g * (peak - bg);
    let inside = |i: usize, j: usize| px[j * w + i] as f64 > thr;
    let (mut s, mut si, mut sj) = (0.0, 0.0, 0.0);
    for j in 1..h - 1 {
        for i in 1..w - 1 {
            let ok = if dilate {
                (j - 1..=j + 1).any(|jj| (i - 1..=i + 1).any(|ii| inside(ii, jj)))
            } else {
                inside(i, j)
            };
            if ok {
                let wgt = px[j * w + i] as f64 - sub;
                s += wgt;
                si += wgt * i as f64;
                sj += wgt * j as f64;
            }
        }
    }
    (si / s, sj / s)
}

fn main() {
    let camera = CameraModel::canonical();
    let target = Target::grid4x4();
    for (sname, sensor) in [
        ("noiseless", SensorModel::noiseless()),
        ("noisy", SensorModel::default()),
        (
            "dim",
            SensorModel {
                blob_signal_e: 1000.0,
                ..SensorModel::default()
            },
        ),
        (
            "12bit",
            SensorModel {
                bit_depth: 12,
                ..SensorModel::default()
            },
        ),
    ] {
        let r = RoiRenderer::new(camera.clone(), target.clone(), sensor).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let variants = [
            ("f.05 g.05", 0.05, 0.05, false),
            ("f.1 g.1", 0.1, 0.1, false),
            ("f.15 g.15", 0.15, 0.15, false),
            ("f.2 g.2", 0.2, 0.2, false),
            ("f.25 g.25", 0.25, 0.25, false),
            ("f.3 g.3", 0.3, 0.3, false),
            ("f.15 g0", 0.15, 0.0, false),
            ("f.5 g0 dil", 0.5, 0.0, true),
        ];
        let mut stats = vec![(0.0f64, 0.0f64); variants.len()];
        let n = 400;
        for k in 0..n {
            let dx = k as f64 / n as f64 * 0.0008;
            let mut s = bench_state();
            s.cam_t_obj_m += Vector3::new(dx, 0.37 * dx, 0.0);
            let st = |_t: f64| -> MotionState { s };
            let idx = 5;
            let e = r.disk_image_centre_px(&s, idx).unwrap();
            let roi = Roi::centred(e.x, e.y, 32, 1024, 1024).unwrap();
            let mut out = vec![0u16; roi.len()];
            r.render_roi(&st, &roi, 0.0, &mut rng, &mut out);
            for (o, &(_, f, g, d)) in variants.iter().enumerate() {
                let c = centroid(&out, 32, f, g, d);
                let (du, dv) = (c.0 + roi.x0 as f64 - e.x, c.1 + roi.y0 as f64 - e.y);
                stats[o].0 = stats[o].0.max(du.abs().max(dv.abs()));
                stats[o].1 += du * du + dv * dv;
            }
        }
        for (o, (name, ..)) in variants.iter().enumerate() {
            println!(
                "{sname} {name}: max {:.4} rms {:.4}",
                stats[o].0,
                (stats[o].1 / n as f64).sqrt()
            );
        }
    }
}
