//! The default estimator: an error-state extended Kalman filter on the 12-dof state with a constant-velocity process
//! model; every centroid updates the state once, at its own time.
//!
//! The error state is the correction `δ = (v, w, dV, dW)` of [`MotionState::corrected`]. Between measurements the
//! state moves with its twist; the twist drifts as a random walk driven by white linear and angular acceleration of
//! spectral densities `q_a` ((m/s²)²/Hz) and `q_α` ((rad/s²)²/Hz). Innovations beyond the gate are rejected as
//! outliers; a run of rejections widens the covariance (a jump of the target, or a bad update), by escalating steps.
//!
//! By default the filter is told neither the noise of the centroids nor how the target moves; it learns both:
//! - **Centroid noise**: at each control step, the window's least-squares residual at its own optimum divided by its
//!   redundancy (`2 m - 12` for m measurements) is an unbiased sample of the noise variance, whatever the process
//!   noise; an exponential memory of about 2,000 degrees of freedom averages them, each window moving the estimate by
//!   at most a factor 4 (an outlier does not drag it). The initialisation starts it from the median residual of its
//!   two-cycle fit, so that a noise ten times the configured one still initialises. Steps whose measurements share
//!   one instant (global-shutter frames) sample their own measurements instead, the pose alone fitted
//!   ([`NoiseSample`]).
//! - **Process noise**: the linear and the angular density are each scaled by a factor that follows the
//!   *persistence* of the innovations: the innovation projected on the displacement that the recent corrections
//!   (their exponential average over two cycles) predict for the measured point, normalised to a standard normal
//!   variable. Innovations of a filter with the right gain are white and their persistence averages zero; a lagging
//!   filter keeps correcting one way (positive), a filter that chases the noise undoes its corrections (negative).
//!   The logarithm of each factor moves by 0.05 times the persistence per measurement: a still target is averaged
//!   down, a manoeuvre raises the process noise within tens of measurements. Steps whose measurements share one
//!   instant (frames) leave the factors as they are.
//!
//! With [`KalmanTuning::adapt_noise`] and [`KalmanTuning::adapt_motion`] off, the filter takes
//! [`TrackerConfig::noise_px`] and the densities as the truth: a hand-tuned filter.

use nalgebra::{Matrix2, SMatrix, Vector2, Vector3};

use super::calibration::TwistCalibration;
use super::problem::{Observation, ResidualFigures, ResidualTally};
use super::track::{Law, Step, Track, TrackCore};
use super::{
    ConfigError, Estimate, Estimator, EstimatorConfig, EstimatorReport, TrackError, TrackStatus,
    TrackerConfig,
};
use crate::{
    CameraModel, JacobianKind, Measurement, MotionState, SpatioTemporalModel, Target, Vector12, so3,
};

/// A 12 x 12 matrix: covariances of the error state (v, w, dV, dW).
pub type Matrix12 = SMatrix<f64, 12, 12>;

/// The covariance is made exactly symmetric again after this many updates (each leaves a round-off asymmetry of
/// about 1e-16 of its entries).
const SYMMETRISE_EVERY_UPDATES: u64 = 16;
/// Consecutive measurements rejected by the gate after which the covariance is widened.
const GATED_IN_A_ROW_FOR_RESET: usize = 6;
/// Fractions of the broad prior covariance added at successive covariance resets (variance scales: 1/100 is a tenth
/// of its standard deviations).
const RESET_SCALES: [f64; 3] = [0.01, 0.1, 1.0];
/// Accepted measurements in a row after which the next reset starts small again.
const ACCEPTED_IN_A_ROW_FOR_CALM: usize = 64;

