//! The measurement-level simulator: sequential ROI centroids with their own timestamps, plus ground truth.

use nalgebra::{Vector2, Vector3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_core::{
    CameraModel, Measurement, MotionState, PoseSample, RoiOrder, Target, TwistSample,
};
use thiserror::Error;

use crate::Scenario;

/// How to sample a scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationOptions {
    /// Seed of every random choice (noise, drops, outliers, random order).
    pub seed: u64,
    /// Standard deviation of the centroid noise, per image axis (px). The built-in scene: 0.1 px.
    pub noise_px: f64,
    /// ROI rate (Hz): sample k is taken at t = k / rate, its exposure midpoint. The built-in scene: 4 kHz.
    pub rate_hz: f64,
    /// The order in which the ROIs cycle through the points.
    pub order: RoiOrder,
    /// Fraction of ROIs whose measurement is lost, in [0, 1).
    pub drop_fraction: f64,
    /// Fraction of measurements moved 5-20 px in a random direction, in [0, 1].
    pub outlier_fraction: f64,
    /// Fault: points hidden during a time interval (each entry one occlusion). Default none.
    pub occlusions: Vec<Occlusion>,
    /// Fault: intervals with no measurement at all. Default none.
    pub gaps: Vec<TimeGap>,
    /// Fault: runs of consecutive lost ROIs. Default none.
    pub bursts: Vec<RoiBurst>,
    /// Fault: from a time on, the true pose is translated (the ground truth includes the jump). Default none.
    pub jump: Option<Jump>,
    /// Fault: a sideways excursion of the target during an interval, far enough to take blobs out of the image (the
    /// ground truth includes it). Default none.
    pub excursion: Option<Excursion>,
    /// Drop the measurements of blobs outside the image instead of failing with [`SimError::BlobOffImage`].
    pub skip_off_image: bool,
}

/// The points `ids` are not measured during `[t0_s, t1_s)` (their ROIs are read but find nothing).
#[derive(Debug, Clone, PartialEq)]
pub struct Occlusion {
    /// The ids of the hidden points.
    pub ids: Vec<u32>,
    /// Start of the occlusion (s), included.
    pub t0_s: f64,
    /// End of the occlusion (s), excluded.
    pub t1_s: f64,
}

/// No measurement during `[t0_s, t0_s + duration_s)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeGap {
    /// Start of the gap (s).
    pub t0_s: f64,
    /// Length of the gap (s).
    pub duration_s: f64,
}

/// `count` consecutive ROIs lost, starting with the first ROI at or after `t0_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoiBurst {
    /// The burst starts at the first ROI at or after this time (s).
    pub t0_s: f64,
    /// Consecutive ROIs lost.
    pub count: usize,
}

/// From `t_s` on, the true target position (camera frame) is offset by `offset_m`; the twist is unchanged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jump {
    /// When the jump happens (s).
    pub t_s: f64,
    /// The translation added to the target's position from then on (m, camera frame).
    pub offset_m: Vector3<f64>,
}

impl Jump {
    /// `state` (the scenario's truth at `t_s`) with the jump applied.
    pub fn apply(&self, t_s: f64, mut state: MotionState) -> MotionState {
        if t_s >= self.t_s {
            state.cam_t_obj_m += self.offset_m;
        }
        state
    }
}

/// During `[t0_s, t1_s]` the true target position (camera frame) is moved by `offset_m` times a raised-cosine bump
/// `(1 - cos(2π (t - t0) / (t1 - t0))) / 2`, which rises from 0 to 1 and back: a smooth excursion and return, with
/// the bump's derivative added to the true velocity (the truth stays a consistent motion).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excursion {
    /// Start of the excursion (s).
    pub t0_s: f64,
    /// End of the excursion (s), the target back on its path.
    pub t1_s: f64,
    /// The largest displacement, reached half-way (m, camera frame).
    pub offset_m: Vector3<f64>,
}

