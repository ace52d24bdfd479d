//! The 12-dof window fit as a value: [`WindowProblem`] holds the model, the target, a window of timed observations,
//! the reference time and the robust loss, and is the [`LeastSquaresProblem`] the tracker's initialisation, the VVS
//! loop and the batch baseline hand to the [`solver`](roitrack_core::solver). It is also where the time offset of an
//! observation from the reference time is taken, for every window computation.

use nalgebra::{SVector, Vector2};

use roitrack_core::solver::{
    self, LeastSquaresProblem, NormalEquations, ResidualSink, Solution, SolverOptions,
};
use roitrack_core::{JacobianKind, MotionState, SpatioTemporalModel, TargetPoint};

/// One undistorted centroid: the time it was taken (s), the index of its model point in the target, its ideal
/// (undistorted) pixel.
///
/// ```
/// use nalgebra::Vector2;
/// use roitrack_estimators::Observation;
/// let o = Observation { t_s: 0.25, point_index: 3, ideal_px: Vector2::new(512.0, 500.5) };
/// assert_eq!(o.point_index, 3);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Mid-exposure time of the blob (s), as measured.
    pub t_s: f64,
    /// Index of the model point into the target's points ([`roitrack_core::Target::points`]), not its id.
    pub point_index: usize,
    /// The centroid with the lens distortion removed (ideal px).
    pub ideal_px: Vector2<f64>,
}

/// A robust loss for the window fits (M-estimator by iteratively reweighted least squares). Residuals are measured in
/// units of an automatic scale: the noise level or, when larger, the median residual of the window (a robust
/// estimate of the spread that outliers do not inflate).
///
/// ```
/// use roitrack_estimators::RobustLoss;
/// assert_eq!(RobustLoss::None.weight(100.0), 1.0);
/// assert_eq!(RobustLoss::Huber.weight(2.69), 0.5);
/// assert_eq!(RobustLoss::Tukey.weight(5.0), 0.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RobustLoss {
    /// Plain least squares.
    None,
    /// Huber, k = 1.345 scales (95 % efficiency on Gaussian noise): outliers weigh as `k / r`.
    Huber,
    /// Tukey's biweight, c = 4.685 scales (95 % efficiency): outliers beyond c weigh nothing.
    #[default]
    Tukey,
}

impl RobustLoss {
    /// Huber's threshold (scales): residuals beyond it weigh `k / r`. 1.345 gives 95 % efficiency on Gaussian noise.
    pub const HUBER_K: f64 = 1.345;
    /// Tukey's threshold (scales): residuals beyond it weigh nothing. 4.685 gives 95 % efficiency on Gaussian noise.
    pub const TUKEY_C: f64 = 4.685;

    /// IRLS weight of a residual of `r` scales.
    #[inline]
    pub fn weight(&self, r: f64) -> f64 {
        match self {
            Self::None => 1.0,
            Self::Huber => {
                if r <= Self::HUBER_K {
                    1.0
                } else {
                    Self::HUBER_K / r
                }
            }
            Self::Tukey => {
                if r >= Self::TUKEY_C {
                    0.0
                } else {
                    let q = 1.0 - (r / Self::TUKEY_C).powi(2);
                    q * q
                }
            }
        }
    }
}

/// Largest window whose median residual sets the robust scale (a stack buffer: no allocation).
const MAX_SCALE_SAMPLES: usize = 128;

/// The median of the norm of a 2-D Gaussian residual, in standard deviations per axis.
const MEDIAN_NORM_PER_SIGMA: f64 = 1.1774;

/// The robust scale (px per axis) for a median residual norm: `median / 1.1774` (the median norm of a 2-D Gaussian
/// residual of unit standard deviation per axis), never below `floor_px`.
pub(crate) fn scale_from_median_px(median_px: f64, floor_px: f64) -> f64 {
    (median_px / MEDIAN_NORM_PER_SIGMA).max(floor_px)
}

/// Residual figures of a window at a state (px).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ResidualFigures {
    /// RMS per coordinate.
    pub rms_px: f64,
    /// Median residual norm (of the first 128 observations).
    pub median_px: f64,
    /// Residual norm of the newest observation.
    pub newest_px: f64,
}

