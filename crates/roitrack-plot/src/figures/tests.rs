//! Tests of the figures: files written, ranges, clipping, decimation, the statistics shown.

use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use roitrack_core::{PoseSample, TwistSample};
use roitrack_eval::{EvalOptions, estimate_errors};

use crate::PlotError;

use super::data::num;
use super::draw::{clipped_paths, decimate};
use super::{TrackSeries, TruthSeries, error_columns, finite_mean, write_figures};

/// A small deterministic normal generator (xorshift + Box–Muller), to avoid a dependency.
struct Noise(u64);
impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// Interval between the estimates of the synthetic runs (s): 400 Hz.
const PERIOD_S: f64 = 1.0 / 400.0;

/// Two laps of a 60 mm circle in the image plane at 0.6 m depth, in 2 s, sampled at 4 kHz.
fn circle_truth() -> TruthSeries {
    let w = std::f64::consts::TAU;
    let r = 0.06;
    let t_s: Vec<f64> = (0..8000).map(|i| i as f64 / 4000.0).collect();
    TruthSeries {
        position_m: t_s
            .iter()
            .map(|t| [r * (w * t).cos(), r * (w * t).sin(), 0.6])
            .collect(),
        velocity_mps: t_s
            .iter()
            .map(|t| [-r * w * (w * t).sin(), r * w * (w * t).cos(), 0.0])
            .collect(),
        t_s,
    }
}

/// The truth's position and velocity at `t`, interpolated linearly and held at the ends: a lagging estimate
/// between the truth's samples.
fn truth_at(truth: &TruthSeries, t: f64) -> ([f64; 3], [f64; 3]) {
    let ts = &truth.t_s;
    let j = ts.partition_point(|&s| s <= t).clamp(1, ts.len() - 1);
    let i = j - 1;
    let a = ((t - ts[i]) / (ts[j] - ts[i])).clamp(0.0, 1.0);
    let lerp = |p: &[f64; 3], q: &[f64; 3]| std::array::from_fn(|c| p[c] + a * (q[c] - p[c]));
    (
        lerp(&truth.position_m[i], &truth.position_m[j]),
        lerp(&truth.velocity_mps[i], &truth.velocity_mps[j]),
    )
}

fn poses(t_s: &[f64], position_m: &[[f64; 3]]) -> Vec<PoseSample> {
    t_s.iter()
        .zip(position_m)
        .map(|(&t_s, p)| PoseSample {
            t_s,
            cam_from_obj: Isometry3::from_parts(
                Translation3::new(p[0], p[1], p[2]),
                UnitQuaternion::identity(),
            ),
        })
        .collect()
}

fn twists(t_s: &[f64], velocity_mps: &[[f64; 3]]) -> Vec<TwistSample> {
    t_s.iter()
        .zip(velocity_mps)
        .map(|(&t_s, v)| TwistSample {
            t_s,
            velocity_mps: Vector3::from(*v),
            angular_velocity_radps: Vector3::zeros(),
        })
        .collect()
}

/// `run` with its errors and metrics from roitrack-eval against `truth`, as a caller gives them; without
/// `twists`, the estimate's twists are withheld, so that the run has no velocity error or lag.
fn scored(truth: &TruthSeries, mut run: TrackSeries, with_twists: bool) -> TrackSeries {
    let opts = EvalOptions::default();
    let truth_twists = twists(&truth.t_s, &truth.velocity_mps);
    let est_twists = twists(&run.t_s, &run.velocity_mps);
    let errors = estimate_errors(
        &poses(&truth.t_s, &truth.position_m),
        Some(&truth_twists),
        &poses(&run.t_s, &run.position_m),
        with_twists.then_some(est_twists.as_slice()),
        &opts,
    )
    .unwrap();
    (run.position_error_m, run.velocity_error_mps) = error_columns(&errors);
    run.metrics = Some(errors.metrics(&opts));
    run.mean_residual_px = finite_mean(&run.residual_rms_px);
    run
}

/// A run at 400 Hz: the truth `lag_s` late, plus noise (position sigma in m, depth 3× larger; velocity sigma),
/// scored against `truth`.
fn run(
    truth: &TruthSeries,
    label: &str,
    lag_s: f64,
    pos_sigma: f64,
    vel_sigma: f64,
    residual: f64,
    seed: u64,
) -> TrackSeries {
    let mut noise = Noise(seed);
    let t_s: Vec<f64> = (0..800).map(|i| i as f64 * PERIOD_S).collect();
    let mut out = TrackSeries {
        label: label.to_string(),
        ..TrackSeries::default()
    };
    for &t in &t_s {
        let (p, v) = truth_at(truth, t - lag_s);
        out.position_m.push([
            p[0] + pos_sigma * noise.normal(),
            p[1] + pos_sigma * noise.normal(),
            p[2] + 3.0 * pos_sigma * noise.normal(),
        ]);
        out.velocity_mps
            .push(std::array::from_fn(|c| v[c] + vel_sigma * noise.normal()));
        out.residual_rms_px
            .push(residual * (1.0 + 0.2 * noise.normal()).abs());
    }
    out.t_s = t_s;
    scored(truth, out, true)
}