/// Tuning of the Kalman filter.
///
/// ```
/// use roitrack_core::estimator::{EstimatorConfig, KalmanTuning, TrackerConfig};
/// // A hand-tuned filter: less lag, more noise with a larger linear acceleration density, held fixed.
/// let tuning = KalmanTuning { linear_accel_psd: 10.0, adapt_motion: false, ..KalmanTuning::default() };
/// let config = TrackerConfig { estimator: EstimatorConfig::Kalman(tuning), ..TrackerConfig::default() };
/// assert!(config.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanTuning {
    /// White linear acceleration spectral density q_a ((m/s²)²/Hz). Larger: less lag, more noise. With
    /// [`Self::adapt_motion`], only the starting value.
    pub linear_accel_psd: f64,
    /// White angular acceleration spectral density q_α ((rad/s²)²/Hz). With [`Self::adapt_motion`], only the
    /// starting value.
    pub angular_accel_psd: f64,
    /// Innovations beyond this many standard deviations (Mahalanobis, 2 dof) are rejected as outliers. Default 3:
    /// it rejects exp(-9/2) = 1.1 % of good measurements. Measured with `roitrack faults` (3 runs each): against 6,
    /// it costs 0.9 % of position RMSE on clean measurements (0.2647 against 0.2623 mm on orthoglide), and with 10 %
    /// of rendered ROIs carrying a reflection it keeps the error at 1.4-3.6x the clean image run instead of 1.9-21x
    /// (a reflection merged with the blob biases its centroid by a fraction of a pixel, well inside 6 σ of the
    /// prediction); 3.5 left up to 30x.
    pub gate_sigma: f64,
    /// Huber threshold (standard deviations, Mahalanobis): a larger innovation gets its measurement noise inflated
    /// by `distance / huber_sigma` (the Huber weight), so a moderate outlier pulls less; `f64::INFINITY` turns it off.
    pub huber_sigma: f64,
    /// Estimate the centroid noise online from the innovations (default): `TrackerConfig::noise_px` is then only the
    /// starting value. Off, the filter takes `noise_px` as the truth (a hand-tuned filter).
    pub adapt_noise: bool,
    /// Let the process noise follow the motion (default): the acceleration densities above are then only starting
    /// values, lowered while the innovations show the filter over-reacting (a still target is averaged down) and
    /// raised while they show it lagging. Off, they are fixed (a hand-tuned filter).
    pub adapt_motion: bool,
    /// Scale the reported covariance of the linear and the angular velocity (default) by how far the estimates'
    /// twists actually stray from the mean twist of the poses around them (see docs/estimation.md): the process noise
    /// the filter needs to follow manoeuvres makes it claim a velocity uncertainty two to four times too wide on
    /// smooth motion. Only the reported covariance changes, never the estimate.
    pub calibrate_twist_covariance: bool,
    /// Which residual the noise estimate samples (with [`Self::adapt_noise`]). Default [`NoiseSample::Window`].
    pub noise_sample: NoiseSample,
}

/// Which residuals the Kalman filter's noise estimate samples.
///
/// Measurements that come a frame at a time (the blobs of global-shutter frames, several at each time) are sampled
/// frame by frame in either case: each frame's residual with its pose alone fitted and the twist held at the
/// filter's, of redundancy `2 m - 6`. A frame alone cannot tell the twist, and a window spanning several frames, tens
/// of milliseconds apart, takes the motion's change for noise: a 4-point target's window (24 measurements, 6 frames at
/// 30 Hz) learnt 4.6 px instead of 0.3.
///
/// ```
/// use roitrack_core::estimator::{KalmanTuning, NoiseSample};
///
/// assert_eq!(KalmanTuning::default().noise_sample, NoiseSample::Window);
/// // What the frame tracker uses.
/// let frames = KalmanTuning { noise_sample: NoiseSample::Frames, ..KalmanTuning::default() };
/// assert!(frames.adapt_noise);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseSample {
    /// Every other control step: its window (as [`crate::estimator::TrackerConfig::window`] selects it, at least
    /// 24 measurements for targets of fewer than 12 points) under one constant twist, all 12 parameters fitted: right
    /// for ROIs, a few milliseconds apart.
    Window,
    /// Only the steps of one instant: the measurements come a frame at a time, and a rolling-shutter frame (whose
    /// blobs are not simultaneous) leaves the noise as it is. Its own residual misses what matters there: its blobs
    /// also pin the twist, through the image's stretch over the readout, and an error of the twist over the readout
    /// bends the frame in ways the pose absorbs. Learnt from rolling-shutter frames that way, the noise came out near
    /// the centroids' (0.01-0.02 px), and that helped on one simulated camera (1024 x 1024 px, 30 µs a row: position
    /// 0.175 to 0.153 mm) but hurt on another (640 x 480 px, 60 µs a row, three seeds: 0.165-0.273 to 0.246-0.295
    /// mm), whose best setting was 0.05 px.
    Frames,
}

impl Default for KalmanTuning {
    fn default() -> Self {
        Self {
            linear_accel_psd: 1.0,
            angular_accel_psd: 10.0,
            gate_sigma: 3.0,
            huber_sigma: 2.5,
            adapt_noise: true,
            adapt_motion: true,
            calibrate_twist_covariance: true,
            noise_sample: NoiseSample::Window,
        }
    }
}

/// The filter's covariance; the state itself lives in the tracker.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ErrorStateKalman {
    covariance: Matrix12,
    tuning: KalmanTuning,
    /// Exponential average of the recent corrections (error-state units), and its weight per update.
    trend: Vector12,
    trend_rate: f64,
    /// Updates applied, to symmetrise the covariance every [`SYMMETRISE_EVERY_UPDATES`].
    updates: u64,
    /// The persistence of the newest innovation along the translational and the rotational part of the trend (see
    /// [`Self::update`]); 0 when there is no trend yet.
    persistence: [f64; 2],
}

/// What one measurement update did.
#[derive(Debug, Clone, Copy, PartialEq)]
enum UpdateOutcome {
    /// Used: the norm of its innovation (px) and its squared Mahalanobis distance (the normalised innovation
    /// squared, 2 dof).
    Accepted { norm_px: f64, nis: f64 },
    /// Rejected by the innovation gate: the norm of its innovation (px) and its squared Mahalanobis distance.
    Gated { norm_px: f64, nis: f64 },
    /// The point does not project (behind the camera) or the innovation covariance is singular.
    Invalid,
}

