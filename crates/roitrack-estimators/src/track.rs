//! What every estimator shares: measurement checks and undistortion, the measurement window, initialisation from no
//! prior, the degeneracy gate's window widening, and the status of each estimate (converging, tracking, degenerate,
//! disputed, lost). [`Track`] runs this around a [`Law`], the part that differs between estimators: what a
//! measurement does to the state, what a control step does, and when an estimate is disputed.
//!
//! Each public estimator ([`super::KalmanEstimator`], [`super::VvsEstimator`], [`super::BatchEstimator`],
//! [`super::StaticEstimator`]) is a `Track` of its own law, so the per-measurement path is monomorphised: no
//! dispatch inside the hot loop.

use nalgebra::{SMatrix, Vector2};

use super::problem::{Observation, ResidualFigures, WindowProblem, scale_from_median_px};
use super::window::ObservationWindow;
use super::{
    ConfigError, Emit, Estimate, EstimatorConfig, EstimatorReport, InitError, Matrix12, RobustLoss,
    StartFailure, TrackError, TrackStatus, TrackerConfig, WindowMode,
    model_error::{ModelEffect, cost_difference_effect},
    static_pose::{MODEL_SPREAD_SIGMAS, PixelNoise, PoseFit, solve_static_pose},
};
use roitrack_core::solver::{DampingSchedule, Method, NormalEquations, SolverOptions};
use roitrack_core::{CameraModel, Measurement, MotionState, SpatioTemporalModel, Target};

/// Consecutive good steps needed before a widened window shrinks back; doubled at every degenerate window since the
/// initialisation (up to 2^6 times), so an acquisition order that keeps producing degenerate windows keeps the wider
/// window.
const SHRINK_AFTER_GOOD_STEPS: usize = 20;
/// Smallest residual scale (px) of the window fits' M-estimator: below it, the spread of a window's residuals is the
/// model's own (a prediction across a fast rotation, a gain-limited loop), not outliers, and must not be cut away.
/// With Tukey's c = 4.685 scales, residuals beyond about 5 px are rejected.
const ROBUST_SCALE_FLOOR_PX: f64 = 1.0;
/// Smallest redundancy (equations beyond the 12 unknowns) of a window whose 12-parameter fit is vouched for.
pub(crate) const MIN_FIT_REDUNDANCY: usize = 4;
/// On a target of fewer than [`SMALL_TARGET_POINTS`] points, a default window ([`WindowMode::NewestPerPoint`]) of the
/// window fits takes whole cycles up to this many measurements. One cycle of a 3 x 3 grid (18 equations for 12
/// unknowns) leaves the state so loosely tied that the servo loops wandered far off with small residuals, vouched
/// for; three cycles (27 measurements) kept the exact loop near the path (measured in docs/results.md, "Design
/// measurements behind the code"). Targets of 12 points or more keep the newest measurement of each point (the
/// paper's window; 16 points give 32 equations).
pub(crate) const MIN_DEFAULT_WINDOW_MEASUREMENTS: usize = 24;
/// See [`MIN_DEFAULT_WINDOW_MEASUREMENTS`].
pub(crate) const SMALL_TARGET_POINTS: usize = 12;

/// Cycles of a default window for a target of `n` points: whole cycles up to [`MIN_DEFAULT_WINDOW_MEASUREMENTS`] on
/// a small target, one otherwise.
fn default_window_cycles(n: usize) -> usize {
    if n < SMALL_TARGET_POINTS {
        MIN_DEFAULT_WINDOW_MEASUREMENTS.div_ceil(n.max(1))
    } else {
        1
    }
}
/// A window fit's estimate whose residual RMS at the emitted state exceeds this many times the centroid noise is
/// not vouched for (disputed): the state does not explain its own window.
pub(crate) const MAX_RESIDUAL_NOISE_RATIO: f64 = 3.0;
/// Estimates reported as `Converging` after an initialisation.
const CONVERGING_ESTIMATES: usize = 3;
/// Consecutive bad estimates before the track is declared lost.
const LOST_AFTER_BAD_ESTIMATES: usize = 3;
/// Levenberg-Marquardt iterations of the initial 12-dof fit.
const INIT_MAX_ITERATIONS: usize = 50;
/// Largest median residual (px) of an initial fit accepted by an estimator that learns the noise: the noise is not
/// known, so the fit is judged only against gross failures (a wrong local minimum leaves residuals of many pixels).
/// 2.5 px is the median residual norm of 2.1 px noise per axis.
pub(crate) const ADAPTIVE_INIT_MAX_MEDIAN_PX: f64 = 2.5;
/// The smallest noise (px) an estimator that learns it may settle on.
pub(crate) const MIN_NOISE_PX: f64 = 0.005;
/// The median of the norm of a 2-d Gaussian residual of σ = 1 per axis (Rayleigh: √(2 ln 2)).
const RAYLEIGH_MEDIAN: f64 = 1.177_410_022_515_474_7;

/// The solver's options for the start candidates' fits, which are judged by their costs: Levenberg-Marquardt stopped
/// once a step lowers the cost by less than 1e-6 of it, instead of the window fits' 1e-12. A rival's fit (a mirror
/// twin's, say) has residuals far above the noise, where Gauss-Newton converges only linearly: to 1e-12 it ran to the
/// iteration limit at every attempt of a start that stays ambiguous, a third of a rig's whole run. What the judgement
/// needs is each cost to well within the ambiguity bound (`AMBIGUITY_CHI2_12DOF` centroid variances); the costs of
/// the fits stopped at 1e-6 are that close to those run to 1e-12 (docs/results.md). The winner is then taken to its
/// minimum as before.
fn start_judgement_options() -> SolverOptions {
    SolverOptions {
        max_iterations: INIT_MAX_ITERATIONS,
        method: Method::LevenbergMarquardt(DampingSchedule {
            relative_decrease: Some(1e-6),
            ..DampingSchedule::WINDOW
        }),
    }
}