fn example_runs(truth: &TruthSeries) -> Vec<TrackSeries> {
    let mut default = run(truth, "kalman (default)", PERIOD_S, 0.0002, 0.01, 0.12, 7);
    // A gap in the estimates must not break the figures (the metrics were computed before it).
    default.position_m[300] = [f64::NAN; 3];
    default.position_error_m[300] = [f64::NAN; 3];
    default.velocity_mps[301][1] = f64::INFINITY;
    default.velocity_error_mps[301][1] = f64::INFINITY;
    default.residual_rms_px[302] = f64::NAN;
    let baseline = run(
        truth,
        "baseline (noisy, 10 ms lag)",
        4.0 * PERIOD_S,
        0.002,
        1.0,
        0.6,
        11,
    );
    vec![default, baseline]
}

#[test]
fn mean_residual_skips_non_finite_values() {
    assert_eq!(finite_mean(&[1.0, f64::NAN, 3.0, f64::INFINITY]), Some(2.0));
    assert_eq!(finite_mean(&[f64::NAN]), None);
    assert_eq!(finite_mean(&[]), None);
}

#[test]
fn figure_7_shows_the_velocity_lag_of_eval() {
    let truth = circle_truth();
    let lagging = run(&truth, "lagging", 2.0 * PERIOD_S, 0.0, 0.0, 0.1, 3);
    let metrics = lagging.metrics.clone().unwrap();
    assert_eq!(metrics.velocity_lag_samples, Some(2), "{metrics:?}");
    let subsample = metrics.velocity_lag_subsample.unwrap();
    let mut no_twists = run(&truth, "no twists", 0.0, 0.0002, 0.01, 0.1, 5);
    no_twists.velocity_error_mps.clear();
    let no_twists = scored(&truth, no_twists, false);
    assert!(no_twists.velocity_error_mps.is_empty());
    assert_eq!(
        no_twists.metrics.as_ref().unwrap().velocity_lag_samples,
        None
    );

    let dir = tempfile::tempdir().unwrap();
    write_figures(dir.path(), "circle", &truth, &[lagging, no_twists]).unwrap();
    let fig7 = std::fs::read_to_string(dir.path().join("fig7_velocity.svg")).unwrap();
    let shown = format!("velocity lag: 2 samples (5.0 ms; sub-sample {subsample:.2})");
    assert!(fig7.contains(&shown), "fig7 lacks '{shown}'");
    assert!(fig7.contains("velocity lag: n/a"));
    assert!(fig7.contains(&format!("lagging  ({} estimates)", metrics.count)));
}

#[test]
fn polylines_are_split_at_gaps_and_clipped() {
    let xs = [0.0, 1.0, 2.0, 3.0, f64::NAN, 5.0, 6.0];
    let ys = [0.0, 0.0, 10.0, 0.0, 0.0, 0.0, 0.0];
    let paths = clipped_paths(&xs, &ys, (-1.0, 10.0), (-1.0, 1.0));
    // 0→1→(1.1, 1) | (2.9, 1)→3 | 5→6
    assert_eq!(paths.len(), 3);
    assert_eq!(paths[0].len(), 3);
    assert!((paths[0][2].0 - 1.1).abs() < 1e-12 && paths[0][2].1 == 1.0);
    assert!((paths[1][0].0 - 2.9).abs() < 1e-12);
    assert_eq!(paths[2], vec![(5.0, 0.0), (6.0, 0.0)]);
}

#[test]
fn decimation_keeps_the_envelope() {
    let path: Vec<(f64, f64)> = (0..1000)
        .map(|i| (i as f64, if i == 437 { 50.0 } else { (i % 7) as f64 }))
        .collect();
    let out = decimate(path, 20);
    assert!(out.len() <= 102);
    assert!(out.iter().any(|p| p.1 == 50.0));
    assert_eq!(out[0], (0.0, 0.0));
    assert_eq!(out.last().unwrap().0, 999.0);
}