impl ErrorStateKalman {
    fn new(covariance: Matrix12, tuning: KalmanTuning, trend_rate: f64) -> Self {
        Self {
            covariance,
            tuning,
            trend: Vector12::zeros(),
            trend_rate,
            persistence: [0.0; 2],
            updates: 0,
        }
    }

    /// Moves the state `dt_s` ahead and grows the covariance, with the acceleration densities scaled by
    /// `process_scale`.
    fn predict(&mut self, state: &mut MotionState, dt_s: f64, process_scale: [f64; 2]) {
        if dt_s == 0.0 {
            return;
        }
        // F = [I 0 dt·I 0; 0 E 0 B; 0 0 I 0; 0 0 0 I] with E = Exp(W dt) and B = J_l(W dt) dt: F P Fᵀ by blocks of
        // three rows, then three columns (a seventh of the dense product's work).
        let rotation_increment = state.angular_velocity_radps * dt_s;
        let e_rotation = so3::exp(&rotation_increment);
        let e = *e_rotation.matrix();
        let b = so3::left_jacobian(&rotation_increment) * dt_s;
        // In place on the column-major entries (p[i + 12 j] is row i, column j): no 12 x 12 temporaries.
        let p = self.covariance.as_mut_slice();
        for column in p.chunks_exact_mut(12) {
            let old: [f64; 12] = column.try_into().expect("12 rows");
            for k in 0..3 {
                column[k] = old[k] + old[6 + k] * dt_s;
                column[3 + k] = (0..3)
                    .map(|l| e[(k, l)] * old[3 + l] + b[(k, l)] * old[9 + l])
                    .sum();
            }
        }
        let old_translation: [f64; 36] = p[..36].try_into().expect("3 columns");
        let old_rotation: [f64; 36] = p[36..72].try_into().expect("3 columns");
        for k in 0..3 {
            for i in 0..12 {
                p[i + 12 * k] = old_translation[i + 12 * k] + p[i + 12 * (6 + k)] * dt_s;
                p[i + 12 * (3 + k)] = (0..3)
                    .map(|l| old_rotation[i + 12 * l] * e[(k, l)] + p[i + 12 * (9 + l)] * b[(k, l)])
                    .sum();
            }
        }
        // Q of white acceleration: per axis [dt³/3 dt²/2; dt²/2 dt] times the density.
        let dt = dt_s.abs();
        let p = &mut self.covariance;
        for (pos, vel, psd) in [
            (0, 6, self.tuning.linear_accel_psd * process_scale[0]),
            (3, 9, self.tuning.angular_accel_psd * process_scale[1]),
        ] {
            let (qpp, qpv, qvv) = (psd * dt * dt * dt / 3.0, psd * dt * dt / 2.0, psd * dt);
            for i in 0..3 {
                p[(pos + i, pos + i)] += qpp;
                p[(pos + i, vel + i)] += qpv;
                p[(vel + i, pos + i)] += qpv;
                p[(vel + i, vel + i)] += qvv;
            }
        }
        // The state's own prediction (`MotionState::predicted`), with the rotation increment already at hand.
        state.cam_r_obj = e_rotation * state.cam_r_obj;
        state.cam_t_obj_m += state.velocity_mps * dt_s;
    }

