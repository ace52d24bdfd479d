//! The 12-dof pose and velocity tracker (SPEC section 4) and its baselines (SPEC section 10).
//!
//! A [`Tracker`] takes raw centroids one at a time ([`Tracker::push`]), undistorts them, initialises itself from the
//! first cycles with no prior ([`static_pose`]), then every `k` measurements emits an [`Estimate`] at the time of the
//! newest measurement. Estimators, chosen by [`EstimatorKind`]:
//!
//! - `Kalman` (default): an error-state Kalman filter with a constant-velocity model ([`kalman`]); every centroid
//!   updates the state once, at its own time.
//! - `Vvs`: the paper's virtual visual servoing loop: predict with the current twist, then `iterations` steps
//!   `δ = -λ L⁺ e` on the window (1 iteration = the paper; more = Gauss-Newton), with the `exact` or `paper` Jacobian.
//! - `Static` baseline: static PnP on the newest centroid of each point as if simultaneous, velocity by finite
//!   differences.
//! - `Batch` baseline: Levenberg-Marquardt of the 12 parameters to convergence on the window (Ait-Aider et al.).
//!
//! Every estimator refuses to update on a degenerate window (reciprocal condition number of the column-scaled
//! Jacobian below [`TrackerConfig::min_inverse_condition`]), flags the estimate, and widens its window.

pub mod cholesky;
pub mod kalman;
pub mod normal_equations;
pub mod static_pose;
pub mod window;
pub mod window_fit;

use nalgebra::{SMatrix, Vector2};
use thiserror::Error;

use crate::{
    CameraModel, JacobianKind, Measurement, MotionState, SpatioTemporalModel, Target, so3,
};
pub use kalman::{ErrorStateKalman, KalmanTuning, Matrix12, UpdateOutcome};
use normal_equations::NormalEquations;
pub use static_pose::{InitError, PoseFit, refine_static_pose, solve_static_pose};
pub use window::{Observation, ObservationWindow, WindowMode};
pub use window_fit::RobustLoss;

/// Which estimator a [`Tracker`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EstimatorKind {
    /// Error-state Kalman filter, constant-velocity model, one update per centroid (the default).
    #[default]
    Kalman,
    /// The paper's virtual visual servoing loop (with `jacobian`, `gain`, `iterations`, `window`).
    Vvs,
    /// Baseline: static PnP as if the newest centroids were simultaneous; velocity by finite differences.
    Static,
    /// Baseline: Levenberg-Marquardt of the 12 parameters to convergence on the window.
    Batch,
}

/// Options of a [`Tracker`]. `Default` gives the recommended configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    pub estimator: EstimatorKind,
    /// Interaction matrix of the `Vvs` estimator: `Exact` (default) or the paper's eqs. 17-24.
    pub jacobian: JacobianKind,
    /// Gain λ of the `Vvs` update `δ = -λ L⁺ e` (the paper's loop; 1 = full Gauss-Newton step).
    pub gain: f64,
    /// Iterations per control step of `Vvs` (1 = the paper).
    pub iterations: usize,
    /// Which measurements a control step uses (`Vvs`, `Batch`, and the conditioning figure).
    pub window: WindowMode,
    /// Control period k: an estimate every `every` measurements (the paper: 10, i.e. 400 Hz at 4 kHz).
    pub every: usize,
    /// Centroid noise standard deviation (px): the Kalman measurement noise and the covariance scale.
    pub noise_px: f64,
    /// Windows whose column-scaled Jacobian has a reciprocal condition number below this are degenerate.
    pub min_inverse_condition: f64,
    /// Median residual (px) above which an estimate counts as bad; 3 bad estimates in a row mean lost.
    pub lost_residual_px: f64,
    /// M-estimator of the window fits (VVS, batch, initialisation): Tukey (default: it rejects gross outliers, which
    /// Huber only down-weights), Huber or none. The Kalman filter has its own (`kalman.huber_sigma`, `gate_sigma`).
    pub robust: RobustLoss,
    pub kalman: KalmanTuning,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            estimator: EstimatorKind::Kalman,
            jacobian: JacobianKind::Exact,
            gain: 1.0,
            iterations: 1,
            window: WindowMode::NewestPerPoint,
            every: 10,
            noise_px: 0.1,
            min_inverse_condition: 3e-3,
            lost_residual_px: 5.0,
            robust: RobustLoss::Tukey,
            kalman: KalmanTuning::default(),
        }
    }
}