/// A [`ResidualTally`]'s state, to rewind it to.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TallyMark {
    count: usize,
    sum_squares: f64,
    newest_px: f64,
}

/// Residual norms gathered one at a time (a filter's innovations), summed into [`ResidualFigures`]: no allocation.
#[derive(Debug, Clone)]
pub(crate) struct ResidualTally {
    /// The first [`Self::MAX`] norms, for the median.
    norms: [f64; Self::MAX],
    count: usize,
    sum_squares: f64,
    newest_px: f64,
}

impl Default for ResidualTally {
    fn default() -> Self {
        Self {
            norms: [0.0; Self::MAX],
            count: 0,
            sum_squares: 0.0,
            newest_px: 0.0,
        }
    }
}

impl ResidualTally {
    const MAX: usize = 128;

    /// Adds the norm (px) of one residual, the newest.
    pub fn add(&mut self, norm_px: f64) {
        if self.count < Self::MAX {
            self.norms[self.count] = norm_px;
        }
        self.count += 1;
        self.sum_squares += norm_px * norm_px;
        self.newest_px = norm_px;
    }

    pub fn clear(&mut self) {
        self.count = 0;
        self.sum_squares = 0.0;
        self.newest_px = 0.0;
    }

    /// Where the tally stands, to [`Self::rewind`] to.
    pub fn mark(&self) -> TallyMark {
        TallyMark {
            count: self.count,
            sum_squares: self.sum_squares,
            newest_px: self.newest_px,
        }
    }

    /// Forgets the norms added since `mark`.
    pub fn rewind(&mut self, mark: TallyMark) {
        self.count = mark.count;
        self.sum_squares = mark.sum_squares;
        self.newest_px = mark.newest_px;
    }

    /// RMS per coordinate, median and newest norm; `None` before the first residual.
    pub fn figures(&self) -> Option<ResidualFigures> {
        if self.count == 0 {
            return None;
        }
        let n = self.count.min(Self::MAX);
        let mut norms = self.norms;
        let (_, median, _) = norms[..n].select_nth_unstable_by(n / 2, f64::total_cmp);
        Some(ResidualFigures {
            rms_px: (self.sum_squares / (2 * self.count) as f64).sqrt(),
            median_px: *median,
            newest_px: self.newest_px,
        })
    }
}

/// The 12-dof fit of a [`MotionState`] at `t_ref_s` to a window of observations, each seen at its own time: the
/// residual of observation `o` is the projection of its model point `o.t_s - t_ref_s` after the reference time minus
/// its ideal pixel, weighted by `loss` at `|residual| / scale_px`.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_estimators::{Observation, WindowProblem};
/// use roitrack_core::solver::{SolverOptions, solve};
/// use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
///
/// let model = SpatioTemporalModel::new(CameraModel::canonical().intrinsics);
/// let target = Target::grid4x4();
/// // The truth: moving at 0.2 m/s; 32 noiseless observations 250 µs apart, the newest at t = 0.
/// let mut truth = MotionState::at_rest(Default::default(), Vector3::new(0.0, 0.0, 0.6));
/// truth.velocity_mps = Vector3::new(0.2, 0.0, 0.0);
/// let window: Vec<Observation> = (0..32)
///     .map(|k| {
///         let t_s = (k as f64 - 31.0) * 250e-6;
///         let point_index = k % 16;
///         let p = &target.points()[point_index].point_in_obj_m;
///         Observation { t_s, point_index, ideal_px: model.project(&truth, p, t_s).unwrap() }
///     })
///     .collect();
/// let mut problem = WindowProblem::new(&model, target.points(), &window, 0.0);
/// let start = MotionState::at_rest(Default::default(), Vector3::new(0.001, 0.0, 0.61));
/// let fit = solve(&mut problem, start, &SolverOptions::levenberg_marquardt(50));
/// assert!(fit.report.converged);
/// assert!((fit.params.velocity_mps - truth.velocity_mps).norm() < 1e-6);
/// ```
#[derive(Debug, Clone, Copy)]
pub struct WindowProblem<'a> {
    /// The projection model (the camera's intrinsics) that predicts each observation.
    pub model: &'a SpatioTemporalModel,
    /// The target's model points, indexed by [`Observation::point_index`].
    pub points: &'a [TargetPoint],
    /// The observations fitted, at their own times.
    pub window: &'a [Observation],
    /// The reference time of the state (s).
    pub t_ref_s: f64,
    /// Which interaction matrix the linearisation uses (the paper's loop may use its own).
    pub jacobian: JacobianKind,
    /// The M-estimator that weighs the residuals (in units of `scale_px`).
    pub loss: RobustLoss,
    /// Residual scale of the loss (px per axis).
    pub scale_px: f64,
    /// Every observation taken as if at the reference time (the static baseline's view of the window).
    pub simultaneous: bool,
    /// With [`Self::reweight`] (servo iterations): the loss's scale is set from the window's median residual, never
    /// below this (px).
    pub scale_floor_px: f64,
}