impl Excursion {
    /// `state` (the scenario's truth at `t_s`) with the excursion applied.
    pub fn apply(&self, t_s: f64, mut state: MotionState) -> MotionState {
        if t_s > self.t0_s && t_s < self.t1_s {
            let omega = std::f64::consts::TAU / (self.t1_s - self.t0_s);
            let phase = omega * (t_s - self.t0_s);
            state.cam_t_obj_m += self.offset_m * (0.5 * (1.0 - phase.cos()));
            state.velocity_mps += self.offset_m * (0.5 * omega * phase.sin());
        }
        state
    }
}

impl SimulationOptions {
    /// The true state at `t_s`: the scenario's, with the jump and the excursion (if any) applied. Use it to render or
    /// to score a run simulated with these options.
    pub fn truth_at(&self, scenario: &Scenario, t_s: f64) -> MotionState {
        let mut state = scenario.state_at(t_s);
        if let Some(jump) = &self.jump {
            state = jump.apply(t_s, state);
        }
        if let Some(excursion) = &self.excursion {
            state = excursion.apply(t_s, state);
        }
        state
    }

    /// True when a fault removes the measurement of point `id` taken at `t_s` (ROI index `k`; `burst_starts` holds
    /// the first ROI index of each burst).
    fn fault_hides(&self, id: u32, t_s: f64, k: usize, burst_starts: &[usize]) -> bool {
        self.occlusions
            .iter()
            .any(|o| o.ids.contains(&id) && t_s >= o.t0_s && t_s < o.t1_s)
            || self
                .gaps
                .iter()
                .any(|g| t_s >= g.t0_s && t_s < g.t0_s + g.duration_s)
            || self
                .bursts
                .iter()
                .zip(burst_starts)
                .any(|(b, &start)| k >= start && k < start + b.count)
    }
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
            occlusions: Vec::new(),
            gaps: Vec::new(),
            bursts: Vec::new(),
            jump: None,
            excursion: None,
            skip_off_image: false,
        }
    }
}

/// A simulation's options are invalid, or a blob left the image.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SimError {
    /// An option is out of its range or not finite.
    #[error("{field} must be {expected}, got {value}")]
    BadOption {
        /// The option's field name.
        field: &'static str,
        /// The range it must be in, in words.
        expected: &'static str,
        /// The value given.
        value: f64,
    },
    /// The run would have more than [`MAX_SIMULATED_ROIS`] ROIs.
    #[error(
        "{duration_s} s at {rate_hz} Hz is more than {MAX_SIMULATED_ROIS} ROIs: shorten the run or lower the ROI rate"
    )]
    TooManyRois {
        /// The run's length (s).
        duration_s: f64,
        /// The ROI rate (Hz).
        rate_hz: f64,
    },
    /// A blob projects outside the image (and [`SimulationOptions::skip_off_image`] is off).
    #[error("point id {id} leaves the image at t = {t_s} s (raw pixel {u_px:.1}, {v_px:.1})")]
    BlobOffImage {
        /// The point's id.
        id: u32,
        /// The ROI's time (s).
        t_s: f64,
        /// Where the pinhole projection (without distortion) puts it: column (px).
        u_px: f64,
        /// Where the pinhole projection (without distortion) puts it: row (px).
        v_px: f64,
    },
}

/// A simulated acquisition: what the camera measured and what really happened.
#[derive(Debug, Clone)]
pub struct SimulatedRun {
    /// The camera that took the measurements.
    pub camera: CameraModel,
    /// The target measured.
    pub target: Target,
    /// In time order; dropped ROIs are absent.
    pub measurements: Vec<Measurement>,
    /// Ground truth at every ROI time (dropped or not).
    pub truth_poses: Vec<PoseSample>,
    /// Ground truth twists at the same times as [`Self::truth_poses`].
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

/// The highest ROI rate (Hz) simulated: a million ROIs a second, beyond any ROI camera.
pub const MAX_ROI_RATE_HZ: f64 = 1e6;
/// The most ROIs one simulated run may have: a billion (69 hours at 4 kHz, some 45 GB of measurements), so that a
/// mistaken duration or rate is refused rather than run for days.
pub const MAX_SIMULATED_ROIS: u64 = 1_000_000_000;

/// One ROI of a simulated run, as [`Simulation`] gives them, in time order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulatedRoi {
    /// The ROI's index from 0.
    pub index: usize,
    /// The ROI's time (s): `index / rate_hz`.
    pub t_s: f64,
    /// The true pose at the ROI's time (with the options' jump and excursion).
    pub truth_pose: PoseSample,
    /// The true twist at the ROI's time (with the options' jump and excursion).
    pub truth_twist: TwistSample,
    /// What the ROI measured: `None` when it was dropped, hidden by a fault, or its blob was off the image (with
    /// `skip_off_image`).
    pub measurement: Option<Measurement>,
}