/// The state of a tracker, as told by each estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackStatus {
    /// Just initialised: the first estimates after (re)initialisation.
    Converging,
    /// Normal operation.
    Tracking,
    /// The window was degenerate: the update was not applied (the state was only predicted).
    Degenerate,
    /// The residual stayed too large: the tracker drops this track and re-initialises from the next measurements.
    Lost,
    /// The newest measurement disagreed with the track beyond the outlier gate and was rejected (Kalman) or weighed
    /// nothing (robust window fits): the estimate rests on the earlier measurements. It is right if that measurement
    /// was an outlier and out of date if the target has just jumped; one measurement cannot tell which, so the
    /// estimate is not vouched for.
    Disputed,
}

impl TrackStatus {
    pub fn name(&self) -> &'static str {
        match self {
            Self::Converging => "converging",
            Self::Tracking => "tracking",
            Self::Degenerate => "degenerate",
            Self::Lost => "lost",
            Self::Disputed => "disputed",
        }
    }
}

/// One output of the tracker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Reference time (s): the time of the newest measurement used.
    pub t_ref_s: f64,
    pub state: MotionState,
    /// RMS of the window's reprojection residual at the emitted state (px, per coordinate).
    pub residual_rms_px: f64,
    /// Reciprocal condition number of the window's column-scaled Jacobian (1 perfect, 0 singular).
    pub inverse_condition: f64,
    /// Measurements in the window.
    pub measurements_used: usize,
    /// Iterations (or Kalman updates since the last estimate).
    pub iterations: usize,
    pub status: TrackStatus,
    /// Covariance of the error state (v, w, dV, dW) where the estimator has one (Kalman; Batch and Vvs give the
    /// Gauss-Newton covariance σ² (JᵀJ)⁻¹ of the window).
    pub covariance: Option<Matrix12>,
}

/// Why a measurement was refused. The tracker's state is unchanged by a refused measurement.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TrackError {
    #[error("measurement at t = {t_s} s: {field} is not finite ({value})")]
    NotFinite {
        t_s: f64,
        field: &'static str,
        value: f64,
    },
    #[error(
        "measurement at t = {t_s} s is older than the previous one ({previous_s} s): times must not decrease"
    )]
    TimeOutOfOrder { t_s: f64, previous_s: f64 },
    #[error("measurement at t = {t_s} s: point id {id} is not in the target")]
    UnknownId { t_s: f64, id: u32 },
    #[error("measurement at t = {t_s} s: {source}")]
    Undistortion {
        t_s: f64,
        #[source]
        source: crate::CameraError,
    },
}

/// Why a configuration is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConfigError {
    #[error("{field} must be {expected}, got {value}")]
    Invalid {
        field: &'static str,
        expected: &'static str,
        value: f64,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Initializing,
    Running,
}

/// Consecutive good steps needed before a widened window shrinks back; doubled at every degenerate window since the
/// initialisation (up to 2^6 times), so an acquisition order that keeps producing degenerate windows keeps the wider
/// window.
const SHRINK_AFTER_GOOD_STEPS: usize = 20;
/// Smallest residual scale (px) of the window fits' M-estimator: below it, the spread of a window's residuals is the
/// model's own (a prediction across a fast rotation, a gain-limited loop), not outliers, and must not be cut away.
/// With Tukey's c = 4.685 scales, residuals beyond about 5 px are rejected.
const ROBUST_SCALE_FLOOR_PX: f64 = 1.0;