impl<'a> WindowProblem<'a> {
    /// Plain least squares with the exact Jacobian, observations at their own times.
    pub fn new(
        model: &'a SpatioTemporalModel,
        points: &'a [TargetPoint],
        window: &'a [Observation],
        t_ref_s: f64,
    ) -> Self {
        Self {
            model,
            points,
            window,
            t_ref_s,
            jacobian: JacobianKind::Exact,
            loss: RobustLoss::None,
            scale_px: 1.0,
            simultaneous: false,
            scale_floor_px: 1.0,
        }
    }

    /// The same problem with another interaction matrix.
    pub fn with_jacobian(self, jacobian: JacobianKind) -> Self {
        Self { jacobian, ..self }
    }

    /// The same problem with a robust loss at a fixed residual scale (px).
    pub fn with_loss(self, loss: RobustLoss, scale_px: f64) -> Self {
        Self {
            loss,
            scale_px,
            ..self
        }
    }

    /// The time of observation `o` relative to the reference time (s): 0 for a simultaneous window.
    #[inline]
    pub fn offset_s(&self, o: &Observation) -> f64 {
        if self.simultaneous {
            0.0
        } else {
            o.t_s - self.t_ref_s
        }
    }

    /// Where the window's observation `o` projects at `state` (ideal pixel), or `None` behind the camera.
    #[inline]
    fn project(&self, state: &MotionState, o: &Observation) -> Option<Vector2<f64>> {
        self.model.project(
            state,
            &self.points[o.point_index].point_in_obj_m,
            self.offset_s(o),
        )
    }

    /// The normal equations at `state`.
    pub fn normal_equations(&self, state: &MotionState) -> NormalEquations<12> {
        solver::normal_equations(self, state)
    }

    /// The median residual norm (px) of the window at `state` (its first 128 observations); `None` when no point
    /// projects.
    pub fn median_residual_px(&self, state: &MotionState) -> Option<f64> {
        let mut norms = [0.0f64; MAX_SCALE_SAMPLES];
        let mut n = 0;
        for o in self.window.iter().take(MAX_SCALE_SAMPLES) {
            if let Some(px) = self.project(state, o) {
                norms[n] = (px - o.ideal_px).norm();
                n += 1;
            }
        }
        if n == 0 {
            return None;
        }
        let (_, median, _) = norms[..n].select_nth_unstable_by(n / 2, f64::total_cmp);
        Some(*median)
    }

    /// `Σ min(|e|², limit²)` over the window at `state` (px²), a point that does not project counting the limit: a
    /// cost that rival states can be compared on, whatever outliers the window holds.
    pub(crate) fn truncated_cost_px2(&self, state: &MotionState, limit_px: f64) -> f64 {
        let limit2 = limit_px * limit_px;
        self.window
            .iter()
            .map(|o| {
                self.project(state, o)
                    .map_or(limit2, |px| (px - o.ideal_px).norm_squared().min(limit2))
            })
            .sum()
    }

    /// The robust scale (px per axis) of the window's residuals at `state`: the median residual norm over 1.1774 (the
    /// median norm of a 2-D Gaussian residual of unit standard deviation per axis), never below `floor_px`.
    pub fn robust_scale_px(&self, state: &MotionState, floor_px: f64) -> f64 {
        self.median_residual_px(state)
            .map_or(floor_px, |median| scale_from_median_px(median, floor_px))
    }

