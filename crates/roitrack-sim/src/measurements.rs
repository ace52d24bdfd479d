//! The measurement-level simulator: sequential ROI centroids with their own timestamps, plus ground truth.

use nalgebra::Vector2;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_core::{CameraModel, Measurement, PoseSample, RoiOrder, Target, TwistSample};
use thiserror::Error;

use crate::Scenario;

/// How to sample a scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationOptions {
    /// Seed of every random choice (noise, drops, outliers, random order).
    pub seed: u64,
    /// Standard deviation of the centroid noise, per image axis (px). SPEC section 6: 0.1 px.
    pub noise_px: f64,
    /// ROI rate (Hz): sample k is taken at t = k / rate, its exposure midpoint. SPEC: 4 kHz.
    pub rate_hz: f64,
    pub order: RoiOrder,
    /// Fraction of ROIs whose measurement is lost, in [0, 1).
    pub drop_fraction: f64,
    /// Fraction of measurements moved 5-20 px in a random direction, in [0, 1].
    pub outlier_fraction: f64,
}

impl Default for SimulationOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            noise_px: 0.1,
            rate_hz: 4000.0,
            order: RoiOrder::BitReversed,
            drop_fraction: 0.0,
            outlier_fraction: 0.0,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Error)]
pub enum SimError {
    #[error("{field} must be {expected}, got {value}")]
    BadOption {
        field: &'static str,
        expected: &'static str,
        value: f64,
    },
    #[error("point id {id} leaves the image at t = {t_s} s (raw pixel {u_px:.1}, {v_px:.1})")]
    BlobOffImage {
        id: u32,
        t_s: f64,
        u_px: f64,
        v_px: f64,
    },
}

/// A simulated acquisition: what the camera measured and what really happened.
#[derive(Debug, Clone)]
pub struct SimulatedRun {
    pub camera: CameraModel,
    pub target: Target,
    /// In time order; dropped ROIs are absent.
    pub measurements: Vec<Measurement>,
    /// Ground truth at every ROI time (dropped or not).
    pub truth_poses: Vec<PoseSample>,
    pub truth_twists: Vec<TwistSample>,
}

fn check_option(
    field: &'static str,
    value: f64,
    expected: &'static str,
    ok: bool,
) -> Result<(), SimError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(SimError::BadOption {
            field,
            expected,
            value,
        })
    }
}