/// A rival whose excess cost is within this factor of the ambiguity bound is near: a start past it is confirmed by
/// the next attempt.
const NEAR_RIVAL_FACTOR: f64 = 4.0;
/// Two start fits nearer than this ([`MotionState::pose_distance`]) reached one minimum.
const SAME_START_POSE: f64 = 1e-3;
/// The ambiguity bound of two 12-dof fits (in noise variances): each absorbs the noise along its own 12 directions,
/// so for twins that fit noise-free data alike the cost difference is that of two χ² of 12 degrees of freedom, which
/// exceeds 30 with a chance of 1.1e-4, 36 with 1.2e-5 and 40 with 2.5e-6 (simulated, 2e7 draws).
const AMBIGUITY_CHI2_12DOF: f64 = 36.0;

/// How start candidates compare once fitted with their twist ([`TrackCore::judge_start_fits`]).
struct StartJudgement {
    /// Each candidate's 12-dof fit.
    fits: Vec<MotionState>,
    /// The best fit's index.
    best: usize,
    /// Other minima within the ambiguity bound.
    rivals: usize,
    /// The nearest other minimum, if within a few times the bound.
    near_rival: Option<usize>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Initializing,
    Running,
}

/// What a control step of a [`Law`] produced; [`Track`] turns it into an [`Estimate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Step {
    pub inverse_condition: f64,
    pub measurements_used: usize,
    pub iterations: usize,
    pub status: TrackStatus,
    pub covariance: Option<Matrix12>,
    pub acceleration: Option<roitrack_core::Acceleration>,
}

/// The part of an estimator that differs from the others.
pub(crate) trait Law: Clone + std::fmt::Debug + Send {
    /// A new track starts at `core.state` (time `core.t_ref_s`), with this covariance if the start gave one.
    fn begin_track(&mut self, core: &TrackCore, covariance: Option<Matrix12>);
    /// The state of a running track predicted to `t_s` with its pose/twist covariance, when the law has one (a
    /// filter's prediction: its accelerations and process noise included).
    fn predicted(&self, _core: &TrackCore, _t_s: f64) -> Option<(MotionState, Matrix12)> {
        None
    }
    /// A measurement of a running track, already in the window.
    fn on_measurement(&mut self, _core: &mut TrackCore, _obs: &Observation) {}
    /// The measurements of one readout (a frame's blobs, in time order) of a running track, already in the window:
    /// each in turn, unless the law takes them together.
    fn on_batch(&mut self, core: &mut TrackCore, batch: &[Observation]) {
        for obs in batch {
            self.on_measurement(core, obs);
        }
    }
    /// The control step at `t_new_s` (the newest measurement's time); `core.scratch` holds the window it uses.
    fn control_step(&mut self, core: &mut TrackCore, t_new_s: f64) -> Step;
    /// Whether the estimate just computed rests on the older measurements only: the newest was rejected.
    fn is_disputed(&self, core: &TrackCore, residuals: &ResidualFigures) -> bool;
    /// The law's own residual figures for the estimate, if it has better ones than the window's residual at the
    /// emitted state (a filter's innovations).
    fn own_residuals(&self) -> Option<ResidualFigures> {
        None
    }
    /// Whether the estimate's residuals take every measurement as simultaneous (the static baseline).
    fn simultaneous_residuals(&self) -> bool {
        false
    }
    /// After each estimate (its counters since the last one start again).
    fn after_estimate(&mut self) {}
    /// Whether the law estimates the centroid noise itself ([`TrackCore::noise_px`]): the initialisation then
    /// accepts any noise up to [`ADAPTIVE_INIT_MAX_MEDIAN_PX`] and starts the estimate from its own residual.
    fn adapts_noise(&self) -> bool {
        false
    }
    /// Adds the law's own counters to a report.
    fn add_to_report(&self, _report: &mut EstimatorReport) {}
    /// The target's known acceleration its predictions use (a control input), if the law predicts with one.
    fn known_acceleration(&mut self) -> Option<&mut super::kalman::KnownAcceleration> {
        None
    }
}

/// The state a [`Law`] works on, shared by every estimator.
#[derive(Debug, Clone)]
pub(crate) struct TrackCore {
    pub camera: CameraModel,
    pub model: SpatioTemporalModel,
    pub target: Target,
    pub config: TrackerConfig,
    window: ObservationWindow,
    /// Scratch copy of the current window, so solvers can take several passes over a slice.
    pub scratch: Vec<Observation>,
    /// Checked measurements of a batch, before any is applied.
    pending: Vec<Observation>,
    phase: Phase,
    pub state: MotionState,
    pub t_ref_s: f64,
    /// The centroid noise (px, per axis) the estimates are computed with: [`TrackerConfig::noise_px`], or the
    /// estimate of a law that learns it.
    pub noise_px: f64,
    last_t_s: Option<f64>,
    since_estimate: usize,
    /// Measurements since the last attempt to start a track that failed: after a failure the next attempt waits
    /// for a new cycle (a start is decided on whole cycles, and its static poses cost tens of microseconds).
    since_start_attempt: usize,
    /// A start decided with little margin over a rival at the previous attempt (its time and state), which the next
    /// must confirm.
    pending_start: Option<(f64, MotionState)>,
    /// Measurements the current control step answers (those since the previous estimate).
    pub step_measurements: usize,
    estimates_since_init: usize,
    /// Window widening after a degenerate window: number of extra cycles (0 = the configured window).
    widening: usize,
    good_steps: usize,
    degenerate_windows: usize,
    bad_estimates: usize,
    /// Measurements since the last disputed estimate of this track (`None`: none was).
    since_disputed: Option<usize>,
    /// Measurements in the window of the newest control step, as filled for it (the law may refill the scratch
    /// window for its own samples).
    step_window_len: usize,
    report: EstimatorReport,
}