/// Consecutive measurements rejected by the Kalman filter's gate after which its covariance is widened.
const GATED_IN_A_ROW_FOR_RESET: usize = 6;
/// Fractions of the broad prior covariance added at successive covariance resets (variance scales: 1/100 is a tenth
/// of its standard deviations).
const RESET_SCALES: [f64; 3] = [0.01, 0.1, 1.0];
/// Accepted measurements in a row after which the next reset starts small again.
const ACCEPTED_IN_A_ROW_FOR_CALM: usize = 64;

/// Estimates reported as `Converging` after an initialisation.
const CONVERGING_ESTIMATES: usize = 3;
/// Consecutive bad estimates before the track is declared lost.
const LOST_AFTER_BAD_ESTIMATES: usize = 3;

/// The streaming tracker. Built once; `push` does not allocate.
#[derive(Debug, Clone)]
pub struct Tracker {
    camera: CameraModel,
    model: SpatioTemporalModel,
    target: Target,
    config: TrackerConfig,
    window: ObservationWindow,
    /// Scratch copy of the current window, so solvers can take several passes over a slice.
    scratch: Vec<Observation>,
    phase: Phase,
    state: MotionState,
    t_ref_s: f64,
    last_t_s: Option<f64>,
    since_estimate: usize,
    estimates_since_init: usize,
    /// Window widening after a degenerate window: number of extra cycles (0 = the configured window).
    widening: usize,
    good_steps: usize,
    degenerate_windows: usize,
    bad_estimates: usize,
    /// Kalman: measurements rejected by the gate in a row, and covariance resets since the last estimate.
    gated_in_a_row: usize,
    covariance_resets: usize,
    /// Kalman: how far the covariance is widened at the next reset (escalates while resets follow each other) and the
    /// measurements accepted in a row since the last one.
    reset_level: usize,
    accepted_in_a_row: usize,
    /// Kalman: measurements rejected by the gate since the last estimate.
    gated_since_estimate: usize,
    kalman: ErrorStateKalman,
    /// Previous pose for the static baseline's finite differences.
    previous_static: Option<(f64, MotionState)>,
}