/// Samples `scenario` one ROI at a time.
pub fn simulate(scenario: &Scenario, opts: &SimulationOptions) -> Result<SimulatedRun, SimError> {
    check_option(
        "noise_px",
        opts.noise_px,
        "finite and >= 0",
        opts.noise_px >= 0.0,
    )?;
    check_option("rate_hz", opts.rate_hz, "positive", opts.rate_hz > 0.0)?;
    check_option(
        "drop_fraction",
        opts.drop_fraction,
        "in [0, 1)",
        (0.0..1.0).contains(&opts.drop_fraction),
    )?;
    check_option(
        "outlier_fraction",
        opts.outlier_fraction,
        "in [0, 1]",
        (0.0..=1.0).contains(&opts.outlier_fraction),
    )?;
    let camera = scenario.camera.clone();
    let target = scenario.target.clone();
    let n = target.len();
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let noise = Normal::new(0.0, opts.noise_px).expect("noise_px checked finite and >= 0");

    let sample_count = (scenario.duration_s * opts.rate_hz + 1e-9).floor() as usize + 1;
    let mut measurements = Vec::with_capacity(sample_count);
    let mut truth_poses = Vec::with_capacity(sample_count);
    let mut truth_twists = Vec::with_capacity(sample_count);
    let mut cycle: Vec<usize> = match opts.order {
        RoiOrder::BitReversed => bit_reversed_indices(n),
        RoiOrder::RowMajor | RoiOrder::Random => (0..n).collect(),
    };
    for k in 0..sample_count {
        let slot = k % n;
        if slot == 0 && opts.order == RoiOrder::Random {
            cycle.shuffle(&mut rng);
        }
        let t_s = k as f64 / opts.rate_hz;
        let state = scenario.state_at(t_s);
        truth_poses.push(PoseSample::from_state(t_s, &state));
        truth_twists.push(TwistSample::from_state(t_s, &state));
        let point = target.points()[cycle[slot]];
        let raw = camera
            .raw_pixel_from_cam(&state.point_in_cam_at(&point.point_in_obj_m, 0.0))
            .filter(|px| camera.contains_raw_pixel(px))
            .ok_or_else(|| {
                let p = state.point_in_cam_at(&point.point_in_obj_m, 0.0);
                let px = camera
                    .intrinsics
                    .pixel_from_cam(&p)
                    .unwrap_or(Vector2::new(f64::NAN, f64::NAN));
                SimError::BlobOffImage {
                    id: point.id,
                    t_s,
                    u_px: px.x,
                    v_px: px.y,
                }
            })?;
        // Draw every random number whether or not it is used, so options change only what they control.
        let dropped = rng.random::<f64>() < opts.drop_fraction;
        let outlier = rng.random::<f64>() < opts.outlier_fraction;
        let outlier_offset = {
            let angle = rng.random_range(0.0..std::f64::consts::TAU);
            Vector2::new(angle.cos(), angle.sin()) * rng.random_range(5.0..20.0)
        };
        let mut measured = raw + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng));
        if outlier {
            measured += outlier_offset;
        }
        if !dropped {
            measurements.push(Measurement {
                t_s,
                id: point.id,
                u_px: measured.x,
                v_px: measured.y,
            });
        }
    }
    Ok(SimulatedRun {
        camera,
        target,
        measurements,
        truth_poses,
        truth_twists,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ScenarioKind;
    use roitrack_core::so3;

    #[test]
    fn orthoglide_at_4khz_has_the_spec_sample_count_and_order() {
        let run = simulate(
            &Scenario::new(ScenarioKind::Orthoglide, 1),
            &SimulationOptions::default(),
        )
        .unwrap();
        assert_eq!(run.measurements.len(), 19_655);
        assert_eq!(run.truth_poses.len(), 19_655);
        let ids: Vec<u32> = run.measurements[..17].iter().map(|m| m.id).collect();
        assert_eq!(
            ids,
            vec![0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15, 0]
        );
        assert_eq!(run.measurements[3].t_s, 3.0 / 4000.0);
    }

    #[test]
    fn noiseless_measurements_are_exact_projections() {
        let scenario = Scenario::new(ScenarioKind::Spin, 1);
        let opts = SimulationOptions {
            noise_px: 0.0,
            ..Default::default()
        };
        let run = simulate(&scenario, &opts).unwrap();
        for m in run.measurements.iter().step_by(97) {
            let p = run.target.points()[run.target.index_of(m.id).unwrap()].point_in_obj_m;
            let px = run
                .camera
                .raw_pixel_from_cam(&scenario.state_at(m.t_s).point_in_cam_at(&p, 0.0))
                .unwrap();
            assert_eq!((px.x, px.y), (m.u_px, m.v_px));
        }
    }

    #[test]
    fn noise_drops_and_outliers_follow_their_options() {
        let scenario = Scenario::new(ScenarioKind::Static, 1);
        let clean = simulate(
            &scenario,
            &SimulationOptions {
                noise_px: 0.0,
                ..Default::default()
            },
        )
        .unwrap();
        let noisy = simulate(&scenario, &SimulationOptions::default()).unwrap();
        let residuals: Vec<f64> = clean
            .measurements
            .iter()
            .zip(&noisy.measurements)
            .flat_map(|(a, b)| [b.u_px - a.u_px, b.v_px - a.v_px])
            .collect();
        let rms = (residuals.iter().map(|r| r * r).sum::<f64>() / residuals.len() as f64).sqrt();
        assert!((rms - 0.1).abs() < 0.005, "noise rms {rms}");

        let dropped = simulate(
            &scenario,
            &SimulationOptions {
                drop_fraction: 0.5,
                ..Default::default()
            },
        )
        .unwrap();
        let kept = dropped.measurements.len() as f64 / clean.measurements.len() as f64;
        assert!((kept - 0.5).abs() < 0.03, "kept {kept}");
        assert_eq!(dropped.truth_poses.len(), clean.truth_poses.len());

        let outliers = simulate(
            &scenario,
            &SimulationOptions {
                outlier_fraction: 0.1,
                noise_px: 0.0,
                ..Default::default()
            },
        )
        .unwrap();
        let moved: Vec<f64> = clean
            .measurements
            .iter()
            .zip(&outliers.measurements)
            .map(|(a, b)| (b.u_px - a.u_px).hypot(b.v_px - a.v_px))
            .filter(|d| *d > 0.0)
            .collect();
        let fraction = moved.len() as f64 / clean.measurements.len() as f64;
        assert!((fraction - 0.1).abs() < 0.02, "outlier fraction {fraction}");
        assert!(moved.iter().all(|d| (5.0..=20.0).contains(d)));
    }

    #[test]
    fn random_order_visits_every_point_once_per_cycle() {
        let opts = SimulationOptions {
            order: RoiOrder::Random,
            ..Default::default()
        };
        let run = simulate(&Scenario::new(ScenarioKind::Static, 1), &opts).unwrap();
        for cycle in run.measurements.chunks_exact(16).take(20) {
            let mut ids: Vec<u32> = cycle.iter().map(|m| m.id).collect();
            ids.sort_unstable();
            assert_eq!(ids, (0..16).collect::<Vec<_>>());
        }
    }

    /// Integrating the ground-truth twist from one sample to the next (trapezoid rule: V and W averaged over the
    /// step, R advanced by Exp on the left) reproduces the next ground-truth pose to 1e-9. This pins the convention:
    /// V is the velocity of the object origin and W the angular velocity, both in the camera frame.
    #[test]
    fn integrating_the_truth_twist_reproduces_the_next_pose() {
        for kind in ScenarioKind::ALL {
            let run = simulate(&Scenario::new(kind, 1), &SimulationOptions::default()).unwrap();
            let mut worst: f64 = 0.0;
            for (p, w) in run.truth_poses.windows(2).zip(run.truth_twists.windows(2)) {
                let dt = p[1].t_s - p[0].t_s;
                let t_next = p[0].cam_from_obj.translation.vector
                    + (w[0].velocity_mps + w[1].velocity_mps) * (dt / 2.0);
                let r_next = so3::exp(
                    &((w[0].angular_velocity_radps + w[1].angular_velocity_radps) * (dt / 2.0)),
                ) * p[0].cam_from_obj.rotation.to_rotation_matrix();
                let position_error = (t_next - p[1].cam_from_obj.translation.vector).norm();
                let rotation_error =
                    so3::angle_between(&r_next, &p[1].cam_from_obj.rotation.to_rotation_matrix());
                worst = worst.max(position_error).max(rotation_error);
            }
            assert!(
                worst < 1e-9,
                "{kind:?}: worst one-step integration error {worst}"
            );
        }
    }

    #[test]
    fn bad_options_are_refused() {
        let s = Scenario::new(ScenarioKind::Static, 1);
        for opts in [
            SimulationOptions {
                noise_px: -1.0,
                ..Default::default()
            },
            SimulationOptions {
                rate_hz: 0.0,
                ..Default::default()
            },
            SimulationOptions {
                drop_fraction: 1.0,
                ..Default::default()
            },
            SimulationOptions {
                outlier_fraction: f64::NAN,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                simulate(&s, &opts),
                Err(SimError::BadOption { .. })
            ));
        }
    }
}