impl TrackCore {
    fn new(camera: CameraModel, target: Target, config: TrackerConfig) -> Self {
        let n = target.len();
        let capacity = Self::max_window(&config, n);
        Self {
            model: SpatioTemporalModel::new(camera.intrinsics),
            camera,
            window: ObservationWindow::new(n, capacity),
            scratch: Vec::with_capacity(capacity.max(n)),
            pending: Vec::with_capacity(n),
            target,
            config,
            phase: Phase::Initializing,
            state: MotionState::at_rest(Default::default(), Default::default()),
            t_ref_s: 0.0,
            noise_px: config.noise_px,
            last_t_s: None,
            since_estimate: 0,
            since_start_attempt: 0,
            pending_start: None,
            step_measurements: 0,
            estimates_since_init: 0,
            widening: 0,
            good_steps: 0,
            degenerate_windows: 0,
            bad_estimates: 0,
            since_disputed: None,
            step_window_len: 0,
            report: EstimatorReport::default(),
        }
    }

    /// Largest window the tracker may use: the configured one widened by up to 3 cycles, and 2 cycles for
    /// initialisation.
    fn max_window(config: &TrackerConfig, n: usize) -> usize {
        let configured = match config.window {
            WindowMode::NewestPerPoint => n * default_window_cycles(n),
            WindowMode::Last(m) => m,
        };
        configured.max(n) + 3 * n
    }