impl Tracker {
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
    ) -> Result<Self, ConfigError> {
        let check = |field, value: f64, expected, ok: bool| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(ConfigError::Invalid {
                    field,
                    expected,
                    value,
                })
            }
        };
        check(
            "gain",
            config.gain,
            "in (0, 2]",
            config.gain > 0.0 && config.gain <= 2.0,
        )?;
        check(
            "iterations",
            config.iterations as f64,
            "at least 1",
            config.iterations >= 1,
        )?;
        check(
            "every",
            config.every as f64,
            "at least 1",
            config.every >= 1,
        )?;
        check(
            "noise_px",
            config.noise_px,
            "positive",
            config.noise_px > 0.0,
        )?;
        check(
            "min_inverse_condition",
            config.min_inverse_condition,
            "in [0, 1)",
            (0.0..1.0).contains(&config.min_inverse_condition),
        )?;
        check(
            "lost_residual_px",
            config.lost_residual_px,
            "positive",
            config.lost_residual_px > 0.0,
        )?;
        check(
            "kalman.linear_accel_psd",
            config.kalman.linear_accel_psd,
            "positive",
            config.kalman.linear_accel_psd > 0.0,
        )?;
        check(
            "kalman.angular_accel_psd",
            config.kalman.angular_accel_psd,
            "positive",
            config.kalman.angular_accel_psd > 0.0,
        )?;
        check(
            "kalman.gate_sigma",
            config.kalman.gate_sigma,
            "positive",
            config.kalman.gate_sigma > 0.0,
        )?;
        if let WindowMode::Last(n) = config.window {
            check("window", n as f64, "at least 4 measurements", n >= 4)?;
        }
        let n = target.len();
        let capacity = Self::max_window(&config, n);
        Ok(Self {
            model: SpatioTemporalModel::new(camera.intrinsics),
            camera,
            window: ObservationWindow::new(n, capacity),
            scratch: Vec::with_capacity(capacity.max(n)),
            target,
            config,
            phase: Phase::Initializing,
            state: MotionState::at_rest(Default::default(), Default::default()),
            t_ref_s: 0.0,
            last_t_s: None,
            since_estimate: 0,
            estimates_since_init: 0,
            widening: 0,
            good_steps: 0,
            degenerate_windows: 0,
            bad_estimates: 0,
            gated_in_a_row: 0,
            gated_since_estimate: 0,
            covariance_resets: 0,
            reset_level: 0,
            accepted_in_a_row: 0,
            kalman: ErrorStateKalman::new(Matrix12::identity(), config.kalman),
            previous_static: None,
        })
    }

    /// Largest window the tracker may use: the configured one widened by up to 3 cycles, and 2 cycles for
    /// initialisation.
    fn max_window(config: &TrackerConfig, n: usize) -> usize {
        let configured = match config.window {
            WindowMode::NewestPerPoint => n,
            WindowMode::Last(m) => m,
        };
        configured.max(n) + 3 * n
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    pub fn target(&self) -> &Target {
        &self.target
    }

    /// The current state (at the time of the newest measurement processed), once initialised.
    pub fn state(&self) -> Option<(f64, MotionState)> {
        (self.phase == Phase::Running).then_some((self.t_ref_s, self.state))
    }

    /// Drops the current track: the next measurements initialise a new one (after a re-initialisation from a full
    /// frame, say). Measurement times must still not decrease.
    pub fn reset(&mut self) {
        self.phase = Phase::Initializing;
        self.window.clear();
        self.since_estimate = 0;
    }

    /// Starts tracking from a known state at time `t_s` (e.g. a static pose from a full frame, velocity zero) with
    /// its covariance (error-state order v, w, dV, dW), instead of initialising from the first two cycles.
    pub fn start_from(&mut self, t_s: f64, state: MotionState, covariance: Option<Matrix12>) {
        self.window.clear();
        self.last_t_s = Some(self.last_t_s.map_or(t_s, |last| last.max(t_s)));
        self.begin_track(t_s, state, covariance);
    }

    /// Starts a new track at `state` (time `t_s`): every per-track counter back to zero, the Kalman filter at
    /// `covariance` (a broad prior without one). The measurement window is kept.
    fn begin_track(&mut self, t_s: f64, state: MotionState, covariance: Option<Matrix12>) {
        self.state = state;
        self.t_ref_s = t_s;
        self.phase = Phase::Running;
        self.since_estimate = 0;
        self.estimates_since_init = 0;
        self.widening = 0;
        self.good_steps = 0;
        self.degenerate_windows = 0;
        self.bad_estimates = 0;
        self.gated_in_a_row = 0;
        self.gated_since_estimate = 0;
        self.covariance_resets = 0;
        self.reset_level = 0;
        self.accepted_in_a_row = 0;
        self.previous_static = None;
        self.kalman = ErrorStateKalman::new(
            covariance.unwrap_or_else(|| self.prior_covariance()),
            self.config.kalman,
        );
    }

    /// Takes one raw centroid; returns an estimate every `every` measurements once initialised.
    pub fn push(&mut self, m: &Measurement) -> Result<Option<Estimate>, TrackError> {
        for (field, value) in [("t", m.t_s), ("u", m.u_px), ("v", m.v_px)] {
            if !value.is_finite() {
                return Err(TrackError::NotFinite {
                    t_s: m.t_s,
                    field,
                    value,
                });
            }
        }
        if let Some(previous_s) = self.last_t_s
            && m.t_s < previous_s
        {
            return Err(TrackError::TimeOutOfOrder {
                t_s: m.t_s,
                previous_s,
            });
        }
        let point_index = self.target.index_of(m.id).ok_or(TrackError::UnknownId {
            t_s: m.t_s,
            id: m.id,
        })?;
        let ideal_px = self
            .camera
            .undistort_pixel(&Vector2::new(m.u_px, m.v_px))
            .map_err(|source| TrackError::Undistortion { t_s: m.t_s, source })?;
        self.last_t_s = Some(m.t_s);
        let obs = Observation {
            t_s: m.t_s,
            point_index,
            ideal_px,
        };
        self.window.push(obs);
        match self.phase {
            Phase::Initializing => Ok(self.try_initialize()),
            Phase::Running => {
                if self.config.estimator == EstimatorKind::Kalman {
                    self.kalman_update(&obs);
                }
                self.since_estimate += 1;
                if self.since_estimate >= self.config.every {
                    Ok(Some(self.control_step()))
                } else {
                    Ok(None)
                }
            }
        }
    }

    /// Static pose from the newest centroid of each point, then a 12-dof fit on the last two cycles, so that a target
    /// already moving at the start is initialised with its velocity.
    fn try_initialize(&mut self) -> Option<Estimate> {
        let n = self.target.len();
        let init_len = 2 * n;
        if self.window.points_seen() < n || self.window.len() < init_len {
            return None;
        }
        self.fill_scratch(WindowMode::NewestPerPoint);
        let fit = solve_static_pose(&self.model, &self.target, &self.scratch).ok()?;
        let t_ref = self.window.last(1).next()?.t_s;
        self.fill_scratch(WindowMode::Last(init_len));
        let (state, ne, iterations) = self.levenberg_marquardt(fit.state, t_ref, 50);
        let inverse_condition = ne.fast_inverse_condition();
        let well_posed = inverse_condition >= self.config.min_inverse_condition;
        // Residuals far above the noise mean a wrong local minimum or bad data: wait for more measurements.
        // The median residual, which outliers do not inflate, must be at the noise level: the 12-dof model is exact
        // over two cycles.
        let median_px = window_fit::median_residual_px(
            &self.model,
            self.target.points(),
            &state,
            t_ref,
            &self.scratch,
        )
        .unwrap_or(0.0);
        if ne.residual_rms_px() > self.config.lost_residual_px
            || median_px > (3.0 * self.config.noise_px).max(0.3)
        {
            return None;
        }
        let state = if well_posed {
            state
        } else {
            MotionState::at_rest(fit.state.cam_r_obj, fit.state.cam_t_obj_m)
        };
        let covariance = self.window_covariance(&ne, inverse_condition);
        self.begin_track(t_ref, state, covariance);
        Some(self.finish_estimate(
            inverse_condition,
            ne.count,
            iterations,
            if well_posed {
                TrackStatus::Converging
            } else {
                TrackStatus::Degenerate
            },
            covariance,
        ))
    }

    /// A broad prior when the initial window cannot give a covariance: 1 cm, 0.1 rad, 1 m/s, 10 rad/s.
    fn prior_covariance(&self) -> Matrix12 {
        let sigmas = [
            1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0, 10.0, 10.0, 10.0,
        ];
        Matrix12::from_diagonal(&SMatrix::<f64, 12, 1>::from_fn(|i, _| {
            sigmas[i] * sigmas[i]
        }))
    }

    /// σ² (JᵀJ)⁻¹ of a window, when it is well posed; `inverse_condition` is that of `ne`, already computed by the
    /// caller's step.
    fn window_covariance(
        &self,
        ne: &NormalEquations<12>,
        inverse_condition: f64,
    ) -> Option<Matrix12> {
        if inverse_condition < self.config.min_inverse_condition {
            return None;
        }
        let sigma2 = self.config.noise_px * self.config.noise_px;
        ne.symmetric_jtj().try_inverse().map(|inv| inv * sigma2)
    }

    fn effective_window(&self) -> WindowMode {
        let n = self.target.len();
        match (self.config.window, self.widening) {
            (mode, 0) => mode,
            (WindowMode::NewestPerPoint, w) => WindowMode::Last(n * (1 + w)),
            (WindowMode::Last(m), w) => WindowMode::Last(m + n * w),
        }
    }

    fn fill_scratch(&mut self, mode: WindowMode) {
        self.scratch.clear();
        self.scratch.extend(self.window.select(mode).copied());
    }

    /// Normal equations of the 12-dof problem on the scratch window at `state` (reference time `t_ref`).
    fn accumulate(
        &self,
        kind: JacobianKind,
        state: &MotionState,
        t_ref: f64,
    ) -> NormalEquations<12> {
        window_fit::window_normal_equations(
            &self.model,
            self.target.points(),
            kind,
            state,
            t_ref,
            &self.scratch,
        )
    }

    /// Levenberg-Marquardt of the 12 parameters on the scratch window, to convergence.
    fn levenberg_marquardt(
        &self,
        initial: MotionState,
        t_ref: f64,
        max_iterations: usize,
    ) -> (MotionState, NormalEquations<12>, usize) {
        // Least squares first: from a rough start (a static pose of a moving target, a prediction across a fast
        // rotation) the residuals are large for every point and a robust loss would discard the good ones. Then the
        // robust refinement from there rejects the outliers.
        let (state, ne, iterations) = window_fit::levenberg_marquardt(
            &self.model,
            self.target.points(),
            initial,
            t_ref,
            &self.scratch,
            max_iterations,
        );
        if self.config.robust == RobustLoss::None {
            return (state, ne, iterations);
        }
        // Two rounds: the second, with the scale of the cleaner first fit, rejects what the first (started from a
        // fit pulled by the outliers) kept.
        let (mut state, mut ne, mut iterations) = (state, ne, iterations);
        for _ in 0..2 {
            let (next, next_ne, more) = window_fit::robust_levenberg_marquardt(
                &self.model,
                self.target.points(),
                state,
                t_ref,
                &self.scratch,
                max_iterations,
                self.config.robust,
                self.robust_scale_px(&state, t_ref),
            );
            (state, ne, iterations) = (next, next_ne, iterations + more);
        }
        (state, ne, iterations)
    }

    /// The M-estimator's residual scale of the scratch window at `state` (at least the noise and 1 px).
    /// The smallest robust scale of the window fits (px): the noise, and at least [`ROBUST_SCALE_FLOOR_PX`].
    fn robust_scale_floor_px(&self) -> f64 {
        ROBUST_SCALE_FLOOR_PX.max(self.config.noise_px)
    }

    fn robust_scale_px(&self, state: &MotionState, t_ref: f64) -> f64 {
        window_fit::robust_scale_px(
            &self.model,
            self.target.points(),
            state,
            t_ref,
            &self.scratch,
            self.robust_scale_floor_px(),
        )
    }

    fn kalman_update(&mut self, obs: &Observation) {
        let dt = obs.t_s - self.t_ref_s;
        self.kalman.predict(&mut self.state, dt);
        self.t_ref_s = obs.t_s;
        let p = self.target.points()[obs.point_index].point_in_obj_m;
        let outcome = self.kalman.update(
            &self.model,
            &mut self.state,
            &p,
            &obs.ideal_px,
            self.config.noise_px,
        );
        // Outliers are rare and scattered; a run of gated measurements means the filter itself is off (after a jump
        // of the target, or an outlier that got through): widen its covariance so the measurements pull it back,
        // instead of coasting on a wrong state.
        if outcome == UpdateOutcome::Gated {
            self.gated_since_estimate += 1;
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
            self.kalman.covariance += self.prior_covariance() * scale;
            self.reset_level += 1;
            self.gated_in_a_row = 0;
            self.covariance_resets += 1;
        }
    }

    /// One control step at the newest measurement's time.
    fn control_step(&mut self) -> Estimate {
        self.since_estimate = 0;
        let t_new = self.last_t_s.unwrap_or(self.t_ref_s);
        let mode = self.effective_window();
        self.fill_scratch(mode);
        match self.config.estimator {
            EstimatorKind::Kalman => {
                // The filter is already at t_new; the window only gives the residual and conditioning figures.
                let ne = self.accumulate(JacobianKind::Exact, &self.state, t_new);
                let inverse_condition = ne.fast_inverse_condition();
                self.track_conditioning(inverse_condition);
                // After a covariance reset the filter is re-converging: say so.
                let status = if self.covariance_resets > 0 {
                    self.covariance_resets = 0;
                    TrackStatus::Converging
                } else if inverse_condition < self.config.min_inverse_condition {
                    TrackStatus::Degenerate
                } else {
                    TrackStatus::Tracking
                };
                let covariance = Some(self.kalman.covariance);
                self.finish_estimate(
                    inverse_condition,
                    ne.count,
                    self.config.every,
                    status,
                    covariance,
                )
            }
            EstimatorKind::Vvs => {
                self.state = self.state.predicted(t_new - self.t_ref_s);
                self.t_ref_s = t_new;
                let mut inverse_condition = 1.0;
                let mut status = TrackStatus::Tracking;
                let mut iterations = 0;
                let mut last_ne = None;
                for _ in 0..self.config.iterations {
                    let scale_px = self.robust_scale_px(&self.state, t_new);
                    let step = window_fit::robust_vvs_iteration(
                        &self.model,
                        self.target.points(),
                        self.config.jacobian,
                        &self.state,
                        t_new,
                        &self.scratch,
                        self.config.gain,
                        self.config.min_inverse_condition,
                        self.config.robust,
                        scale_px,
                    );
                    inverse_condition = step.inverse_condition;
                    last_ne = Some(step.normal_equations);
                    if !step.applied {
                        status = TrackStatus::Degenerate;
                        break;
                    }
                    self.state = step.state;
                    iterations += 1;
                    if step.step_norm < 1e-12 {
                        break;
                    }
                }
                self.track_conditioning(inverse_condition);
                let covariance = last_ne
                    .as_ref()
                    .and_then(|ne| self.window_covariance(ne, inverse_condition));
                self.finish_estimate(
                    inverse_condition,
                    self.scratch.len(),
                    iterations,
                    status,
                    covariance,
                )
            }
            EstimatorKind::Batch => {
                let predicted = self.state.predicted(t_new - self.t_ref_s);
                self.t_ref_s = t_new;
                let (state, ne, iterations) = self.levenberg_marquardt(predicted, t_new, 30);
                let inverse_condition = ne.fast_inverse_condition();
                self.track_conditioning(inverse_condition);
                let status = if inverse_condition < self.config.min_inverse_condition
                    || !state.is_finite()
                {
                    self.state = predicted;
                    TrackStatus::Degenerate
                } else {
                    self.state = state;
                    TrackStatus::Tracking
                };
                let covariance = self.window_covariance(&ne, inverse_condition);
                self.finish_estimate(inverse_condition, ne.count, iterations, status, covariance)
            }
            EstimatorKind::Static => {
                self.fill_scratch(WindowMode::NewestPerPoint);
                let fit =
                    refine_static_pose(&self.model, &self.target, &self.scratch, &self.state, 20);
                self.track_conditioning(fit.inverse_condition);
                let mut state = fit.state;
                if let Some((t_prev, prev)) = self.previous_static {
                    let dt = t_new - t_prev;
                    if dt > 0.0 {
                        state.velocity_mps = (state.cam_t_obj_m - prev.cam_t_obj_m) / dt;
                        state.angular_velocity_radps =
                            so3::log(&(state.cam_r_obj * prev.cam_r_obj.inverse())) / dt;
                    }
                }
                let status = if fit.inverse_condition < self.config.min_inverse_condition
                    || !state.is_finite()
                {
                    TrackStatus::Degenerate
                } else {
                    self.previous_static = Some((t_new, state));
                    self.state = state;
                    TrackStatus::Tracking
                };
                self.t_ref_s = t_new;
                self.finish_estimate(
                    fit.inverse_condition,
                    self.scratch.len(),
                    fit.iterations,
                    status,
                    None,
                )
            }
        }
    }

    /// Widens the window after a degenerate step; shrinks it back after a run of good ones.
    fn track_conditioning(&mut self, inverse_condition: f64) {
        if inverse_condition < self.config.min_inverse_condition {
            self.widening = (self.widening + 1).min(3);
            self.good_steps = 0;
            self.degenerate_windows += 1;
        } else {
            self.good_steps += 1;
            let shrink_after = SHRINK_AFTER_GOOD_STEPS << self.degenerate_windows.min(6);
            if self.widening > 0 && self.good_steps >= shrink_after {
                self.widening -= 1;
                self.good_steps = 0;
            }
        }
    }

    /// Residual at the emitted state, status bookkeeping (converging, lost), and the estimate itself.
    fn finish_estimate(
        &mut self,
        inverse_condition: f64,
        measurements_used: usize,
        iterations: usize,
        status: TrackStatus,
        covariance: Option<Matrix12>,
    ) -> Estimate {
        // Residual over the configured window at the emitted state (static: as if simultaneous, as it fits). The
        // track is judged on the median residual: a few outliers in the window must not make it look lost.
        let (residual_rms_px, residual_median_px, newest_residual_px) = self.residual_figures_px();
        let disputed = match self.config.estimator {
            // The newest measurement rejected, or most of those since the last estimate (the filter was reset after a
            // run of them and is still re-converging).
            EstimatorKind::Kalman => {
                self.gated_in_a_row > 0 || 2 * self.gated_since_estimate >= self.config.every.max(2)
            }
            // The robust scale of the window fits (see `robust_scale_px`); beyond Tukey's c a measurement weighs
            // nothing.
            EstimatorKind::Vvs | EstimatorKind::Batch => {
                let scale_px = window_fit::scale_from_median_px(
                    residual_median_px,
                    self.robust_scale_floor_px(),
                );
                newest_residual_px > RobustLoss::TUKEY_C * scale_px
            }
            EstimatorKind::Static => false,
        };
        let mut status = status;
        let bad = !residual_median_px.is_finite()
            || residual_median_px > self.config.lost_residual_px
            || !self.state.is_finite();
        self.bad_estimates = if bad { self.bad_estimates + 1 } else { 0 };
        if self.bad_estimates >= LOST_AFTER_BAD_ESTIMATES {
            status = TrackStatus::Lost;
            self.phase = Phase::Initializing;
            self.window.clear();
        } else if disputed && matches!(status, TrackStatus::Tracking | TrackStatus::Converging) {
            status = TrackStatus::Disputed;
        } else if status == TrackStatus::Tracking
            && self.estimates_since_init < CONVERGING_ESTIMATES
        {
            status = TrackStatus::Converging;
        }
        self.estimates_since_init += 1;
        self.gated_since_estimate = 0;
        Estimate {
            t_ref_s: self.t_ref_s,
            state: self.state,
            residual_rms_px,
            inverse_condition,
            measurements_used,
            iterations,
            status,
            covariance,
        }
    }

    /// RMS residual (px per coordinate), median residual norm (px) and the residual norm of the newest measurement
    /// (px) of the scratch window at the current state.
    fn residual_figures_px(&self) -> (f64, f64, f64) {
        const MAX: usize = 128;
        let points = self.target.points();
        let simultaneous = self.config.estimator == EstimatorKind::Static;
        let mut norms = [0.0f64; MAX];
        let (mut sum, mut count) = (0.0, 0usize);
        let (mut newest_t_s, mut newest_px) = (f64::NEG_INFINITY, 0.0);
        for o in &self.scratch {
            let d = if simultaneous {
                0.0
            } else {
                o.t_s - self.t_ref_s
            };
            match self
                .model
                .project(&self.state, &points[o.point_index].point_in_obj_m, d)
            {
                Some(px) => {
                    let r2 = (px - o.ideal_px).norm_squared();
                    sum += r2;
                    if count < MAX {
                        norms[count] = r2.sqrt();
                    }
                    if o.t_s >= newest_t_s {
                        (newest_t_s, newest_px) = (o.t_s, r2.sqrt());
                    }
                }
                None => return (f64::INFINITY, f64::INFINITY, f64::INFINITY),
            }
            count += 1;
        }
        if count == 0 {
            return (0.0, 0.0, 0.0);
        }
        let n = count.min(MAX);
        let (_, median, _) = norms[..n].select_nth_unstable_by(n / 2, f64::total_cmp);
        ((sum / (2 * count) as f64).sqrt(), *median, newest_px)
    }
}

/// 1-sigma standard deviations of an error-state covariance, in the order (v, w, dV, dW).
pub fn standard_deviations(covariance: &Matrix12) -> [f64; 12] {
    std::array::from_fn(|i| covariance[(i, i)].max(0.0).sqrt())
}