    /// Updates with one centroid (ideal pixel) of `point_in_obj_m`, observed at the state's reference time.
    fn update(
        &mut self,
        model: &SpatioTemporalModel,
        state: &mut MotionState,
        point_in_obj_m: &Vector3<f64>,
        ideal_px: &Vector2<f64>,
        sigma_px: f64,
    ) -> UpdateOutcome {
        let Some(projected) =
            model.project_with_jacobian(JacobianKind::Exact, state, point_in_obj_m, 0.0)
        else {
            return UpdateOutcome::Invalid;
        };
        let h = projected.jacobian;
        let innovation = ideal_px - projected.pixel;
        let ph_t: SMatrix<f64, 12, 2> = self.covariance * h.transpose();
        let s = h * ph_t + Matrix2::identity() * (sigma_px * sigma_px);
        let Some(s_inv) = s.try_inverse() else {
            return UpdateOutcome::Invalid;
        };
        let mahalanobis2 = (innovation.transpose() * s_inv * innovation)[0];
        if !mahalanobis2.is_finite() {
            return UpdateOutcome::Invalid;
        }
        // Persistence: the innovation along the displacement that the recent corrections predict for this point,
        // normalised. An optimal filter's innovations are white, so this is N(0, 1); it is positive on average when
        // the corrections keep going one way (the filter lags the motion) and negative when they undo each other
        // (the filter chases the noise).
        for (part, rows) in [(0, [0, 6]), (1, [3, 9])] {
            let expected: Vector2<f64> = rows
                .iter()
                .map(|&r| h.fixed_columns::<3>(r) * self.trend.fixed_rows::<3>(r))
                .sum();
            let spread2 = (expected.transpose() * s_inv * expected)[0];
            self.persistence[part] = if spread2 > 0.0 {
                (innovation.transpose() * s_inv * expected)[0] / spread2.sqrt()
            } else {
                0.0
            };
        }
        if mahalanobis2 > self.tuning.gate_sigma * self.tuning.gate_sigma {
            return UpdateOutcome::Gated {
                norm_px: innovation.norm(),
                nis: mahalanobis2,
            };
        }
        let distance = mahalanobis2.sqrt();
        let (sigma2, s_inv) = if distance > self.tuning.huber_sigma {
            let inflated = sigma_px * sigma_px * distance / self.tuning.huber_sigma;
            match (h * ph_t + Matrix2::identity() * inflated).try_inverse() {
                Some(inv) => (inflated, inv),
                None => return UpdateOutcome::Invalid,
            }
        } else {
            (sigma_px * sigma_px, s_inv)
        };
        let gain = ph_t * s_inv;
        let correction = gain * innovation;
        let corrected = state.corrected(&correction);
        if !corrected.is_finite() {
            return UpdateOutcome::Invalid;
        }
        *state = corrected;
        self.trend += (correction - self.trend) * self.trend_rate;
        // P - K S Kᵀ = P - (P Hᵀ) S⁻¹ (P Hᵀ)ᵀ with the gain that is optimal for S (the Huber-inflated one included):
        // a twelfth of the Joseph form's work, as a rank-2 downdate in place, symmetrised every few updates against
        // round-off. Should rounding ever leave a variance that is not positive, the Joseph form takes over.
        for (j, column) in self
            .covariance
            .as_mut_slice()
            .chunks_exact_mut(12)
            .enumerate()
        {
            let (a, b) = (ph_t[(j, 0)], ph_t[(j, 1)]);
            for (i, entry) in column.iter_mut().enumerate() {
                *entry -= gain[(i, 0)] * a + gain[(i, 1)] * b;
            }
        }
        self.updates += 1;
        if self.updates.is_multiple_of(SYMMETRISE_EVERY_UPDATES) {
            self.covariance = (self.covariance + self.covariance.transpose()) * 0.5;
        }
        if (0..12).any(|i| self.covariance[(i, i)] <= 0.0) {
            let before = self.covariance + gain * ph_t.transpose();
            let i_kh = Matrix12::identity() - gain * h;
            self.covariance = i_kh * before * i_kh.transpose() + gain * gain.transpose() * sigma2;
        }
        UpdateOutcome::Accepted {
            norm_px: innovation.norm(),
            nis: mahalanobis2,
        }
    }
}

/// How fast the process-noise scales follow the persistence of the innovations: their logarithms move by this much
/// per measurement and per unit of persistence (a standard normal variable when the filter is right). Chosen on the
/// orthoglide, static, spin and random scenes at 0.03-1 px and 4-10 kHz: 0.01 is too slow to average a still target
/// down within a second, 0.15 starts to follow the noise (measured with the sum of log position RMSE over nine cases:
/// best between 0.04 and 0.08).
const PROCESS_ADAPTATION_RATE: f64 = 0.05;
/// The trend of the corrections is averaged over this many cycles of the target's points.
const TREND_CYCLES: f64 = 2.0;
/// Bounds of the process-noise scale, relative to the tuning's densities.
const PROCESS_SCALE_RANGE: (f64, f64) = (1e-4, 1e4);
/// Degrees of freedom of the window residual that the noise estimate remembers (an exponential memory): 2,000 dof
/// (100 control steps of a 16-point window) estimate the variance to ±3 %.
const NOISE_MEMORY_DOF: f64 = 2000.0;
/// Smallest redundancy (2 x measurements - 12) of a window that feeds the noise estimate.
const MIN_NOISE_DOF: usize = 8;
/// Largest factor by which one window may raise the noise variance: a window that holds an outlier does not drag it
/// up.
const NOISE_STEP_FACTOR: f64 = 4.0;

/// The centroid noise learnt from the redundancy of the measurement windows.
///
/// At every control step the window's least-squares residual at its own optimum, `eᵀe - eᵀJ (JᵀJ)⁻¹ Jᵀe`, divided by
/// its redundancy `2 m - 12` (m measurements, 12 parameters), is an unbiased sample of the noise variance per axis
/// as long as the constant twist holds over the window (a few milliseconds of ROIs). Unlike the innovations it does
/// not depend on the process noise: a filter that lags does not mistake its lag for noise.
#[derive(Debug, Clone, Copy, PartialEq)]
struct NoiseEstimate {
    variance_px2: f64,
    /// Degrees of freedom behind the estimate (capped at [`NOISE_MEMORY_DOF`]).
    dof: f64,
}