    /// The scratch window as a 12-dof problem at reference time `t_ref_s` (least squares, exact Jacobian).
    pub fn window_problem(&self, t_ref_s: f64) -> WindowProblem<'_> {
        let mut problem =
            WindowProblem::new(&self.model, self.target.points(), &self.scratch, t_ref_s);
        problem.scale_floor_px = self.robust_scale_floor_px();
        problem
    }

    /// The smallest robust scale of the window fits (px): the noise, and at least 1 px.
    pub fn robust_scale_floor_px(&self) -> f64 {
        ROBUST_SCALE_FLOOR_PX.max(self.noise_px)
    }

    /// A broad prior when the initial window cannot give a covariance: 1 cm, 0.1 rad, 1 m/s, 10 rad/s.
    pub fn prior_covariance(&self) -> Matrix12 {
        let sigmas = [
            1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0, 10.0, 10.0, 10.0,
        ];
        Matrix12::from_diagonal(&SMatrix::<f64, 12, 1>::from_fn(|i, _| {
            sigmas[i] * sigmas[i]
        }))
    }

    /// σ² (JᵀJ)⁻¹ of a window, when it is well posed; `inverse_condition` is that of `ne`, already computed by the
    /// caller's step.
    pub fn window_covariance(
        &self,
        ne: &NormalEquations<12>,
        inverse_condition: f64,
    ) -> Option<Matrix12> {
        if inverse_condition < self.config.min_inverse_condition {
            return None;
        }
        ne.covariance(self.noise_px)
    }

    /// Whether the newest measurement lies beyond Tukey's c at the window's robust scale (see
    /// [`super::problem::scale_from_median_px`]): a robust window fit gave it no weight.
    pub fn newest_beyond_robust_scale(&self, residuals: &ResidualFigures) -> bool {
        let scale_px = scale_from_median_px(residuals.median_px, self.robust_scale_floor_px());
        residuals.newest_px > RobustLoss::TUKEY_C * scale_px
    }

    /// Whether a window with this conditioning is degenerate.
    pub fn is_degenerate(&self, inverse_condition: f64) -> bool {
        inverse_condition < self.config.min_inverse_condition
    }

    /// Whether a window of `measurements` centroids is too small for a 12-parameter fit to be vouched for: fewer
    /// than [`MIN_FIT_REDUNDANCY`] equations beyond the 12 unknowns (the newest centroid of each of 6 points fits
    /// exactly whatever their noise, and nothing tells a wrong centroid).
    pub fn is_underdetermined(&self, measurements: usize) -> bool {
        2 * measurements < 12 + MIN_FIT_REDUNDANCY
    }

    fn effective_window(&self) -> WindowMode {
        let n = self.target.len();
        let cycles = default_window_cycles(n);
        match (self.config.window, self.widening) {
            (WindowMode::NewestPerPoint, 0) if cycles > 1 => WindowMode::Last(n * cycles),
            (mode, 0) => mode,
            (WindowMode::NewestPerPoint, w) => WindowMode::Last(n * (cycles + w)),
            (WindowMode::Last(m), w) => WindowMode::Last(m + n * w),
        }
    }

    /// Time from the oldest to the newest of the window's newest `n` measurements (s); 0 for fewer than two.
    pub fn window_span_s(&self, n: usize) -> f64 {
        let mut times = self.window.last(n).map(|o| o.t_s);
        let first = times.next();
        match (first, times.last()) {
            (Some(a), Some(b)) => (b - a).abs(),
            _ => 0.0,
        }
    }

    /// Measurements in the window.
    pub fn window_len(&self) -> usize {
        self.window.len()
    }

    /// Whether the newest `n` measurements come a frame at a time: on average at least two of them share each time
    /// (the blobs of global-shutter frames), where the measurements of ROIs or of a rolling shutter each have their
    /// own.
    pub fn recent_are_frames(&self, n: usize) -> bool {
        let (mut instants, mut previous_s) = (0, None);
        for o in self.window.last(n) {
            if Some(o.t_s) != previous_s {
                instants += 1;
                previous_s = Some(o.t_s);
            }
        }
        n >= 2 && self.window.len() >= n && 2 * instants <= n
    }

    /// Fills the scratch window with the measurements of one instant: those of the newest `n` that share the time of
    /// the one `skip` places back from the newest, which must start its instant (the first call skips 0, each next
    /// one the count returned so far). Returns how many there are (0 past the `n`).
    pub fn fill_scratch_with_instant(&mut self, n: usize, skip: usize) -> usize {
        let scratch = &mut self.scratch;
        scratch.clear();
        let mut newest_first = self.window.last(n).skip(skip);
        if let Some(first) = newest_first.next() {
            scratch.push(*first);
            scratch.extend(newest_first.take_while(|o| o.t_s == first.t_s).copied());
        }
        scratch.len()
    }

    /// Whether a window fit's residual RMS at its emitted state is beyond [`MAX_RESIDUAL_NOISE_RATIO`] times the
    /// centroid noise: the state does not explain its window.
    pub fn residual_inconsistent(&self, residuals: &ResidualFigures) -> bool {
        residuals.rms_px > MAX_RESIDUAL_NOISE_RATIO * self.noise_px
    }

    /// The pose a track starts from, with the static fit it came from, at `t_ref_s` (the newest measurement's time),
    /// the scratch window holding the first cycles (the last `init_len` measurements).
    ///
    /// The newest cycle's static pose gives the candidates: its best, the rivals that fit as well within the noise
    /// and the nearest one left out. With one candidate the start is its static pose. With several, each is fitted
    /// with its twist over the first cycles (12 dof: a target that moves during a cycle, one ROI at a time, leaves a
    /// static residual that is the motion's, not the noise's), and they are judged on those fits: against the
    /// larger of the configured noise and the 95 % upper bound the best fit's residual allows, and the spread a
    /// model's error gives their costs (which repeats at every cycle). A rival within that bound leaves the start
    /// ambiguous; one within a few times it must lose the same way at the next attempt too, a cycle later (the
    /// start is tried at every cycle, and one lucky draw among many must not decide).
    fn decide_start_pose(
        &mut self,
        t_ref_s: f64,
        init_len: usize,
    ) -> Result<(MotionState, PoseFit), StartFailure> {
        let prior = PixelNoise::Assumed(self.config.noise_px);
        let cycle = self
            .window
            .cycle(0)
            .ok_or(StartFailure::NoPose(InitError::TooFewPoints {
                required: 3,
                actual: self.window.points_seen(),
            }))?;
        let poses = solve_static_pose(&self.model, &self.target, &cycle, prior)
            .map_err(StartFailure::NoPose)?;
        let candidates: Vec<PoseFit> = poses
            .as_slice()
            .iter()
            .chain(poses.runner_up())
            .copied()
            .collect();
        if candidates.len() == 1 {
            self.pending_start = None;
            return Ok((candidates[0].state, candidates[0]));
        }
        // Judged on the first cycles; while a rival stands, on the whole window too (a twin's excess grows with the
        // measurements where the noise's bound does not).
        let mut judged = self.judge_start_fits(&candidates, t_ref_s, init_len);
        if judged.rivals > 0 && self.window.len() > init_len {
            judged = self.judge_start_fits(&candidates, t_ref_s, self.window.len());
        }
        if judged.rivals > 0 {
            self.pending_start = None;
            return Err(StartFailure::Ambiguous {
                poses: judged.rivals + 1,
            });
        }
        let (fits, best) = (&judged.fits, judged.best);
        let winner = fits[best];
        if let Some(k) = judged.near_rival {
            // Decided with little margin: the previous attempt must have decided the same pose (moved on by its
            // twist), nearer it than the rival.
            let confirmed = self.pending_start.is_some_and(|(t_s, previous)| {
                let moved = previous.predicted(t_ref_s - t_s);
                moved.pose_distance(&winner) < moved.pose_distance(&fits[k])
            });
            self.pending_start = Some((t_ref_s, winner));
            if !confirmed {
                return Err(StartFailure::Unconfirmed);
            }
        }
        self.pending_start = None;
        // The judgement's fits stop short of the last digits (`start_judgement_options`): the winner is taken to its
        // minimum on the window it was judged on (left in the scratch window).
        let winner = self
            .window_problem(t_ref_s)
            .with_loss(self.config.robust, 1.0)
            .fit_robustly(winner, INIT_MAX_ITERATIONS)
            .params;
        Ok((winner, candidates[best]))
    }

    /// The start candidates fitted with their twist over the last `len` measurements (left in the scratch window),
    /// and how they compare (see [`Self::decide_start_pose`]).
    fn judge_start_fits(
        &mut self,
        candidates: &[PoseFit],
        t_ref_s: f64,
        len: usize,
    ) -> StartJudgement {
        self.fill_scratch(WindowMode::Last(len));
        let problem = self
            .window_problem(t_ref_s)
            .with_loss(self.config.robust, 1.0);
        let fits: Vec<MotionState> = candidates
            .iter()
            .map(|c| {
                problem
                    .fit_robustly_with(c.state, &start_judgement_options())
                    .params
            })
            .collect();
        let median_px = fits
            .iter()
            .filter_map(|f| problem.median_residual_px(f))
            .fold(f64::INFINITY, f64::min);
        let limit_px = 5.0 * self.config.noise_px.max(median_px / RAYLEIGH_MEDIAN);
        let costs: Vec<f64> = fits
            .iter()
            .map(|f| problem.truncated_cost_px2(f, limit_px))
            .collect();
        let best = (0..fits.len())
            .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
            .unwrap_or(0);
        let lower = roitrack_core::stats::chi2_lower_5_percent(
            (2 * self.scratch.len()).saturating_sub(12) as f64,
        );
        let variance_px2 = if lower > 0.0 {
            (self.config.noise_px * self.config.noise_px).max(costs[best] / lower)
        } else {
            f64::INFINITY
        };
        // How far a model's error could move each fit's cost excess over the window (where it repeats at every
        // cycle), given what the best fit's residual shows of it.
        // The first-order change holds at least-squares minima (where each fit's residual is orthogonal to what
        // its own parameters absorb): taken from the robust fits, the plain ones.
        let plain = self.window_problem(t_ref_s);
        let minima: Vec<MotionState> = fits
            .iter()
            .map(|f| {
                plain
                    .fit_robustly_with(*f, &start_judgement_options())
                    .params
            })
            .collect();
        let effects: Vec<ModelEffect> = (0..fits.len())
            .map(|k| {
                if k == best {
                    ModelEffect::default()
                } else {
                    cost_difference_effect(
                        &plain,
                        &self.model,
                        &self.target,
                        &self.scratch,
                        |o| o.t_s - t_ref_s,
                        &minima[best],
                        &minima[k],
                        variance_px2,
                    )
                    .unwrap_or_default()
                }
            })
            .collect();
        // Within `factor` times the noise's bound for some model error within MODEL_SPREAD_SIGMAS of its spread.
        let within = |k: usize, factor: f64| {
            effects[k].least_excess_px2(costs[k] - costs[best], MODEL_SPREAD_SIGMAS)
                <= factor * AMBIGUITY_CHI2_12DOF * variance_px2
        };
        let excess = |k: usize| costs[k] - costs[best];
        // Fits that reached the best's own minimum are no rivals.
        let other = |k: usize| k != best && fits[k].pose_distance(&fits[best]) > SAME_START_POSE;
        let rivals = (0..fits.len())
            .filter(|&k| other(k) && within(k, 1.0))
            .count();
        let near_rival = (0..fits.len())
            .filter(|&k| other(k))
            .min_by(|&a, &b| excess(a).total_cmp(&excess(b)))
            .filter(|&k| within(k, NEAR_RIVAL_FACTOR));
        StartJudgement {
            fits,
            best,
            rivals,
            near_rival,
        }
    }

    /// Fills the scratch window with the measurements `mode` selects.
    pub fn fill_scratch(&mut self, mode: WindowMode) {
        self.scratch.clear();
        self.scratch.extend(self.window.select(mode).copied());
    }

    /// Checks `measurements` in order (times must not decrease from the newest taken, nor within them), pushing
    /// each checked one onto `checked`; stops at the first refused, with its offset.
    fn check_all(
        &self,
        measurements: &[Measurement],
        checked: &mut Vec<Observation>,
    ) -> Result<(), (usize, TrackError)> {
        let mut previous_s = self.last_t_s;
        for (offset, m) in measurements.iter().enumerate() {
            checked.push(self.check(m, previous_s).map_err(|e| (offset, e))?);
            previous_s = Some(m.t_s);
        }
        Ok(())
    }

    /// Checks a raw measurement against the previous time `previous_s` and undistorts it, without changing
    /// anything: a refused measurement leaves the estimator as it was.
    fn check(&self, m: &Measurement, previous_s: Option<f64>) -> Result<Observation, TrackError> {
        for (field, value) in [("t", m.t_s), ("u", m.u_px), ("v", m.v_px)] {
            if !value.is_finite() {
                return Err(TrackError::NotFinite {
                    t_s: m.t_s,
                    field,
                    value,
                });
            }
        }
        if let Some(previous_s) = previous_s
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
        Ok(Observation {
            t_s: m.t_s,
            point_index,
            ideal_px,
        })
    }

    /// Adds a checked observation to the window.
    fn commit(&mut self, obs: Observation) {
        self.last_t_s = Some(obs.t_s);
        self.window.push(obs);
        self.report.measurements += 1;
        self.since_start_attempt += 1;
        self.since_disputed = self.since_disputed.map(|m| m + 1);
    }

    /// Widens the window after a degenerate step; shrinks it back after a run of good ones.
    fn track_conditioning(&mut self, step: &Step) {
        if step.status == TrackStatus::Degenerate || self.is_degenerate(step.inverse_condition) {
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
}

/// An initial fit, ready to start a track.
struct Initial {
    t_ref_s: f64,
    state: MotionState,
    covariance: Option<Matrix12>,
    step: Step,
}

/// An estimator: the shared machinery around its law.
#[derive(Debug, Clone)]
pub(crate) struct Track<L> {
    pub core: TrackCore,
    pub law: L,
}

impl<L: Law> Track<L> {
    /// Checks the configuration and builds the estimator: `config`'s common options with `estimator`, the settings
    /// of `law`.
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: TrackerConfig,
        estimator: EstimatorConfig,
        law: L,
    ) -> Result<Self, ConfigError> {
        let config = TrackerConfig {
            estimator,
            ..config
        };
        config.validate()?;
        Ok(Self {
            core: TrackCore::new(camera, target, config),
            law,
        })
    }

    /// Takes one raw centroid; returns an estimate every `every` measurements once initialised.
    pub fn push(&mut self, m: &Measurement) -> Result<Option<Estimate>, TrackError> {
        let obs = match self.core.check(m, self.core.last_t_s) {
            Ok(obs) => obs,
            Err(e) => {
                self.core.report.refused += 1;
                return Err(e);
            }
        };
        self.apply(obs);
        let initialisations = self.core.report.initialisations;
        let estimate = self.estimate_if_due(Emit::Every);
        self.check_first_pose(initialisations, estimate)
    }

    /// Takes the measurements of one readout (the blobs of a frame, in time order) and returns at most one
    /// estimate, after the last of them: always with [`Emit::EachBatch`], with [`Emit::Every`] once `every`
    /// measurements have come since the previous estimate. Every measurement is checked before any is used: a refused
    /// batch leaves the estimator as it was.
    pub fn push_batch(
        &mut self,
        measurements: &[Measurement],
        emit: Emit,
    ) -> Result<Option<Estimate>, TrackError> {
        let mut pending = std::mem::take(&mut self.core.pending);
        pending.clear();
        if let Err((_, e)) = self.core.check_all(measurements, &mut pending) {
            self.core.report.refused += 1;
            self.core.pending = pending;
            return Err(e);
        }
        for obs in &pending {
            self.core.commit(*obs);
        }
        if self.core.phase == Phase::Running {
            self.law.on_batch(&mut self.core, &pending);
            self.core.since_estimate += pending.len();
        }
        self.core.pending = pending;
        let initialisations = self.core.report.initialisations;
        let estimate = self.estimate_if_due(emit);
        self.check_first_pose(initialisations, estimate)
    }

    /// Which measurement of `measurements` [`Self::push_batch`] would refuse first (its offset), and why; `None` if it
    /// would take them all. Takes nothing and counts nothing.
    pub fn first_refused(&self, measurements: &[Measurement]) -> Option<(usize, TrackError)> {
        let mut checked = Vec::with_capacity(measurements.len());
        self.core.check_all(measurements, &mut checked).err()
    }

    /// Adds a checked measurement to the window and, on a running track, to the state.
    fn apply(&mut self, obs: Observation) {
        self.core.commit(obs);
        if self.core.phase == Phase::Running {
            self.law.on_measurement(&mut self.core, &obs);
            self.core.since_estimate += 1;
        }
    }

    /// The estimate, or an error if it starts the first track (the initialisations went up from none) at a pose
    /// behind the camera or farther than the configured distance. The track is dropped then and not counted, so the
    /// next initialisation is checked again. Re-initialisations after a lost track are not checked: a run that has
    /// tracked is not stopped by one bad restart.
    fn check_first_pose(
        &mut self,
        initialisations: usize,
        estimate: Option<Estimate>,
    ) -> Result<Option<Estimate>, TrackError> {
        let Some(e) = estimate else {
            return Ok(None);
        };
        if initialisations > 0 || self.core.report.initialisations == initialisations {
            return Ok(Some(e));
        }
        let t = e.state.cam_t_obj_m;
        let distance_m = t.norm();
        let max_m = self.core.config.max_first_distance_m;
        if t.z > 0.0 && distance_m <= max_m {
            return Ok(Some(e));
        }
        self.reset();
        self.core.report.initialisations = initialisations;
        self.core.report.uncount(e.status);
        Err(TrackError::ImplausibleFirstPose {
            t_s: e.t_ref_s,
            x_m: t.x,
            y_m: t.y,
            z_m: t.z,
            distance_m,
            max_m,
        })
    }

    /// After new measurements: an initialisation when one is possible, or a control step when `emit` says one is
    /// due.
    fn estimate_if_due(&mut self, emit: Emit) -> Option<Estimate> {
        match (self.core.phase, emit) {
            (_, Emit::Hold) => None,
            (Phase::Initializing, _) => self.try_initialize(),
            (Phase::Running, Emit::EachBatch) => {
                (self.core.since_estimate > 0).then(|| self.control_step())
            }
            (Phase::Running, Emit::Every) => {
                (self.core.since_estimate >= self.core.config.every).then(|| self.control_step())
            }
        }
    }

    /// Drops the current track: the next measurements initialise a new one.
    pub fn reset(&mut self) {
        self.core.phase = Phase::Initializing;
        self.core.window.clear();
        self.core.since_estimate = 0;
        self.core.pending_start = None;
    }

    /// Starts tracking from a known state at time `t_s` with its covariance (error-state order v, w, dV, dW). The
    /// new track takes measurements from `t_s` on, even if the old one had later ones: a frame tracker that finds its
    /// running track wrong on a frame starts a new one from the same frame's blobs.
    pub fn start_from(&mut self, t_s: f64, state: MotionState, covariance: Option<Matrix12>) {
        self.core.window.clear();
        self.core.last_t_s = Some(t_s);
        self.begin_track(t_s, state, covariance);
    }

    /// Tells the law the target's acceleration from `t_s` on ([`super::Estimator::set_known_acceleration`]).
    pub fn set_known_acceleration(
        &mut self,
        t_s: f64,
        acceleration: roitrack_core::Acceleration,
    ) -> Result<(), super::KnownAccelerationError> {
        let estimator = self.core.config.estimator.name();
        // No prediction starts before the running track's time, nor (a track yet to start) before the newest
        // measurement: what is in force before either is forgotten.
        let now_s = if self.core.phase == Phase::Running {
            Some(self.core.t_ref_s)
        } else {
            self.core.last_t_s
        };
        let known = self
            .law
            .known_acceleration()
            .ok_or(super::KnownAccelerationError::Unsupported { estimator })?;
        if let Some(now_s) = now_s {
            known.forget_before(now_s);
        }
        known.set(t_s, acceleration)
    }

    /// Forgets every known acceleration ([`super::Estimator::clear_known_acceleration`]).
    pub fn clear_known_acceleration(&mut self) {
        if let Some(known) = self.law.known_acceleration() {
            known.clear();
        }
    }

    /// The current state (at the time of the newest measurement processed), once initialised.
    pub fn state(&self) -> Option<(f64, MotionState)> {
        (self.core.phase == Phase::Running).then_some((self.core.t_ref_s, self.core.state))
    }

    /// The current state predicted to `t_s`, once initialised: by the estimator's own motion model with its
    /// covariance (pose and twist, error-state order) when it has one (the Kalman filter's accelerations and process
    /// noise included), else carried by the twist with no covariance.
    pub fn predicted(&self, t_s: f64) -> Option<(MotionState, Option<Matrix12>)> {
        if self.core.phase != Phase::Running {
            return None;
        }
        Some(match self.law.predicted(&self.core, t_s) {
            Some((state, covariance)) => (state, Some(covariance)),
            None => (self.core.state.predicted(t_s - self.core.t_ref_s), None),
        })
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.core.config
    }

    pub fn target(&self) -> &Target {
        &self.core.target
    }

    pub fn report(&self) -> EstimatorReport {
        let mut report = self.core.report;
        self.law.add_to_report(&mut report);
        report
    }

    /// Starts a new track at `state` (time `t_s`): every per-track counter back to zero. The measurement window is
    /// kept.
    fn begin_track(&mut self, t_s: f64, state: MotionState, covariance: Option<Matrix12>) {
        let core = &mut self.core;
        core.state = state;
        core.t_ref_s = t_s;
        core.phase = Phase::Running;
        core.since_estimate = 0;
        core.estimates_since_init = 0;
        core.widening = 0;
        core.good_steps = 0;
        core.degenerate_windows = 0;
        core.bad_estimates = 0;
        core.since_disputed = None;
        core.pending_start = None;
        core.report.initialisations += 1;
        self.law.begin_track(&self.core, covariance);
    }

    /// Static pose from the newest centroid of each point, then a 12-dof fit on the last two cycles, so that a target
    /// already moving at the start is initialised with its velocity.
    fn try_initialize(&mut self) -> Option<Estimate> {
        let initial = self.initial_fit()?;
        self.begin_track(initial.t_ref_s, initial.state, initial.covariance);
        Some(self.finish_estimate(initial.step))
    }

    fn initial_fit(&mut self) -> Option<Initial> {
        let core = &mut self.core;
        let n = core.target.len();
        let init_len = 2 * n;
        if core.window.points_seen() < n || core.window.len() < init_len {
            return None;
        }
        if core.report.start_failure.is_some() && core.since_start_attempt < n {
            return None;
        }
        core.since_start_attempt = 0;
        let t_ref_s = core.window.last(1).next()?.t_s;
        let (pose, static_fit) = match core.decide_start_pose(t_ref_s, init_len) {
            Ok(start) => {
                // A start decided by the static pose alone has not filled the scratch window.
                core.fill_scratch(WindowMode::Last(init_len));
                start
            }
            Err(failure) => {
                core.report.start_failure = Some(failure);
                return None;
            }
        };
        let problem = core
            .window_problem(t_ref_s)
            .with_loss(core.config.robust, 1.0);
        let fit = problem.fit_robustly(pose, INIT_MAX_ITERATIONS);
        let (state, ne) = (fit.params, fit.normal_equations);
        let inverse_condition = ne.fast_inverse_condition();
        let well_posed = !core.is_degenerate(inverse_condition);
        // Residuals far above the noise mean a wrong local minimum or bad data: wait for more measurements. The
        // median residual, which outliers do not inflate, must be at the noise level: the 12-dof model is exact over
        // two cycles.
        let median_px = problem.median_residual_px(&state).unwrap_or(0.0);
        // The static pose's own residual is the model's error plus the noise (a camera or target file a little off
        // leaves pixels of it): a fit of the first cycles that explains them about as well is no wrong minimum.
        let static_median_px = 3.0 * RAYLEIGH_MEDIAN * static_fit.residual_rms_px;
        let max_median_px = if self.law.adapts_noise() {
            ADAPTIVE_INIT_MAX_MEDIAN_PX.max(static_median_px)
        } else {
            (3.0 * core.config.noise_px).max(0.3)
        };
        // The noise from the median residual (which outliers do not move), corrected for the 12 fitted parameters;
        // never below a hundredth of a pixel, the floor of any centroid.
        let n = 2.0 * ne.count() as f64;
        let dof = (n - 12.0).max(1.0);
        let noise_estimate_px = (median_px / RAYLEIGH_MEDIAN * (n / dof).sqrt()).max(MIN_NOISE_PX);
        // The residual's cost truncated, as the start's decision truncates it, at five times the larger of that
        // estimate and the configured noise: an outlier among the first cycles must not make the noise (below).
        let truncated_cost_px2 =
            problem.truncated_cost_px2(&state, 5.0 * noise_estimate_px.max(core.config.noise_px));
        if ne.residual_rms_px() > core.config.lost_residual_px || median_px > max_median_px {
            core.report.start_failure = Some(StartFailure::Residual { median_px });
            return None;
        }
        core.report.start_failure = None;
        if self.law.adapts_noise() {
            core.noise_px = noise_estimate_px;
            // With few degrees of freedom (two cycles of 4 points leave 4) the residual often shows far less than
            // the noise, and a filter started from it trusts its first state and its measurements too much (a
            // 4-point body: first residual 0.02 px at 0.1 px of noise, its depth 1.9 mm off at 7 of its stated
            // sigmas, the track lost 23 ms later; 1.15 mm RMSE over the run, 0.17 mm with the bound). A stream of
            // ROIs learns the noise with a memory of thousands of degrees of freedom, over which a low start
            // lingers: it starts from the 95 % upper bound the residual allows (1.2 times the estimate for two
            // cycles of 16 points, 2.4 for 4). Frames are not: the filter samples each frame's noise from its own
            // blobs, and a start 3-4 times the noise left four dots at 30 Hz behind the random scene's turns.
            let lower = roitrack_core::stats::chi2_lower_5_percent(dof);
            if lower > 0.0 && !core.recent_are_frames(init_len) {
                core.noise_px = core.noise_px.max((truncated_cost_px2 / lower).sqrt());
            }
        }
        let state = if well_posed {
            state
        } else {
            MotionState::at_rest(static_fit.state.cam_r_obj, static_fit.state.cam_t_obj_m)
        };
        let covariance = core.window_covariance(&ne, inverse_condition);
        Some(Initial {
            t_ref_s,
            state,
            covariance,
            step: Step {
                inverse_condition,
                measurements_used: ne.count(),
                iterations: fit.report.iterations,
                status: if well_posed {
                    TrackStatus::Converging
                } else {
                    TrackStatus::Degenerate
                },
                covariance,
                acceleration: None,
            },
        })
    }

    /// One control step at the newest measurement's time.
    fn control_step(&mut self) -> Estimate {
        let core = &mut self.core;
        core.step_measurements = core.since_estimate;
        core.since_estimate = 0;
        let t_new_s = core.last_t_s.unwrap_or(core.t_ref_s);
        let mode = core.effective_window();
        core.fill_scratch(mode);
        core.step_window_len = core.scratch.len();
        let step = self.law.control_step(core, t_new_s);
        self.core.track_conditioning(&step);
        self.finish_estimate(step)
    }

    /// Residual at the emitted state, status bookkeeping (converging, disputed, lost), and the estimate itself.
    fn finish_estimate(&mut self, step: Step) -> Estimate {
        // Residual over the step's window at the emitted state. The track is judged on the median residual: a few
        // outliers in the window must not make it look lost.
        let residuals = self.law.own_residuals().unwrap_or_else(|| {
            let mut problem = self.core.window_problem(self.core.t_ref_s);
            problem.simultaneous = self.law.simultaneous_residuals();
            problem.residual_figures(&self.core.state)
        });
        let core = &mut self.core;
        // A state disputed once is vouched for again only when a whole window of measurements newer than the dispute
        // agrees with it: refitted on a window partly the same, a state that left its measurements can settle in a
        // wrong minimum with a residual a little above the noise (the exact-Jacobian loop on the spin scene at 0.3 px:
        // 24 mm off between two disputed estimates, its residual 2.6 times the noise).
        let bad = !residuals.median_px.is_finite()
            || residuals.median_px > core.config.lost_residual_px
            || !core.state.is_finite();
        // A state that does not explain its measurements (their median residual beyond the lost residual) is not
        // vouched for even once, before the run of such estimates that declares the track lost.
        let disputed_now = bad || self.law.is_disputed(core, &residuals);
        let disputed = disputed_now
            || core
                .since_disputed
                .is_some_and(|m| m < core.step_window_len);
        if disputed_now {
            core.since_disputed = Some(0);
        }
        let mut status = step.status;
        core.bad_estimates = if bad { core.bad_estimates + 1 } else { 0 };
        if core.bad_estimates >= LOST_AFTER_BAD_ESTIMATES {
            status = TrackStatus::Lost;
            core.phase = Phase::Initializing;
            core.window.clear();
        } else if disputed && matches!(status, TrackStatus::Tracking | TrackStatus::Converging) {
            status = TrackStatus::Disputed;
        } else if status == TrackStatus::Tracking
            && core.estimates_since_init < CONVERGING_ESTIMATES
        {
            status = TrackStatus::Converging;
        }
        core.estimates_since_init += 1;
        core.report.count(status);
        let noise_px = core.noise_px;
        self.law.after_estimate();
        let core = &self.core;
        Estimate {
            t_ref_s: core.t_ref_s,
            state: core.state,
            residual_rms_px: residuals.rms_px,
            inverse_condition: step.inverse_condition,
            measurements_used: step.measurements_used,
            iterations: step.iterations,
            status,
            covariance: step.covariance,
            noise_px,
            acceleration: step.acceleration,
        }
    }
}