/// A simulated acquisition one ROI at a time, in constant memory whatever the duration: the measurements and the
/// ground truth of [`simulate`] (which collects them), bit for bit, as an iterator. After an error (a blob leaving the
/// image without `skip_off_image`) it ends.
///
/// ```
/// use roitrack_sim::{Scenario, ScenarioKind, Simulation, SimulationOptions, simulate};
///
/// let scenario = Scenario::new(ScenarioKind::Spin, 1);
/// let options = SimulationOptions::default();
/// let stream = Simulation::new(&scenario, &options).unwrap();
/// assert_eq!(stream.len(), 12_001);
/// let measured: Vec<_> = stream.filter_map(|roi| roi.unwrap().measurement).collect();
/// assert_eq!(measured, simulate(&scenario, &options).unwrap().measurements);
/// ```
#[derive(Debug, Clone)]
pub struct Simulation<'a> {
    scenario: &'a Scenario,
    opts: &'a SimulationOptions,
    rng: ChaCha8Rng,
    noise: Normal<f64>,
    cycle: Vec<usize>,
    burst_starts: Vec<usize>,
    next: usize,
    sample_count: usize,
    done: bool,
}

impl<'a> Simulation<'a> {
    /// Checks the options (as [`simulate`] does) and starts the run.
    pub fn new(scenario: &'a Scenario, opts: &'a SimulationOptions) -> Result<Self, SimError> {
        check_options(opts)?;
        let samples = (scenario.duration_s * opts.rate_hz + 1e-9).floor() + 1.0;
        if samples.is_nan() || samples > MAX_SIMULATED_ROIS as f64 {
            return Err(SimError::TooManyRois {
                duration_s: scenario.duration_s,
                rate_hz: opts.rate_hz,
            });
        }
        let sample_count = samples as usize;
        // The first ROI index of each burst: the first sample at or after its start time.
        let burst_starts: Vec<usize> = opts
            .bursts
            .iter()
            .map(|b| (b.t0_s.max(0.0) * opts.rate_hz - 1e-9).ceil().max(0.0) as usize)
            .collect();
        let n = scenario.target.len();
        let cycle: Vec<usize> = match opts.order {
            RoiOrder::BitReversed => bit_reversed_indices(n),
            RoiOrder::RowMajor | RoiOrder::Random => (0..n).collect(),
        };
        Ok(Self {
            scenario,
            opts,
            rng: ChaCha8Rng::seed_from_u64(opts.seed),
            noise: Normal::new(0.0, opts.noise_px).expect("noise_px checked finite and >= 0"),
            cycle,
            burst_starts,
            next: 0,
            sample_count,
            done: false,
        })
    }

    /// The number of ROIs of the run (dropped ones included): the scenario's duration at the ROI rate, both ends
    /// included.
    pub fn len(&self) -> usize {
        self.sample_count
    }

    /// Whether the run has no ROI (never: the first is at t = 0).
    pub fn is_empty(&self) -> bool {
        self.sample_count == 0
    }