#[test]
fn writes_the_three_figures() {
    let truth = circle_truth();
    let runs = example_runs(&truth);
    let dir = tempfile::tempdir().unwrap();
    let paths = write_figures(dir.path(), "circle", &truth, &runs).unwrap();
    assert_eq!(paths.len(), 6);
    let titles = [
        ("fig5_trajectory", "Fig. 5", "(c) y–z: side view"),
        ("fig6_position", "Fig. 6", "(d) Image residual"),
        ("fig7_velocity", "Fig. 7", "(d) Error statistics"),
    ];
    for (stem, title, panel) in titles {
        let png = dir.path().join(format!("{stem}.png"));
        let svg = dir.path().join(format!("{stem}.svg"));
        assert!(paths.contains(&png) && paths.contains(&svg));
        let len = std::fs::metadata(&png).unwrap().len();
        assert!(len > 20_000, "{stem}.png is {len} bytes");
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.contains("<svg"), "{stem}.svg");
        assert!(
            text.contains(title) && text.contains(panel),
            "{stem}.svg lacks its titles"
        );
        assert!(
            text.contains("kalman (default)"),
            "{stem}.svg lacks the run legend"
        );
    }
    // The numbers shown are eval's.
    let m = runs[0].metrics.as_ref().unwrap();
    let fig5 = std::fs::read_to_string(dir.path().join("fig5_trajectory.svg")).unwrap();
    assert!(fig5.contains(&format!(
        "kalman (default) (3-D position RMS error {} mm)",
        num(m.position_rmse_mm)
    )));
    let fig6 = std::fs::read_to_string(dir.path().join("fig6_position.svg")).unwrap();
    assert!(fig6.contains(&format!("3-D {} mm)", num(m.position_rmse_mm))));
    // The noisy baseline's velocity swamps the error axes unless they are clipped.
    let fig7 = std::fs::read_to_string(dir.path().join("fig7_velocity.svg")).unwrap();
    assert!(fig7.contains("points off-scale"));
    assert!(fig7.contains(&format!("3-D {} mm/s)", num(m.velocity_rmse_mm_s.unwrap()))));
    // Keep a copy to look at when asked to.
    if let Some(keep) = std::env::var_os("ROITRACK_PLOT_KEEP") {
        write_figures(Path::new(&keep), "circle", &truth, &runs).unwrap();
    }
}

#[test]
fn draws_tiny_and_static_input() {
    let dir = tempfile::tempdir().unwrap();
    let truth = TruthSeries {
        t_s: vec![0.0, 1.0],
        position_m: vec![[0.0, 0.0, 0.5]; 2],
        velocity_mps: vec![[0.0; 3]; 2],
    };
    let one = TrackSeries {
        label: "one estimate, no residual".into(),
        t_s: vec![0.5],
        position_m: vec![[0.001, 0.0, 0.5]],
        velocity_mps: vec![[0.0; 3]],
        ..TrackSeries::default()
    };
    let one = scored(&truth, one, true);
    assert_eq!(one.metrics.as_ref().unwrap().count, 1);
    assert_eq!(one.mean_residual_px, None);
    let unscored = TrackSeries {
        label: "no metrics".into(),
        metrics: None,
        ..one.clone()
    };
    let runs = [one, unscored];
    let paths = write_figures(dir.path(), "static", &truth, &runs).unwrap();
    assert!(paths.iter().all(|p| p.exists()));
    if let Some(keep) = std::env::var_os("ROITRACK_PLOT_KEEP") {
        write_figures(&Path::new(&keep).join("static"), "static", &truth, &runs).unwrap();
    }
}

#[test]
fn refuses_empty_and_inconsistent_input() {
    let dir = tempfile::tempdir().unwrap();
    let truth = circle_truth();
    assert!(matches!(
        write_figures(dir.path(), "s", &truth, &[]),
        Err(PlotError::Empty { .. })
    ));
    assert!(matches!(
        write_figures(
            dir.path(),
            "s",
            &TruthSeries::default(),
            &example_runs(&truth)
        ),
        Err(PlotError::Empty { .. })
    ));
    let nan_run = TrackSeries {
        label: "nan".into(),
        t_s: vec![0.0, 0.1],
        position_m: vec![[f64::NAN; 3]; 2],
        velocity_mps: vec![[0.0; 3]; 2],
        position_error_m: vec![[f64::NAN; 3]; 2],
        ..TrackSeries::default()
    };
    assert!(matches!(
        write_figures(dir.path(), "s", &truth, &[nan_run]),
        Err(PlotError::Empty { .. })
    ));
    let good = example_runs(&truth).remove(0);
    let broken: [fn(&mut TrackSeries); 5] = [
        |r| {
            r.velocity_mps.pop();
        },
        |r| {
            r.position_error_m.pop();
        },
        |r| r.position_error_m.clear(),
        |r| {
            r.velocity_error_mps.pop();
        },
        |r| r.metrics.as_mut().unwrap().count += 1,
    ];
    for (k, breaking) in broken.iter().enumerate() {
        let mut run = good.clone();
        breaking(&mut run);
        assert!(
            matches!(
                write_figures(dir.path(), "s", &truth, &[run]),
                Err(PlotError::Invalid { .. })
            ),
            "case {k}"
        );
    }
    // Velocity errors may be absent (no twists), and so may the metrics.
    let mut without = good.clone();
    without.velocity_error_mps.clear();
    without.metrics = None;
    assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
    write_figures(&dir.path().join("ok"), "s", &truth, &[without]).unwrap();
}