impl NoiseEstimate {
    fn new(noise_px: f64, dof: f64) -> Self {
        Self {
            variance_px2: noise_px * noise_px,
            dof,
        }
    }

    /// Folds in one window's residual variance, worth `dof` degrees of freedom.
    fn add(&mut self, sample_px2: f64, dof: f64) {
        if !(sample_px2.is_finite() && dof > 0.0) {
            return;
        }
        let floor = super::track::MIN_NOISE_PX * super::track::MIN_NOISE_PX;
        // Only upwards: a window that holds an outlier the gate let through must not drag the estimate up, but a
        // quiet window is no outlier (after a start from a noisy initial fit, the estimate must come down fast).
        let sample = sample_px2
            .min(self.variance_px2 * NOISE_STEP_FACTOR)
            .max(floor);
        let weight = dof / (self.dof.min(NOISE_MEMORY_DOF) + dof);
        self.variance_px2 += weight * (sample - self.variance_px2);
        self.dof += dof;
    }

    fn noise_px(&self) -> f64 {
        self.variance_px2.sqrt()
    }
}

/// The Kalman filter's part of a track: the filter's covariance, its gate counters and what it learns online.
#[derive(Debug, Clone)]
struct KalmanLaw {
    filter: ErrorStateKalman,
    /// Measurements rejected by the gate in a row, and covariance resets since the last estimate.
    gated_in_a_row: usize,
    covariance_resets: usize,
    /// How far the covariance is widened at the next reset (escalates while resets follow each other) and the
    /// measurements accepted in a row since the last one.
    reset_level: usize,
    accepted_in_a_row: usize,
    /// Innovations since the last estimate: the filter's residual figures.
    innovations: ResidualTally,
    /// Measurements rejected by the gate since the last estimate, and since the start.
    gated_since_estimate: usize,
    gated_total: usize,
    resets_total: usize,
    /// The squared Mahalanobis distance of the newest measurement's innovation.
    newest_nis: f64,
    /// The learnt centroid noise (when `tuning.adapt_noise`).
    noise: NoiseEstimate,
    /// Whether the measurements come a frame at a time (the blobs of global-shutter frames, several at each time),
    /// from the initial window and then from each control step: each frame samples the noise from its own blobs
    /// ([`NoiseSample`]), and the process noise is not adapted.
    frame_steps: bool,
    /// Per point: the time of its newest measurement if the gate rejected it.
    gated_at: Vec<Option<f64>>,
    /// Natural logarithms of the factors applied to the linear and the angular acceleration density (when
    /// `tuning.adapt_motion`).
    process_log_scale: [f64; 2],
    /// The scales of the reported twist covariance (when `tuning.calibrate_twist_covariance`).
    calibration: TwistCalibration,
}

impl Law for KalmanLaw {
    fn begin_track(&mut self, core: &TrackCore, covariance: Option<Matrix12>) {
        *self = Self {
            filter: ErrorStateKalman::new(
                covariance.unwrap_or_else(|| core.prior_covariance()),
                self.filter.tuning,
                1.0 / (TREND_CYCLES * core.target.len() as f64),
            ),
            gated_total: self.gated_total,
            resets_total: self.resets_total,
            // The initial fit's noise (set in `core.noise_px`) counts as one window's worth; the process scale
            // carries over from the previous track.
            noise: NoiseEstimate::new(core.noise_px, 2.0 * core.target.len() as f64),
            process_log_scale: self.process_log_scale,
            // From the measurements the track starts from, if there are enough (a track started from a whole frame
            // has none in its window yet).
            frame_steps: if core.window_len() >= 2 * core.target.len() {
                core.recent_are_frames(2 * core.target.len())
            } else {
                self.frame_steps
            },
            // The scales carry over too; the history of poses starts again.
            calibration: {
                let mut calibration =
                    std::mem::replace(&mut self.calibration, TwistCalibration::new());
                calibration.restart();
                calibration
            },
            gated_at: {
                let mut gated_at = std::mem::take(&mut self.gated_at);
                gated_at.clear();
                gated_at.resize(core.target.len(), None);
                gated_at
            },
            ..Self::new(self.filter.tuning)
        };
    }

    fn adapts_noise(&self) -> bool {
        self.filter.tuning.adapt_noise
    }