    /// The ROI at `self.next`.
    fn sample(&mut self) -> Result<SimulatedRoi, SimError> {
        let (scenario, opts) = (self.scenario, self.opts);
        let camera = &scenario.camera;
        let k = self.next;
        let n = scenario.target.len();
        let slot = k % n;
        if slot == 0 && opts.order == RoiOrder::Random {
            self.cycle.shuffle(&mut self.rng);
        }
        let t_s = k as f64 / opts.rate_hz;
        let state = opts.truth_at(scenario, t_s);
        let point = scenario.target.points()[self.cycle[slot]];
        let raw = camera
            .raw_pixel_from_cam(&state.point_in_cam_at(&point.point_in_obj_m, 0.0))
            .filter(|px| camera.contains_raw_pixel(px));
        let raw = match raw {
            Some(px) => Some(px),
            None if opts.skip_off_image => None,
            None => {
                let p = state.point_in_cam_at(&point.point_in_obj_m, 0.0);
                let px = camera
                    .intrinsics
                    .pixel_from_cam(&p)
                    .unwrap_or(Vector2::new(f64::NAN, f64::NAN));
                return Err(SimError::BlobOffImage {
                    id: point.id,
                    t_s,
                    u_px: px.x,
                    v_px: px.y,
                });
            }
        };
        let rng = &mut self.rng;
        // Draw every random number whether or not it is used, so options change only what they control.
        let dropped = rng.random::<f64>() < opts.drop_fraction;
        let outlier = rng.random::<f64>() < opts.outlier_fraction;
        let outlier_offset = {
            let angle = rng.random_range(0.0..std::f64::consts::TAU);
            Vector2::new(angle.cos(), angle.sin()) * rng.random_range(5.0..20.0)
        };
        let noise_px = Vector2::new(self.noise.sample(rng), self.noise.sample(rng));
        // Faults and blobs off the image remove a measurement after its random numbers are drawn, so the others are
        // those of the run without the fault.
        let measurement = raw.and_then(|raw| {
            let mut measured = raw + noise_px;
            if outlier {
                measured += outlier_offset;
            }
            (!dropped && !opts.fault_hides(point.id, t_s, k, &self.burst_starts)).then_some(
                Measurement {
                    t_s,
                    id: point.id,
                    u_px: measured.x,
                    v_px: measured.y,
                },
            )
        });
        Ok(SimulatedRoi {
            index: k,
            t_s,
            truth_pose: PoseSample::from_state(t_s, &state),
            truth_twist: TwistSample::from_state(t_s, &state),
            measurement,
        })
    }
}

impl Iterator for Simulation<'_> {
    type Item = Result<SimulatedRoi, SimError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done || self.next >= self.sample_count {
            return None;
        }
        let sample = self.sample();
        self.next += 1;
        if sample.is_err() {
            self.done = true;
        }
        Some(sample)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = if self.done {
            0
        } else {
            self.sample_count - self.next
        };
        (0, Some(left))
    }
}

/// The checks of [`simulate`]'s options.
fn check_options(opts: &SimulationOptions) -> Result<(), SimError> {
    check_option(
        "noise_px",
        opts.noise_px,
        "finite and >= 0",
        opts.noise_px >= 0.0,
    )?;
    check_option(
        "rate_hz",
        opts.rate_hz,
        "positive, at most 1e6 (a million ROIs a second)",
        opts.rate_hz > 0.0 && opts.rate_hz <= MAX_ROI_RATE_HZ,
    )?;
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
    for o in &opts.occlusions {
        check_option("occlusion t0_s", o.t0_s, "finite", true)?;
        check_option(
            "occlusion t1_s",
            o.t1_s,
            "finite and >= t0_s",
            o.t1_s >= o.t0_s,
        )?;
    }
    for g in &opts.gaps {
        check_option("gap t0_s", g.t0_s, "finite", true)?;
        check_option(
            "gap duration_s",
            g.duration_s,
            "finite and >= 0",
            g.duration_s >= 0.0,
        )?;
    }
    for b in &opts.bursts {
        check_option("burst t0_s", b.t0_s, "finite", true)?;
    }
    if let Some(j) = &opts.jump {
        check_option("jump t_s", j.t_s, "finite", true)?;
        for (field, value) in [
            ("jump dx_m", j.offset_m.x),
            ("jump dy_m", j.offset_m.y),
            ("jump dz_m", j.offset_m.z),
        ] {
            check_option(field, value, "finite", true)?;
        }
    }
    if let Some(e) = &opts.excursion {
        check_option("excursion t0_s", e.t0_s, "finite", true)?;
        check_option(
            "excursion t1_s",
            e.t1_s,
            "finite and > t0_s",
            e.t1_s > e.t0_s,
        )?;
        for (field, value) in [
            ("excursion dx_m", e.offset_m.x),
            ("excursion dy_m", e.offset_m.y),
            ("excursion dz_m", e.offset_m.z),
        ] {
            check_option(field, value, "finite", true)?;
        }
    }
    Ok(())
}