    /// RMS, median and newest residual of the window at `state`; all infinite if a point does not project.
    pub(crate) fn residual_figures(&self, state: &MotionState) -> ResidualFigures {
        const MAX: usize = 128;
        let mut norms = [0.0f64; MAX];
        let (mut sum, mut count) = (0.0, 0usize);
        let (mut newest_t_s, mut newest_px) = (f64::NEG_INFINITY, 0.0);
        for o in self.window {
            match self.project(state, o) {
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
                None => {
                    return ResidualFigures {
                        rms_px: f64::INFINITY,
                        median_px: f64::INFINITY,
                        newest_px: f64::INFINITY,
                    };
                }
            }
            count += 1;
        }
        if count == 0 {
            return ResidualFigures {
                rms_px: 0.0,
                median_px: 0.0,
                newest_px: 0.0,
            };
        }
        let n = count.min(MAX);
        let (_, median, _) = norms[..n].select_nth_unstable_by(n / 2, f64::total_cmp);
        ResidualFigures {
            rms_px: (sum / (2 * count) as f64).sqrt(),
            median_px: *median,
            newest_px,
        }
    }

    /// Levenberg-Marquardt to convergence (or `max_iterations` a round) with the problem's loss: least squares first,
    /// then, with a robust loss, two robust rounds, each at the scale of the previous fit's residuals (never below
    /// [`Self::scale_floor_px`]). From a rough start (a static pose of a moving target, a prediction across a fast
    /// rotation) the residuals are large for every point and a robust loss would discard the good ones: the
    /// least-squares fit comes first. The second robust round, with the scale of the cleaner first, rejects what the
    /// first (started from a fit pulled by the outliers) kept. The report's iterations and steps add up over the
    /// rounds; its initial cost is that of the first round, its final cost and stop those of the last.
    pub fn fit_robustly(
        &self,
        initial: MotionState,
        max_iterations: usize,
    ) -> Solution<MotionState, 12> {
        self.fit_robustly_with(initial, &SolverOptions::levenberg_marquardt(max_iterations))
    }

    /// [`Self::fit_robustly`] with the solver's options given.
    pub fn fit_robustly_with(
        &self,
        initial: MotionState,
        options: &SolverOptions,
    ) -> Solution<MotionState, 12> {
        let options = *options;
        let mut plain = self.with_loss(RobustLoss::None, 1.0);
        let mut fit = solver::solve(&mut plain, initial, &options);
        if self.loss == RobustLoss::None {
            return fit;
        }
        for _ in 0..2 {
            let scale_px = self.robust_scale_px(&fit.params, self.scale_floor_px);
            let mut robust = self.with_loss(self.loss, scale_px);
            let next = solver::solve(&mut robust, fit.params, &options);
            let report = fit.report;
            fit = next;
            fit.report.iterations += report.iterations;
            fit.report.steps_applied += report.steps_applied;
            fit.report.initial_cost_px2 = report.initial_cost_px2;
        }
        fit
    }
}

impl LeastSquaresProblem<12> for WindowProblem<'_> {
    type Params = MotionState;

    #[inline]
    fn linearize<S: ResidualSink<12>>(&self, state: &MotionState, sink: &mut S) {
        for o in self.window {
            let p = &self.points[o.point_index].point_in_obj_m;
            match self
                .model
                .project_with_jacobian(self.jacobian, state, p, self.offset_s(o))
            {
                Some(pp) => {
                    let e = pp.pixel - o.ideal_px;
                    let w = self.loss.weight(e.norm() / self.scale_px);
                    sink.add(&pp.jacobian, &e, w);
                }
                None => sink.add_unevaluable(),
            }
        }
    }

    #[inline]
    fn apply_step(&self, state: &MotionState, step: &SVector<f64, 12>) -> MotionState {
        state.corrected(step)
    }

    fn is_valid(&self, state: &MotionState) -> bool {
        state.is_finite()
    }

    /// Servo iterations re-weight at the window's median residual scale (never below `scale_floor_px`); without a
    /// robust loss there is nothing to weigh.
    fn reweight(&mut self, state: &MotionState) {
        if self.loss != RobustLoss::None {
            self.scale_px = self.robust_scale_px(state, self.scale_floor_px);
        }
    }
}