    fn on_measurement(&mut self, core: &mut TrackCore, obs: &Observation) {
        let dt = obs.t_s - core.t_ref_s;
        self.filter
            .predict(&mut core.state, dt, self.process_log_scale.map(f64::exp));
        core.t_ref_s = obs.t_s;
        let p = core.target.points()[obs.point_index].point_in_obj_m;
        let outcome = self.filter.update(
            &core.model,
            &mut core.state,
            &p,
            &obs.ideal_px,
            core.noise_px,
        );
        if let UpdateOutcome::Accepted { norm_px, nis } | UpdateOutcome::Gated { norm_px, nis } =
            outcome
        {
            self.innovations.add(norm_px);
            self.newest_nis = nis;
        }
        // Only measurements the gate let through teach the process noise: an outlier's innovation along the trend
        // says nothing about the motion. A manoeuvre the filter lags shows in the accepted ones first. Measurements
        // that come a frame at a time do not: the persistence follows the corrections from one measurement to the
        // next, which within a frame are one instant, and from one frame to the next tens of milliseconds apart (on
        // 16-point frames at 30 Hz, 0.03 px, the adaptation chased them to 14.6 mm). Nor does a measurement at the
        // time of the one before it, before the first step has told the stream's kind.
        if self.filter.tuning.adapt_motion
            && !self.frame_steps
            && dt != 0.0
            && matches!(outcome, UpdateOutcome::Accepted { .. })
        {
            self.adapt_process_scale(self.filter.persistence);
        }
        // Outliers are rare and scattered; a run of gated measurements means the filter itself is off (after a jump
        // of the target, or an outlier that got through): widen its covariance so the measurements pull it back,
        // instead of coasting on a wrong state.
        if let Some(gated_at) = self.gated_at.get_mut(obs.point_index) {
            *gated_at = matches!(outcome, UpdateOutcome::Gated { .. }).then_some(obs.t_s);
        }
        if matches!(outcome, UpdateOutcome::Gated { .. }) {
            self.gated_since_estimate += 1;
            self.gated_total += 1;
            self.gated_in_a_row += 1;
            self.accepted_in_a_row = 0;
        } else {
            self.gated_in_a_row = 0;
            self.accepted_in_a_row += 1;
        }
        if self.accepted_in_a_row >= ACCEPTED_IN_A_ROW_FOR_CALM {
            self.reset_level = 0;
        }
        if self.gated_in_a_row >= GATED_IN_A_ROW_FOR_RESET {
            // Escalate: a run of rejections is more often a bad update than a jump of the target; a little widening
            // lets the measurements correct it without exposing the filter to every outlier, and if the runs go on
            // (a jump), the next resets widen it to the broad prior.
            let scale = RESET_SCALES[self.reset_level.min(RESET_SCALES.len() - 1)];
            self.filter.covariance += core.prior_covariance() * scale;
            self.reset_level += 1;
            self.gated_in_a_row = 0;
            self.covariance_resets += 1;
            self.resets_total += 1;
        }
    }

    fn control_step(&mut self, core: &mut TrackCore, t_new_s: f64) -> Step {
        // The filter is already at t_new; the window only gives the conditioning figure and the noise sample.
        let ne = core.window_problem(t_new_s).normal_equations(&core.state);
        let solved = ne.solve_with_conditioning();
        let inverse_condition = solved.map_or(0.0, |(_, c)| c);
        self.frame_steps = core.recent_are_frames(core.step_measurements);
        if self.filter.tuning.adapt_noise {
            self.learn_noise(core, t_new_s, &ne, solved.map(|(step, _)| step));
        }
        // After a covariance reset the filter is re-converging: say so.
        let status = if self.covariance_resets > 0 {
            self.covariance_resets = 0;
            TrackStatus::Converging
        } else if core.is_degenerate(inverse_condition) {
            TrackStatus::Degenerate
        } else {
            TrackStatus::Tracking
        };
        let covariance = if self.filter.tuning.calibrate_twist_covariance {
            self.calibration.record(
                t_new_s,
                &core.state,
                &self.filter.covariance,
                status == TrackStatus::Tracking,
            );
            self.calibration.apply(&self.filter.covariance)
        } else {
            self.filter.covariance
        };
        Step {
            inverse_condition,
            measurements_used: ne.count(),
            iterations: core.step_measurements,
            status,
            covariance: Some(covariance),
        }
    }

    /// A run of rejected measurements, a newest measurement far beyond the gate, or most of those since the last
    /// estimate rejected (the filter was reset after a run of them and is still re-converging). One measurement
    /// just beyond the gate is not enough: 1.1 % of good measurements land there.
    fn is_disputed(&self, core: &TrackCore, _residuals: &ResidualFigures) -> bool {
        self.gated_in_a_row >= DISPUTED_AFTER_GATED_IN_A_ROW
            || (self.gated_in_a_row > 0 && self.newest_nis > DISPUTED_NIS)
            || 2 * self.gated_since_estimate >= core.step_measurements.max(2)
    }

    fn after_estimate(&mut self) {
        self.gated_since_estimate = 0;
        self.innovations.clear();
    }

    /// The innovations of the measurements since the last estimate, each against the prediction from the one
    /// before: what tells a filter that follows its measurements from one that has lost them. The residual of the
    /// window at the emitted state would also count the constant-twist model's error over the window's span, which
    /// under strong acceleration reaches pixels within a rolling-shutter frame (17 m/s² over a 30 ms readout: 19 px)
    /// while the filter, updated at each blob's own time, follows well.
    fn own_residuals(&self) -> Option<ResidualFigures> {
        self.innovations.figures()
    }