/// Samples `scenario` one ROI at a time: every measurement is the projection of the true pose at its own time (the
/// ROI's exposure middle) plus noise, with the faults of `opts`; the ground truth comes at every ROI time. This is a
/// camera reading one ROI at a time whatever the camera model's time model says (for frames of a rolling or global
/// shutter, render them: [`crate::RoiRenderer::render_frame`]). The run is held in memory; [`Simulation`]
/// gives the same ROIs one at a time.
///
/// ```
/// use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
///
/// let options = SimulationOptions { noise_px: 0.2, drop_fraction: 0.1, ..SimulationOptions::default() };
/// let run = simulate(&Scenario::new(ScenarioKind::Spin, 1), &options).unwrap();
/// // 3 s at 4 kHz (both ends included), a tenth of the ROIs lost; the truth at every ROI time.
/// assert_eq!(run.truth_poses.len(), 12_001);
/// assert!((10_500..11_500).contains(&run.measurements.len()));
/// ```
pub fn simulate(scenario: &Scenario, opts: &SimulationOptions) -> Result<SimulatedRun, SimError> {
    let stream = Simulation::new(scenario, opts)?;
    let sample_count = stream.len();
    let mut measurements = Vec::with_capacity(sample_count);
    let mut truth_poses = Vec::with_capacity(sample_count);
    let mut truth_twists = Vec::with_capacity(sample_count);
    for roi in stream {
        let roi = roi?;
        truth_poses.push(roi.truth_pose);
        truth_twists.push(roi.truth_twist);
        measurements.extend(roi.measurement);
    }
    Ok(SimulatedRun {
        camera: scenario.camera.clone(),
        target: scenario.target.clone(),
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

    fn ideal(kind: ScenarioKind) -> (Scenario, SimulatedRun) {
        let scenario = Scenario::new(kind, 1);
        let run = simulate(&scenario, &SimulationOptions::default()).unwrap();
        (scenario, run)
    }

    /// The measurements of a run with a hiding fault are those of the clean run minus the hidden ones, bit for bit.
    fn assert_clean_minus(
        clean: &SimulatedRun,
        faulty: &SimulatedRun,
        hidden: impl Fn(usize, &Measurement) -> bool,
    ) {
        let expected: Vec<Measurement> = clean
            .measurements
            .iter()
            .enumerate()
            .filter(|(k, m)| !hidden(*k, m))
            .map(|(_, m)| *m)
            .collect();
        assert_eq!(faulty.measurements, expected);
        assert_eq!(faulty.truth_poses, clean.truth_poses);
        assert_eq!(faulty.truth_twists, clean.truth_twists);
    }

    #[test]
    fn occlusion_hides_exactly_its_points_during_its_interval() {
        let (scenario, clean) = ideal(ScenarioKind::Orthoglide);
        let opts = SimulationOptions {
            occlusions: vec![Occlusion {
                ids: vec![0, 5, 10, 15],
                t0_s: 1.0,
                t1_s: 1.2,
            }],
            ..Default::default()
        };
        let run = simulate(&scenario, &opts).unwrap();
        let hidden = |_: usize, m: &Measurement| {
            [0, 5, 10, 15].contains(&m.id) && (1.0..1.2).contains(&m.t_s)
        };
        assert_clean_minus(&clean, &run, hidden);
        // 0.2 s at 4 kHz = 800 ROIs, a quarter of them on the hidden points.
        assert_eq!(clean.measurements.len() - run.measurements.len(), 200);
    }

    #[test]
    fn a_time_gap_removes_every_measurement_of_its_interval() {
        let (scenario, clean) = ideal(ScenarioKind::Orthoglide);
        let opts = SimulationOptions {
            gaps: vec![TimeGap {
                t0_s: 2.0,
                duration_s: 0.05,
            }],
            ..Default::default()
        };
        let run = simulate(&scenario, &opts).unwrap();
        assert_clean_minus(&clean, &run, |_, m| (2.0..2.05).contains(&m.t_s));
        assert_eq!(clean.measurements.len() - run.measurements.len(), 200);
        assert!(
            run.measurements
                .iter()
                .all(|m| !(2.0..2.05).contains(&m.t_s))
        );
    }

    #[test]
    fn a_burst_loses_n_consecutive_rois_from_its_start() {
        let (scenario, clean) = ideal(ScenarioKind::Orthoglide);
        let opts = SimulationOptions {
            bursts: vec![RoiBurst {
                t0_s: 1.5,
                count: 40,
            }],
            ..Default::default()
        };
        let run = simulate(&scenario, &opts).unwrap();
        assert_clean_minus(&clean, &run, |k, _| (6000..6040).contains(&k));
        // Also with drops: the burst removes ROIs on top of the random drops, which are unchanged.
        let drop = SimulationOptions {
            drop_fraction: 0.3,
            ..Default::default()
        };
        let dropped = simulate(&scenario, &drop).unwrap();
        let both = simulate(
            &scenario,
            &SimulationOptions {
                bursts: opts.bursts.clone(),
                ..drop
            },
        )
        .unwrap();
        let expected: Vec<Measurement> = dropped
            .measurements
            .iter()
            .filter(|m| !(1.5..1.51).contains(&m.t_s))
            .copied()
            .collect();
        assert_eq!(both.measurements, expected);
    }

    #[test]
    fn an_excursion_is_a_consistent_motion_that_takes_blobs_off_the_image() {
        let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
        // Far enough right, at the peak, for the image's right edge to fall within the target (6 cm wide).
        let mid = scenario.state_at(1.2).cam_t_obj_m;
        let half_field_m = 512.0 / 1500.0 * mid.z;
        let excursion = Excursion {
            t0_s: 1.0,
            t1_s: 1.4,
            offset_m: Vector3::new(half_field_m - mid.x - 0.01, 0.0, 0.0),
        };
        let opts = SimulationOptions {
            excursion: Some(excursion),
            skip_off_image: true,
            ..Default::default()
        };
        // The offset is 0 outside, the full offset at mid-interval, and the velocity is its derivative.
        let shift =
            |t: f64| opts.truth_at(&scenario, t).cam_t_obj_m - scenario.state_at(t).cam_t_obj_m;
        assert_eq!(shift(0.99), Vector3::zeros());
        assert_eq!(shift(1.41), Vector3::zeros());
        assert!((shift(1.2) - excursion.offset_m).norm() < 1e-12);
        roitrack_testkit::check_jacobian(
            "velocity of the excursion's truth",
            1.2,
            |rng, spread| {
                1.2 + spread * roitrack_testkit::rand::Rng::random_range(rng, -0.18..0.18)
            },
            &nalgebra::Vector1::new(1.0),
            |t, dt| opts.truth_at(&scenario, t + dt[0]).cam_t_obj_m,
            |t| opts.truth_at(&scenario, *t).velocity_mps,
        );
        // Blobs leave the image during the excursion only, and not all of them.
        let run = simulate(&scenario, &opts).unwrap();
        let clean = simulate(&scenario, &SimulationOptions::default()).unwrap();
        let count = |r: &SimulatedRun, a: f64, b: f64| {
            r.measurements
                .iter()
                .filter(|m| m.t_s >= a && m.t_s < b)
                .count()
        };
        assert_eq!(count(&run, 0.0, 1.0), count(&clean, 0.0, 1.0));
        assert_eq!(count(&run, 1.4, 10.0), count(&clean, 1.4, 10.0));
        let (during, all) = (count(&run, 1.15, 1.25), count(&clean, 1.15, 1.25));
        assert!(
            during < all && during > all / 4,
            "{during} of {all} measured at the peak"
        );
        // An interval that does not move forward is refused.
        let bad = SimulationOptions {
            excursion: Some(Excursion {
                t1_s: 1.0,
                ..excursion
            }),
            ..opts
        };
        assert!(simulate(&scenario, &bad).is_err());
    }

    #[test]
    fn a_jump_moves_the_truth_and_the_measurements_from_its_time() {
        let scenario = Scenario::new(ScenarioKind::Random, 1);
        let base = SimulationOptions {
            noise_px: 0.0,
            ..Default::default()
        };
        let clean = simulate(&scenario, &base).unwrap();
        let offset = Vector3::new(0.02, 0.0, 0.0);
        let opts = SimulationOptions {
            jump: Some(Jump {
                t_s: 2.5,
                offset_m: offset,
            }),
            ..base
        };
        let run = simulate(&scenario, &opts).unwrap();
        assert_eq!(run.measurements.len(), clean.measurements.len());
        assert_eq!(run.truth_twists, clean.truth_twists);
        for (a, b) in clean.truth_poses.iter().zip(&run.truth_poses) {
            let shift = b.cam_from_obj.translation.vector - a.cam_from_obj.translation.vector;
            let expected = if a.t_s >= 2.5 {
                offset
            } else {
                Vector3::zeros()
            };
            assert!(
                (shift - expected).norm() < 1e-12,
                "t = {}: shift {shift}",
                a.t_s
            );
            assert_eq!(a.cam_from_obj.rotation, b.cam_from_obj.rotation);
        }
        for (a, b) in clean.measurements.iter().zip(&run.measurements) {
            if a.t_s < 2.5 {
                assert_eq!(a, b);
            } else {
                let p = run.target.points()[run.target.index_of(b.id).unwrap()].point_in_obj_m;
                let px = run
                    .camera
                    .raw_pixel_from_cam(&opts.truth_at(&scenario, b.t_s).point_in_cam_at(&p, 0.0))
                    .unwrap();
                assert_eq!((px.x, px.y), (b.u_px, b.v_px));
                assert!(
                    (a.u_px - b.u_px).abs() > 1.0,
                    "a 2 cm jump moves the blobs by pixels"
                );
            }
        }
    }

    #[test]
    fn blobs_off_the_image_fail_by_default_and_are_skipped_on_request() {
        let scenario = Scenario::new(ScenarioKind::Static, 1);
        let jump = Some(Jump {
            t_s: 0.5,
            offset_m: Vector3::new(0.2, 0.0, 0.0),
        });
        let opts = SimulationOptions {
            jump,
            ..Default::default()
        };
        assert!(matches!(
            simulate(&scenario, &opts),
            Err(SimError::BlobOffImage { .. })
        ));
        let clean = simulate(&scenario, &SimulationOptions::default()).unwrap();
        let run = simulate(
            &scenario,
            &SimulationOptions {
                skip_off_image: true,
                ..opts.clone()
            },
        )
        .unwrap();
        assert!(run.measurements.len() < clean.measurements.len());
        assert!(
            run.measurements.iter().any(|m| m.t_s >= 0.5),
            "some blobs stay visible"
        );
        assert_eq!(run.truth_poses.len(), clean.truth_poses.len());
        let before: Vec<_> = clean
            .measurements
            .iter()
            .filter(|m| m.t_s < 0.5)
            .copied()
            .collect();
        assert_eq!(&run.measurements[..before.len()], &before[..]);
        for m in &run.measurements {
            assert!(run.camera.contains_raw_pixel(&Vector2::new(m.u_px, m.v_px)) || m.t_s < 0.5);
        }
        // Skipping changes nothing when every blob stays inside.
        let skip = simulate(
            &scenario,
            &SimulationOptions {
                skip_off_image: true,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(skip.measurements, clean.measurements);
    }

    #[test]
    fn bad_fault_options_are_refused() {
        let s = Scenario::new(ScenarioKind::Static, 1);
        for opts in [
            SimulationOptions {
                occlusions: vec![Occlusion {
                    ids: vec![0],
                    t0_s: 1.0,
                    t1_s: 0.5,
                }],
                ..Default::default()
            },
            SimulationOptions {
                gaps: vec![TimeGap {
                    t0_s: 0.1,
                    duration_s: -1.0,
                }],
                ..Default::default()
            },
            SimulationOptions {
                jump: Some(Jump {
                    t_s: f64::NAN,
                    offset_m: Vector3::zeros(),
                }),
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