    fn add_to_report(&self, report: &mut EstimatorReport) {
        report.gated = self.gated_total;
        report.covariance_resets = self.resets_total;
    }
}

/// Gated measurements in a row that dispute an estimate (3 in a row happen by chance once in 700,000 good ones).
const DISPUTED_AFTER_GATED_IN_A_ROW: usize = 3;
/// A newest measurement gated with a normalised innovation squared above this (5 σ: once in 270,000 good
/// measurements) disputes the estimate on its own.
const DISPUTED_NIS: f64 = 25.0;

impl KalmanLaw {
    fn new(tuning: KalmanTuning) -> Self {
        Self {
            filter: ErrorStateKalman::new(Matrix12::identity(), tuning, 0.0),
            gated_in_a_row: 0,
            covariance_resets: 0,
            reset_level: 0,
            accepted_in_a_row: 0,
            innovations: ResidualTally::default(),
            gated_since_estimate: 0,
            gated_total: 0,
            resets_total: 0,
            newest_nis: 0.0,
            noise: NoiseEstimate::new(1.0, 0.0),
            process_log_scale: [0.0; 2],
            frame_steps: false,
            gated_at: Vec::new(),
            calibration: TwistCalibration::new(),
        }
    }

    /// Moves each process-noise scale (linear, angular) towards the one that makes the innovations white: a positive
    /// persistence (the corrections keep going one way: the filter lags the motion) raises it, a negative one (they
    /// undo each other: the filter chases the noise, as it does on a still target) lowers it. Clamped at 3 so that
    /// one outlier moves it by at most 16 %.
    fn adapt_process_scale(&mut self, persistence: [f64; 2]) {
        for (scale, z) in self.process_log_scale.iter_mut().zip(persistence) {
            *scale = (*scale + PROCESS_ADAPTATION_RATE * z.clamp(-3.0, 3.0))
                .clamp(PROCESS_SCALE_RANGE.0.ln(), PROCESS_SCALE_RANGE.1.ln());
        }
    }

    /// Folds the residual of the window at its least-squares optimum into the noise estimate. Targets of fewer than
    /// 10 points take a longer window, so that it has a redundancy of at least [`MIN_NOISE_DOF`]. Measurements the
    /// gate rejected are left out (an outlier of 5-20 px would count as much noise as a hundred good centroids),
    /// unless they are more than a quarter of the window: then the noise itself has grown beyond the estimate, and
    /// they must count for the estimate to follow.
    fn learn_noise(
        &mut self,
        core: &mut TrackCore,
        t_new_s: f64,
        ne: &crate::solver::NormalEquations<12>,
        step: Option<crate::Vector12>,
    ) {
        if self.frame_steps {
            self.learn_noise_from_frames(core, t_new_s);
            return;
        }
        // With frames, the other steps are rolling-shutter frames, which are not sampled.
        if self.filter.tuning.noise_sample == NoiseSample::Frames {
            return;
        }
        let min_measurements = (12 + MIN_NOISE_DOF).div_ceil(2);
        let mut rebuilt = false;
        if ne.count() < min_measurements {
            core.fill_scratch(super::WindowMode::Last(min_measurements));
            rebuilt = true;
        }
        rebuilt |= drop_gated(&self.gated_at, &mut core.scratch);
        let (cost_px2, count) = if rebuilt {
            let window = core.window_problem(t_new_s).normal_equations(&core.state);
            let Some((step, _)) = window.solve_with_conditioning() else {
                return;
            };
            (window.cost_px2() + step.dot(window.jte()), window.count())
        } else {
            let Some(step) = step else { return };
            (ne.cost_px2() + step.dot(ne.jte()), ne.count())
        };
        if 2 * count < 12 + MIN_NOISE_DOF {
            return;
        }
        let dof = (2 * count - 12) as f64;
        self.noise.add(
            cost_px2.max(0.0) / dof / self.gate_truncated_fraction(),
            dof,
        );
        core.noise_px = self.noise.noise_px();
    }

    /// Every measurement a noise sample keeps lies inside the gate: the sample is that of a noise truncated at the
    /// gate's Mahalanobis radius g, whose variance is this fraction, (1 - (1 + g²/2) e^(-g²/2)) / (1 - e^(-g²/2)),
    /// of the noise's (0.949 at 3 σ; measured on clean orthoglide without the correction: 0.92).
    fn gate_truncated_fraction(&self) -> f64 {
        let g2 = self.filter.tuning.gate_sigma * self.filter.tuning.gate_sigma;
        let tail = (-g2 / 2.0).exp();
        (1.0 - (1.0 + g2 / 2.0) * tail) / (1.0 - tail)
    }

    /// Folds the residuals of the step's frames into the noise estimate: each frame's blobs (those that share one
    /// time) with its pose alone fitted, the twist held at the filter's, of redundancy `2 m - 6`; frames of fewer
    /// than 4 blobs are left out, and so are the blobs the gate rejected, unless they are more than a quarter of
    /// their frame. Corrected for the gate's truncation as the windows are: the first blobs of a frame meet a gate
    /// widened by the prediction's spread, but the frame's later ones, once those have pinned the pose, one not much
    /// wider than the noise (without the correction, four dots at 0.3 px learnt 0.297 px and tracked 7 % worse than
    /// the filter told the noise; with it, 0.307 px and as well).
    fn learn_noise_from_frames(&mut self, core: &mut TrackCore, t_new_s: f64) {
        let step = core.step_measurements;
        let (mut cost_px2, mut dof, mut taken) = (0.0, 0.0, 0);
        while taken < step {
            let count = core.fill_scratch_with_instant(step, taken);
            if count == 0 {
                break;
            }
            taken += count;
            drop_gated(&self.gated_at, &mut core.scratch);
            if core.scratch.len() < 4 {
                continue;
            }
            let frame = core.window_problem(t_new_s).normal_equations(&core.state);
            if let Some(frame_cost_px2) = pose_only_optimum_cost_px2(&frame) {
                cost_px2 += frame_cost_px2;
                dof += (2 * frame.count() - 6) as f64;
            }
        }
        if dof > 0.0 {
            self.noise
                .add(cost_px2 / dof / self.gate_truncated_fraction(), dof);
            core.noise_px = self.noise.noise_px();
        }
    }
}

/// Leaves out of a noise sample's `scratch` the measurements the gate rejected (per point, the time of its newest
/// rejected one, `gated_at`): an outlier of 5-20 px would count as much noise as a hundred good centroids. Unless they
/// are more than a quarter of it: then the noise itself has grown beyond the estimate, and they must count for the
/// estimate to follow. Returns whether any was left out.
fn drop_gated(gated_at: &[Option<f64>], scratch: &mut Vec<Observation>) -> bool {
    let is_gated = |o: &Observation| gated_at.get(o.point_index) == Some(&Some(o.t_s));
    let gated = scratch.iter().filter(|o| is_gated(o)).count();
    let drop = gated > 0 && 4 * gated <= scratch.len();
    if drop {
        scratch.retain(|o| !is_gated(o));
    }
    drop
}

/// The least-squares residual `eᵀe - gᵀ H⁻¹ g` of `window` at its optimum over the pose alone (the first six
/// parameters; `H` and `g` their block of `JᵀJ` and `Jᵀe`), the twist held; `None` when that block is singular.
fn pose_only_optimum_cost_px2(window: &crate::solver::NormalEquations<12>) -> Option<f64> {
    let jtj = window.symmetric_jtj();
    let h = jtj.fixed_view::<6, 6>(0, 0).into_owned();
    let g = window.jte().fixed_rows::<6>(0).into_owned();
    // Scaled to a unit diagonal: the position (m) and rotation (rad) columns differ by orders of magnitude.
    let scale = h
        .diagonal()
        .map(|d| if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 });
    if scale.iter().any(|&s| s == 0.0) {
        return None;
    }
    let scaled = SMatrix::<f64, 6, 6>::from_fn(|i, j| h[(i, j)] * scale[i] * scale[j]);
    let scaled_g = g.component_mul(&scale);
    let reduction = scaled.cholesky()?.solve(&scaled_g).dot(&scaled_g);
    let cost = window.cost_px2() - reduction;
    cost.is_finite().then_some(cost.max(0.0))
}

/// The default estimator: an error-state Kalman filter, every centroid one update at its own time (see the
/// [module documentation](self)).
///
/// ```
/// use roitrack_core::estimator::{Estimator, KalmanEstimator, KalmanTuning, TrackerConfig};
/// use roitrack_core::{CameraModel, Measurement, Target};
///
/// let mut kalman = KalmanEstimator::new(
///     CameraModel::canonical(),
///     Target::grid4x4(),
///     TrackerConfig::default(),
///     KalmanTuning::default(),
/// )
/// .unwrap();
/// // Until two cycles over the 16 points have been seen, there is nothing to estimate.
/// let m = Measurement { t_s: 0.0, id: 0, u_px: 480.0, v_px: 480.0 };
/// assert_eq!(kalman.push(&m).unwrap(), None);
/// assert_eq!(kalman.report().measurements, 1);
/// ```
#[derive(Debug, Clone)]
pub struct KalmanEstimator(Track<KalmanLaw>);

impl KalmanEstimator {
    /// A Kalman filter for `camera` and `target` with the common options of `config` and the filter's `tuning`
    /// (which replaces `config.estimator`).
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
        tuning: KalmanTuning,
    ) -> Result<Self, ConfigError> {
        Track::new(
            camera,
            target,
            config,
            EstimatorConfig::Kalman(tuning),
            KalmanLaw::new(tuning),
        )
        .map(Self)
    }
}

super::delegate_estimator!(KalmanEstimator);
