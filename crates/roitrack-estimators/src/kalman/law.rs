//! The Kalman filter's part of a track ([`KalmanLaw`]): what it counts, gates and disputes, and what it learns
//! online (the process noise, the points' shares of the noise).

use super::*;

/// Consecutive measurements rejected by the gate after which the covariance is widened.
pub(super) const GATED_IN_A_ROW_FOR_RESET: usize = 6;

/// Fractions of the broad prior covariance added at successive covariance resets (variance scales: 1/100 is a tenth
/// of its standard deviations).
pub(super) const RESET_SCALES: [f64; 3] = [0.01, 0.1, 1.0];

/// Accepted measurements in a row after which the next reset starts small again.
pub(super) const ACCEPTED_IN_A_ROW_FOR_CALM: usize = 64;

/// How fast the process-noise scales follow the persistence of the innovations: their logarithms move by this much
/// per measurement and per unit of persistence (a standard normal variable when the filter is right). Chosen on the
/// orthoglide, static, spin and random scenes at 0.03-1 px and 4-10 kHz: 0.01 is too slow to average a still target
/// down within a second, 0.15 starts to follow the noise (measured with the sum of log position RMSE over nine cases:
/// best between 0.04 and 0.08).
pub(super) const PROCESS_ADAPTATION_RATE: f64 = 0.05;

/// The trend of the corrections is averaged over at least this many cycles of the target's points (longer when the
/// filter's own time constant is: `ErrorStateKalman::trend_rates`).
pub(super) const TREND_CYCLES: f64 = 2.0;

/// The trend is also averaged over at least this many updates, whatever the target: the span at which
/// [`PROCESS_ADAPTATION_RATE`] was chosen (two cycles of the 16-point built-in target). The trend holds a lag's
/// consistent part and the noise's part, which shrinks as one over the root of the span, whatever the number of
/// points; over a shorter span the noise's part hides the lag from the persistence, so the process noise settles
/// lower and the velocity lags more. Two cycles of a 4- or 5-point target (8-10 updates) lagged a fifth of a sample
/// more than the 16-point grid on the same motion (docs/results.md).
pub(super) const TREND_MIN_UPDATES: f64 = 32.0;

/// Bounds of the process-noise scale, relative to the tuning's densities.
pub(super) const PROCESS_SCALE_RANGE: (f64, f64) = (1e-4, 1e4);

/// The Kalman filter's part of a track: the filter's covariance, its gate counters and what it learns online.
#[derive(Debug, Clone)]
pub(super) struct KalmanLaw {
    pub(super) filter: Filter,
    /// Measurements rejected by the gate in a row, and covariance resets since the last estimate.
    pub(super) gated_in_a_row: usize,
    pub(super) covariance_resets: usize,
    /// How far the covariance is widened at the next reset (escalates while resets follow each other) and the
    /// measurements accepted in a row since the last one.
    pub(super) reset_level: usize,
    pub(super) accepted_in_a_row: usize,
    /// Innovations since the last estimate: the filter's residual figures.
    pub(super) innovations: ResidualTally,
    /// Measurements rejected by the gate since the last estimate, and since the start.
    pub(super) gated_since_estimate: usize,
    pub(super) gated_total: usize,
    pub(super) resets_total: usize,
    /// The squared Mahalanobis distance of the newest measurement's innovation.
    pub(super) newest_nis: f64,
    /// Whether a measurement taken alone since the last estimate moved the prediction by more than a lost residual
    /// (see [`KalmanLaw::on_measurement`]).
    pub(super) jumped_since_estimate: bool,
    /// The learnt centroid noise (when `tuning.adapt_noise`).
    pub(super) noise: NoiseEstimate,
    /// On frames, the white part of the learnt noise, from the change of the blobs' residuals from one frame to the
    /// next ([`FrameResiduals`]); see [`CentroidNoise`].
    pub(super) white_noise: NoiseEstimate,
    /// The residuals of the newest frame sampled, which the next frame's are compared with.
    pub(super) frame_residuals: FrameResiduals,
    /// Whether the measurements come a frame at a time (the blobs of global-shutter frames, several at each time),
    /// from the initial window and then from each control step: each frame samples the noise from its own blobs
    /// ([`NoiseSample`]), and the process noise is not adapted.
    pub(super) frame_steps: bool,
    /// Per point: the time of its newest measurement if the gate rejected it.
    pub(super) gated_at: Vec<Option<f64>>,
    /// Per point: how many of its newest measurements in a row the gate rejected, and when the newest of them came
    /// (as a count of the measurements taken).
    pub(super) gated_runs: Vec<(u32, u64)>,
    /// Measurements taken by this track (readouts taken twice count once per take).
    pub(super) taken: u64,
    /// Whether the measurements being taken are a readout of one instant (a global-shutter frame's blobs), whose
    /// order is the points' and says nothing of time: see [`KalmanLaw::on_batch`].
    pub(super) in_one_instant: bool,
    /// Natural logarithms of the factors applied to the linear and the angular acceleration density (when
    /// `tuning.adapt_motion`).
    pub(super) process_log_scale: [f64; 2],
    /// The scales of the reported twist covariance (when `tuning.calibrate_twist_covariance`).
    pub(super) calibration: TwistCalibration,
    /// Per point: its share of the learnt noise (when `tuning.adapt_noise`).
    pub(super) point_noise: PointNoise,
    /// The blobs of the readout being taken, but those that do not project (kept to reuse its allocation).
    pub(super) readout: Vec<ReadoutMeasurement>,
    /// Per blob of the readout being taken, its squared Mahalanobis distance from the prediction before it, when
    /// judged so (see [`KalmanLaw::take_readout`]; kept to reuse its allocation).
    pub(super) judged_nis: Vec<Option<f64>>,
    /// Whether the frame being taken is weighed by the white part of the noise alone (see
    /// [`KalmanLaw::take_readout`]).
    pub(super) bias_apart: bool,
    /// The target's acceleration known from outside (a control input), which every prediction adds to the
    /// filter's own; kept across tracks (it is the target's, not the track's).
    pub(super) known: KnownAcceleration,
}

impl Law for KalmanLaw {
    fn predicted(&self, core: &TrackCore, t_s: f64) -> Option<(MotionState, Matrix12)> {
        // A copy of the filter predicted as `predict_to` would (the known accelerations included).
        let (mut filter, mut state) = (self.filter, core.state);
        filter.predict_known(
            &mut state,
            core.t_ref_s,
            t_s - core.t_ref_s,
            self.process_log_scale.map(f64::exp),
            &self.known,
        );
        Some((state, filter.pose_twist_covariance()))
    }

    fn begin_track(&mut self, core: &TrackCore, covariance: Option<Matrix12>) {
        *self = Self {
            filter: Filter::new(
                covariance.unwrap_or_else(|| core.prior_covariance()),
                *self.filter.tuning(),
                1.0 / (TREND_CYCLES * core.target.len() as f64).max(TREND_MIN_UPDATES),
            ),
            gated_total: self.gated_total,
            resets_total: self.resets_total,
            // The initial fit's noise (set in `core.noise_px`) counts as one window's worth; the process scale
            // carries over from the previous track.
            noise: NoiseEstimate::new(core.noise_px, 2.0 * core.target.len() as f64),
            // The white part carries over (the same camera and footage); the frame the next is compared with does
            // not (a new track's pose may be another fit of the frames).
            white_noise: self.white_noise,
            frame_residuals: {
                let mut frame_residuals = std::mem::take(&mut self.frame_residuals);
                frame_residuals.clear();
                frame_residuals
            },
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
            gated_runs: {
                let mut gated_runs = std::mem::take(&mut self.gated_runs);
                gated_runs.clear();
                gated_runs.resize(core.target.len(), (0, 0));
                gated_runs
            },
            readout: std::mem::take(&mut self.readout),
            judged_nis: std::mem::take(&mut self.judged_nis),
            // The points' shares of the noise carry over too (for the same target).
            point_noise: {
                let mut point_noise = std::mem::take(&mut self.point_noise);
                point_noise.restart(core.target.len());
                point_noise
            },
            known: std::mem::take(&mut self.known),
            ..Self::new(*self.filter.tuning())
        };
        // A track initialised from a window fit holds the twist constant over the window, so its twist is the
        // window's mean one, not the one at its end: as uncertain again as the motion's random walk makes it over the
        // window. Without this the fit's covariance, which knows only the centroids' noise, was too narrow on fast
        // motion (random motion at 2.5 m/s and 7 rad/s: the first measurements after the fit gated, its second
        // estimate disputed) and at a distance (a still target 1.6 m away: a second estimate 6.1 mm off in depth,
        // vouched for). A track started from a known state (`Tracker::start_from`) has an empty window: nothing to
        // add.
        if covariance.is_some() {
            let span_s = core.window_span_s(2 * core.target.len());
            self.filter
                .add_process_noise(span_s, self.process_log_scale.map(f64::exp));
        }
    }

    fn adapts_noise(&self) -> bool {
        self.filter.tuning().adapt_noise
    }

    fn on_measurement(&mut self, core: &mut TrackCore, obs: &Observation) {
        self.known.forget_before(core.t_ref_s);
        let dt = self.predict_to(core, obs.t_s);
        let outcome = self.take(core, obs, dt, true, None);
        // A measurement accepted this far from its prediction was let through by a covariance grown so wide (a
        // target back after half a second out of view: 654 px off, inside a 735 px sigma) that the prediction no
        // longer told where the target was. The one or two measurements after it move the state a long way on a
        // linearisation that holds over pixels, not hundreds of them: a 4 x 4 grid came back 394 mm off, marked
        // tracking, because the measurements before the gap still made the median innovation of the cycle. Such a
        // state is disputed until a whole window of measurements newer than the jump agrees with it. (A frame's
        // blobs are judged together in `on_batch`: its first blob is often pixels off on fast motion, and the rest
        // pin the pose.)
        if let UpdateOutcome::Accepted { norm_px, .. } = outcome
            && norm_px > core.config.lost_residual_px
        {
            self.jumped_since_estimate = true;
        }
    }

    /// Each blob of the readout in turn, then, if at least [`MIN_READOUT_TO_REFINE`] were accepted, their iterated
    /// update from the prior at the readout's first time ([`ErrorStateKalman::refine`]); blobs it finds inside the
    /// gate after all no longer count as rejected.
    fn on_batch(&mut self, core: &mut TrackCore, batch: &[Observation]) {
        // No prediction of this batch starts before the filter's time (a readout taken again starts from its first).
        self.known.forget_before(core.t_ref_s);
        // Too few to refine (the streaming `track` pushes one measurement at a time): no copy of the filter.
        if batch.len() < MIN_READOUT_TO_REFINE {
            for obs in batch {
                self.on_measurement(core, obs);
            }
            return;
        }
        let first = &batch[0];
        let dt = self.predict_to(core, first.t_s);
        let before = self.counters(core);
        // The blobs of one instant come in the points' order, and a camera file's error is worst at the image's
        // edge, where neighbouring points enter the view together: a run of them beyond the gate is the model's
        // error, not the filter's, and widening the covariance there restarted a 24 x 28 grid seen through a
        // nominal camera file whenever a row of circles entered the view. Within one instant, what says the filter
        // is off is the share of its blobs rejected (below), not their order.
        // So on small targets too: a frame that shows a pose has its blobs judged together, each against the
        // prediction before the frame (see `take_readout`), and a run of them beyond the gate widens nothing.
        let one_instant = batch.iter().all(|obs| obs.t_s == first.t_s);
        let pose_points = if core.target.is_planar() { 4 } else { 6 };
        let shows_pose = one_instant && distinct_points(batch, pose_points);
        self.in_one_instant = shows_pose;
        let mut used = self.take_readout(core, batch, dt);
        // Half or more of the blobs of one instant rejected: a filter that no longer predicts the target (a turn
        // faster than its process noise allows between frames), or half the blobs outliers. The readout is taken
        // again from the prior widened at once to the broad one, as the escalating resets would after several frames
        // of rejections, so that its blobs, which pin the pose, set it; and that is kept if it explains more of them
        // (within the gate of their noise) than the first pass did, which it does not when they were outliers.
        if shows_pose && 2 * used <= batch.len() {
            let first_pass = (self.counters(core), self.innovations.clone());
            let explained_first = explained(self.filter.tuning(), core, batch);
            self.restore(core, before);
            self.filter.widen(&core.prior_covariance(), 1.0);
            self.covariance_resets += 1;
            self.resets_total += 1;
            let used_again = self.take_readout(core, batch, dt);
            if explained(self.filter.tuning(), core, batch) > explained_first {
                used = used_again;
                self.judge_by_residuals(core, batch, before.innovations);
            } else {
                self.restore(core, first_pass.0);
                self.innovations = first_pass.1;
            }
        }
        if self.in_one_instant {
            self.in_one_instant = false;
            // Most of the instant's blobs explained: the rejected ones are outliers or the model's error, in no
            // order; no run of them carries over to dispute the estimate or widen the filter.
            if 2 * used > batch.len() {
                self.gated_in_a_row = 0;
            }
        }
    }

    fn control_step(&mut self, core: &mut TrackCore, t_new_s: f64) -> Step {
        // The filter is already at t_new; the window only gives the conditioning figure and the noise sample.
        let ne = core.window_problem(t_new_s).normal_equations(&core.state);
        let solved = ne.solve_with_conditioning();
        // A window of one instant (the blobs of the one global-shutter frame a new track has seen, or, with the
        // newest measurement of each point as the window, of every global-shutter frame) shows the pose and never
        // the twist, which is the filter's prior's (carried over from the previous track, or at rest with
        // a broad spread the covariance states): such a step is as well posed as its pose. (Judged on all 12
        // parameters, the first estimate of every new track on frames was flagged degenerate, an 80-point grid
        // seen whole included.)
        // So does a window of global-shutter frames that mixes two instants: a point left out of this frame (its
        // blob cut by its window) keeps its measurement of the frame before, and the 12 parameters of 322 points of
        // one frame and 14 of the one before were judged degenerate, their twist shown by those 14 alone.
        self.frame_steps = core.recent_are_frames(core.step_measurements);
        let inverse_condition = if is_one_instant(&core.scratch) || self.frame_steps {
            pose_inverse_condition(&ne)
        } else {
            solved.map_or(0.0, |(_, c)| c)
        };
        if self.filter.tuning().adapt_noise {
            self.learn_noise(core, t_new_s, &ne, solved.map(|(step, _)| step));
        }
        if self.shares_noise() {
            self.point_noise.update_factors();
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
        let pose_twist_covariance = self.filter.pose_twist_covariance();
        let covariance = if self.filter.tuning().calibrate_twist_covariance {
            self.calibration.record(
                t_new_s,
                &core.state,
                &pose_twist_covariance,
                status == TrackStatus::Tracking,
            );
            self.calibration.apply(&pose_twist_covariance)
        } else {
            pose_twist_covariance
        };
        Step {
            inverse_condition,
            measurements_used: ne.count(),
            iterations: core.step_measurements,
            status,
            covariance: Some(covariance),
            // The whole acceleration: the filter's own and the known input in force.
            acceleration: self.filter.acceleration().map(|own| {
                if self.known.is_empty() {
                    own
                } else {
                    known::sum(&own, &self.known.at(t_new_s))
                }
            }),
        }
    }

    /// A run of rejected measurements, a newest measurement far beyond the gate, or most of those since the last
    /// estimate rejected (the filter was reset after a run of them and is still re-converging). One measurement
    /// just beyond the gate is not enough: 1.1 % of good measurements land there.
    fn is_disputed(&self, core: &TrackCore, _residuals: &ResidualFigures) -> bool {
        // A point whose last measurements the gate refused, [`DISPUTED_AFTER_POINT_REFUSED_IN_A_ROW`] of them, on a
        // target where the rest are too few to hold the state: a state that has left one point can drift where the
        // others do not hold it (seen on 4 points: rotated 150 degrees within 50 ms, one point refused at every
        // cycle). On larger targets the rest hold the state, and several points refused at once are
        // common while the filter learns a noise above the one it assumed. Only refusals of the last two cycles
        // count: a point refused and then no longer measured (hidden, its window lost) says nothing of the state.
        let recent = |at: u64| self.taken.saturating_sub(at) < 2 * self.gated_runs.len() as u64;
        let refused_points = self
            .gated_runs
            .iter()
            .filter(|&&(run, at)| run > 0 && recent(at))
            .count();
        let holding_points = self.gated_runs.len() - refused_points;
        let persistent = self
            .gated_runs
            .iter()
            .any(|&(run, at)| run >= DISPUTED_AFTER_POINT_REFUSED_IN_A_ROW && recent(at));
        self.jumped_since_estimate
            || self.gated_in_a_row >= DISPUTED_AFTER_GATED_IN_A_ROW
            || (self.gated_in_a_row > 0 && self.newest_nis > DISPUTED_NIS)
            || 2 * self.gated_since_estimate >= core.step_measurements.max(2)
            || (persistent && holding_points < HOLDING_POINTS)
    }

    fn after_estimate(&mut self) {
        self.gated_since_estimate = 0;
        self.jumped_since_estimate = false;
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

    fn known_acceleration(&mut self) -> Option<&mut KnownAcceleration> {
        Some(&mut self.known)
    }
}

/// Points whose newest measurement was accepted that hold a Kalman state when another's was refused: a pose from
/// fewer than 6 points can have rival minima (three give up to four poses, four or five a mirror twin in some views),
/// along which the state can slide while one point disagrees.
pub(super) const HOLDING_POINTS: usize = 6;

/// Whether every observation of `window` has one time (and there is one).
/// The gate of a frame's pose innovation ([`Filter::match_pose_innovation`]): the 99.9 % quantile of a chi-square
/// of 6 degrees of freedom, so that a filter whose covariance is right widens it on one frame in a thousand.
pub(super) const POSE_INNOVATION_GATE_CHI2: f64 = 22.458;

pub(super) fn is_one_instant(window: &[Observation]) -> bool {
    window
        .first()
        .zip(window.last())
        .is_some_and(|(first, last)| first.t_s == last.t_s)
}

/// The reciprocal condition number of the column-scaled Jacobian of the pose alone (the first 6 of the 12
/// parameters, the twist held), as [`roitrack_core::solver::NormalEquations::solve_with_conditioning`] gives it for all 12; 0 when singular.
pub(super) fn pose_inverse_condition(ne: &roitrack_core::solver::NormalEquations<12>) -> f64 {
    let pose = ne.symmetric_jtj().fixed_view::<6, 6>(0, 0).into_owned();
    let scale = pose
        .diagonal()
        .map(|d| if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 });
    let scaled = SMatrix::<f64, 6, 6>::from_diagonal(&scale)
        * pose
        * SMatrix::<f64, 6, 6>::from_diagonal(&scale);
    let eigenvalues = scaled.symmetric_eigenvalues();
    let (low, high) = (eigenvalues.min(), eigenvalues.max());
    if high > 0.0 && low.is_finite() {
        (low.max(0.0) / high).sqrt()
    } else {
        0.0
    }
}

/// Gated measurements in a row that dispute an estimate (3 in a row happen by chance once in 700,000 good ones).
pub(super) const DISPUTED_AFTER_GATED_IN_A_ROW: usize = 3;

/// Measurements of one point refused in a row that dispute an estimate of a target too small for the rest to hold
/// its state ([`HOLDING_POINTS`]): a good point's are refused three times in a row with a chance of 1.3e-6 per
/// point and cycle, as rarely as the other rules fire on good measurements. Two in a row, 1.2e-4, disputed a 2 x 3
/// grid at random about every two seconds at 4 kHz (0.5 a second over its points), a third of them at the start of
/// a move (the orthoglide, seeds 1-6: 0-2 disputes a run); one alone, 1.1e-2, would dispute every twentieth estimate
/// of 4 points.
pub(super) const DISPUTED_AFTER_POINT_REFUSED_IN_A_ROW: u32 = 3;

/// A newest measurement gated with a normalised innovation squared above this (5 σ: once in 270,000 good
/// measurements) disputes the estimate on its own.
pub(super) const DISPUTED_NIS: f64 = 25.0;

/// What [`KalmanLaw::take_readout`] changes besides the readout's points, to take a readout again.
#[derive(Debug, Clone, Copy)]
pub(super) struct LawCounters {
    pub(super) filter: Filter,
    pub(super) state: MotionState,
    pub(super) gated_in_a_row: usize,
    pub(super) covariance_resets: usize,
    pub(super) reset_level: usize,
    pub(super) accepted_in_a_row: usize,
    pub(super) innovations: TallyMark,
    pub(super) gated_since_estimate: usize,
    pub(super) gated_total: usize,
    pub(super) resets_total: usize,
    pub(super) newest_nis: f64,
    pub(super) process_log_scale: [f64; 2],
}

impl KalmanLaw {
    /// After a readout was taken again from a widened covariance, what judges the track (lost, or following its
    /// measurements) is how well the new state explains the readout, not the blobs' innovations against the
    /// prediction it overruled: those stay pixels off however right the state is, and three such estimates in a row
    /// dropped the track. The innovations since `mark` are replaced by the residuals, scaled up by the pose's six
    /// fitted parameters (four dots: 8 equations, 2 redundant), so that a frame the pose cannot explain still shows.
    fn judge_by_residuals(&mut self, core: &TrackCore, batch: &[Observation], mark: TallyMark) {
        let n = 2.0 * batch.len() as f64;
        let unbiased = (n / (n - 6.0)).sqrt();
        self.innovations.rewind(mark);
        for residual_px in residuals_px(core, batch) {
            self.innovations.add(residual_px * unbiased);
        }
    }

    pub(super) fn counters(&self, core: &TrackCore) -> LawCounters {
        LawCounters {
            filter: self.filter,
            state: core.state,
            gated_in_a_row: self.gated_in_a_row,
            covariance_resets: self.covariance_resets,
            reset_level: self.reset_level,
            accepted_in_a_row: self.accepted_in_a_row,
            innovations: self.innovations.mark(),
            gated_since_estimate: self.gated_since_estimate,
            gated_total: self.gated_total,
            resets_total: self.resets_total,
            newest_nis: self.newest_nis,
            process_log_scale: self.process_log_scale,
        }
    }

    pub(super) fn restore(&mut self, core: &mut TrackCore, c: LawCounters) {
        self.filter = c.filter;
        core.state = c.state;
        self.gated_in_a_row = c.gated_in_a_row;
        self.covariance_resets = c.covariance_resets;
        self.reset_level = c.reset_level;
        self.accepted_in_a_row = c.accepted_in_a_row;
        self.innovations.rewind(c.innovations);
        self.gated_since_estimate = c.gated_since_estimate;
        self.gated_total = c.gated_total;
        self.resets_total = c.resets_total;
        self.newest_nis = c.newest_nis;
        self.process_log_scale = c.process_log_scale;
    }

    /// Takes a readout (the filter already at its first time, `dt` after the measurement before): its blobs one by
    /// one, then, for three or more, fitted together with the prior ([`Filter::refine`]). Returns how many blobs the
    /// result uses.
    ///
    /// When the noise holds the model's error apart ([`CentroidNoise`]), the blobs of one instant are judged against
    /// the prediction before any of them: weighed by their white part alone, the first blobs pin the pose, bias and
    /// all, and a later blob judged against that pose sat as far off as the model's error through a fit of three
    /// points amplifies it (4 dots on nominal files: one in a few frames refused, the track disputed and restarted).
    /// And they are weighed so only if every one of them is inside the gate: the pose of the rest would carry their
    /// model's error differently from a pose of all of them (the user's reference), and with 3 dots of 4 it moved
    /// by up to half a millimetre; such a frame is weighed by the whole noise, as the bias were white.
    pub(super) fn take_readout(
        &mut self,
        core: &mut TrackCore,
        batch: &[Observation],
        dt: f64,
    ) -> usize {
        let first = &batch[0];
        let (resets, gated_in_a_row, accepted_in_a_row) = (
            self.resets_total,
            self.gated_in_a_row,
            self.accepted_in_a_row,
        );
        let mut readout = std::mem::take(&mut self.readout);
        readout.clear();
        let mut judged = std::mem::take(&mut self.judged_nis);
        judged.clear();
        let bias = self.split_noise(core.noise_px).bias_px > 0.0;
        // The blobs of a frame judged together (`in_one_instant`, see `on_batch`) are each judged against the
        // prediction before the frame, not against the state its blobs before them moved: after a new track's broad
        // start a frame 28 mm from the prediction, well inside its covariance, moved the state blob by blob along
        // linearisations tens of pixels off, until the next blobs lay beyond their gate, the covariance was reset and
        // the track started again on every frame.
        if (bias || self.in_one_instant) && is_one_instant(batch) {
            judged.extend(batch.iter().map(|obs| {
                let p = &core.target.points()[obs.point_index].point_in_obj_m;
                let noise = self.split_noise(self.point_noise_px(core, obs.point_index));
                self.filter
                    .prediction_nis(&core.model, &core.state, p, &obs.ideal_px, noise)
            }));
            let gate2 = self.filter.tuning().gate_sigma.powi(2);
            self.bias_apart = bias && judged.iter().all(|nis| nis.is_some_and(|nis| nis <= gate2));
            if self.bias_apart {
                let blobs = batch.iter().map(|obs| {
                    let white_px = self
                        .split_noise(self.point_noise_px(core, obs.point_index))
                        .white_px;
                    (
                        core.target.points()[obs.point_index].point_in_obj_m,
                        obs.ideal_px,
                        white_px * white_px,
                    )
                });
                // A copy to widen (the blobs' noise reads the law): the filter is a few hundred words.
                let mut filter = self.filter;
                filter.match_pose_innovation(
                    &core.model,
                    &core.state,
                    blobs,
                    POSE_INNOVATION_GATE_CHI2,
                );
                self.filter = filter;
            }
        }
        let prior = (self.filter, core.state);
        for (i, obs) in batch.iter().enumerate() {
            let dt = if i == 0 {
                dt
            } else {
                self.predict_to(core, obs.t_s)
            };
            // A readout's blobs (a frame's, or a rolling-shutter frame's rows) do not teach the points' shares: each
            // point comes once a frame, and a readout may be taken twice (see `on_batch`).
            let outcome = self.take(core, obs, dt, false, judged.get(i).copied().flatten());
            let huber = self.filter.tuning().huber_sigma;
            let nis = match outcome {
                UpdateOutcome::Accepted { nis, .. } | UpdateOutcome::Gated { nis, .. } => nis,
                UpdateOutcome::Invalid => continue,
            };
            let gated = matches!(outcome, UpdateOutcome::Gated { .. });
            readout.push(ReadoutMeasurement {
                point_index: obs.point_index,
                point_in_obj_m: core.target.points()[obs.point_index].point_in_obj_m,
                ideal_px: obs.ideal_px,
                dt_s: obs.t_s - first.t_s,
                variance_px2: self.centroid_noise(core, obs.point_index).white_px.powi(2)
                    * (nis.sqrt() / huber).max(1.0),
                gated,
                used: !gated,
            });
        }
        // A covariance reset within the readout has already said the prior was wrong: what it widened is no prior.
        let accepted = readout.iter().filter(|m| m.used).count();
        if accepted >= MIN_READOUT_TO_REFINE && self.resets_total == resets {
            let span_s = core.t_ref_s - first.t_s;
            let process_scale = self.process_log_scale.map(f64::exp);
            let noise = self.weighed_noise(core.noise_px);
            let fit = ReadoutFit {
                prior_state: &prior.1,
                span_s,
                model: &core.model,
                noise,
                process_scale,
            };
            let refined = self.filter.refine(
                &prior.0,
                &fit,
                &mut core.state,
                &mut readout,
                Some((first.t_s, &self.known)),
            );
            if refined {
                self.forgive_recovered(&readout, gated_in_a_row, accepted_in_a_row);
            }
        }
        let used = readout.iter().filter(|m| m.used).count();
        self.readout = readout;
        self.judged_nis = judged;
        self.bias_apart = false;
        used
    }

    pub(super) fn new(tuning: KalmanTuning) -> Self {
        Self {
            filter: Filter::new(Matrix12::identity(), tuning, 0.0),
            gated_in_a_row: 0,
            covariance_resets: 0,
            reset_level: 0,
            accepted_in_a_row: 0,
            innovations: ResidualTally::default(),
            gated_since_estimate: 0,
            gated_total: 0,
            resets_total: 0,
            newest_nis: 0.0,
            jumped_since_estimate: false,
            noise: NoiseEstimate::new(1.0, 0.0),
            white_noise: NoiseEstimate::new(1.0, 0.0),
            frame_residuals: FrameResiduals::default(),
            process_log_scale: [0.0; 2],
            frame_steps: false,
            gated_at: Vec::new(),
            gated_runs: Vec::new(),
            taken: 0,
            in_one_instant: false,
            calibration: TwistCalibration::new(),
            point_noise: PointNoise::default(),
            readout: Vec::new(),
            judged_nis: Vec::new(),
            bias_apart: false,
            known: KnownAcceleration::default(),
        }
    }

    /// Moves the filter to `t_s`; returns by how much (s).
    pub(super) fn predict_to(&mut self, core: &mut TrackCore, t_s: f64) -> f64 {
        let dt = t_s - core.t_ref_s;
        self.filter.predict_known(
            &mut core.state,
            core.t_ref_s,
            dt,
            self.process_log_scale.map(f64::exp),
            &self.known,
        );
        core.t_ref_s = t_s;
        dt
    }

    /// Whether the points learn their shares of the learnt noise (`KalmanTuning::learn_point_noise`).
    pub(super) fn shares_noise(&self) -> bool {
        let tuning = self.filter.tuning();
        tuning.adapt_noise && tuning.learn_point_noise
    }

    /// The centroid noise of `point` (px): the target's, times the point's share when the points learn theirs.
    pub(super) fn point_noise_px(&self, core: &TrackCore, point: usize) -> f64 {
        if self.shares_noise() {
            core.noise_px * self.point_noise.factor(point)
        } else {
            core.noise_px
        }
    }

    /// The noise of `point`'s centroid as an update weighs and judges it: the point's noise
    /// ([`Self::point_noise_px`]), split ([`Self::split_noise`]) while the frame being taken holds the model's error
    /// apart ([`KalmanLaw::take_readout`]).
    pub(super) fn centroid_noise(&self, core: &TrackCore, point: usize) -> CentroidNoise {
        self.weighed_noise(self.point_noise_px(core, point))
    }

    /// A centroid noise of `total_px` as the frame being taken weighs it: split while it holds the model's error
    /// apart, else white.
    pub(super) fn weighed_noise(&self, total_px: f64) -> CentroidNoise {
        if self.bias_apart {
            self.split_noise(total_px)
        } else {
            CentroidNoise::white(total_px)
        }
    }

    /// A centroid noise of `total_px` as white noise; but on global-shutter frames, once their white part is known
    /// ([`MIN_WHITE_NOISE_DOF`]), that part, and the rest as the model's error.
    pub(super) fn split_noise(&self, total_px: f64) -> CentroidNoise {
        if !(self.frame_steps
            && self.filter.tuning().adapt_noise
            && self.white_noise.dof >= MIN_WHITE_NOISE_DOF)
        {
            return CentroidNoise::white(total_px);
        }
        // The white part is at most the whole (its samples also hold the bias's change between frames).
        let white_px = self.white_noise.noise_px().min(total_px);
        CentroidNoise {
            white_px,
            bias_px: (total_px * total_px - white_px * white_px).max(0.0).sqrt(),
        }
    }

    /// Updates the filter, already at its time, with `obs`, `dt` after the measurement before, and keeps the
    /// counters and what the filter learns from it (the points' shares of the noise only if `learn_points`), judged
    /// by `judged_nis` if it was judged before ([`ErrorStateKalman::update`]).
    pub(super) fn take(
        &mut self,
        core: &mut TrackCore,
        obs: &Observation,
        dt: f64,
        learn_points: bool,
        judged_nis: Option<f64>,
    ) -> UpdateOutcome {
        let p = core.target.points()[obs.point_index].point_in_obj_m;
        let noise = self.centroid_noise(core, obs.point_index);
        let outcome = self.filter.update(
            &core.model,
            &mut core.state,
            &p,
            &obs.ideal_px,
            noise,
            judged_nis,
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
        if self.filter.tuning().adapt_motion
            && !self.frame_steps
            && dt != 0.0
            && matches!(outcome, UpdateOutcome::Accepted { .. })
        {
            self.adapt_process_scale(self.filter.persistence());
        }
        // Every innovation, gated or not, teaches the points' shares of the noise (a point much noisier than the
        // target's noise has many of its innovations gated; the shares' medians are robust to real outliers), on
        // streams of measurements one at a time only: frames, global- or rolling-shutter, measure each point once a
        // frame, and the second differences would span 100 ms at 30 Hz, too long for a lag to cancel.
        if learn_points
            && self.shares_noise()
            && self.filter.tuning().noise_sample == NoiseSample::Window
            && !self.frame_steps
            && dt != 0.0
            && !matches!(outcome, UpdateOutcome::Invalid)
        {
            let (innovation_px, predicted_variance_px2) = self.filter.newest_innovation();
            self.point_noise.observe(
                obs.point_index,
                obs.t_s,
                innovation_px,
                predicted_variance_px2,
                noise.total_px2().sqrt(),
            );
        }
        // Outliers are rare and scattered; a run of gated measurements means the filter itself is off (after a jump
        // of the target, or an outlier that got through): widen its covariance so the measurements pull it back,
        // instead of coasting on a wrong state.
        let gated = matches!(outcome, UpdateOutcome::Gated { .. });
        self.taken += 1;
        // The same measurement refused again (a readout taken a second time from a widened prior) is no new
        // refusal.
        let again = self.gated_at.get(obs.point_index) == Some(&Some(obs.t_s));
        if let Some((run, at)) = self.gated_runs.get_mut(obs.point_index) {
            *run = match (gated, again) {
                (false, _) => 0,
                (true, true) => *run,
                (true, false) => *run + 1,
            };
            *at = self.taken;
        }
        if let Some(gated_at) = self.gated_at.get_mut(obs.point_index) {
            *gated_at = gated.then_some(obs.t_s);
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
        if self.gated_in_a_row >= GATED_IN_A_ROW_FOR_RESET && !self.in_one_instant {
            // Escalate: a run of rejections is more often a bad update than a jump of the target; a little widening
            // lets the measurements correct it without exposing the filter to every outlier, and if the runs go on
            // (a jump), the next resets widen it to the broad prior.
            let scale = RESET_SCALES[self.reset_level.min(RESET_SCALES.len() - 1)];
            self.filter.widen(&core.prior_covariance(), scale);
            self.reset_level += 1;
            self.gated_in_a_row = 0;
            self.covariance_resets += 1;
            self.resets_total += 1;
        }
        outcome
    }

    /// The readout's blobs that its refinement used after the sequential updates had rejected them
    /// ([`ErrorStateKalman::refine`]) are not counted as rejected; the runs of rejected and accepted blobs are
    /// counted again over the readout, from theirs before it (`gated_in_a_row`, `accepted_in_a_row`).
    pub(super) fn forgive_recovered(
        &mut self,
        readout: &[ReadoutMeasurement],
        gated_in_a_row: usize,
        accepted_in_a_row: usize,
    ) {
        let recovered = readout.iter().filter(|m| m.gated && m.used).count();
        if recovered == 0 {
            return;
        }
        self.gated_since_estimate = self.gated_since_estimate.saturating_sub(recovered);
        self.gated_total = self.gated_total.saturating_sub(recovered);
        (self.gated_in_a_row, self.accepted_in_a_row) = (gated_in_a_row, accepted_in_a_row);
        for m in readout {
            if m.gated
                && m.used
                && let Some(gated_at) = self.gated_at.get_mut(m.point_index)
            {
                *gated_at = None;
                if let Some((run, _)) = self.gated_runs.get_mut(m.point_index) {
                    *run = 0;
                }
            }
            if m.used {
                self.gated_in_a_row = 0;
                self.accepted_in_a_row += 1;
            } else {
                self.gated_in_a_row += 1;
                self.accepted_in_a_row = 0;
            }
        }
    }

    /// Moves each process-noise scale (linear, angular) towards the one that makes the innovations white: a positive
    /// persistence (the corrections keep going one way: the filter lags the motion) raises it, a negative one (they
    /// undo each other: the filter chases the noise, as it does on a still target) lowers it. Clamped at 3 so that
    /// one outlier moves it by at most 16 %.
    pub(super) fn adapt_process_scale(&mut self, persistence: [f64; 2]) {
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
    pub(super) fn learn_noise(
        &mut self,
        core: &mut TrackCore,
        t_new_s: f64,
        ne: &roitrack_core::solver::NormalEquations<12>,
        step: Option<roitrack_core::Vector12>,
    ) {
        if self.frame_steps {
            self.learn_noise_from_frames(core, t_new_s);
            return;
        }
        // With frames, the other steps are rolling-shutter frames, which are not sampled.
        if self.filter.tuning().noise_sample == NoiseSample::Frames {
            return;
        }
        let min_measurements = (12 + MIN_NOISE_DOF).div_ceil(2);
        let mut rebuilt = false;
        if ne.count() < min_measurements {
            core.fill_scratch(crate::WindowMode::Last(min_measurements));
            rebuilt = true;
        }
        rebuilt |= drop_gated(&self.gated_at, &mut core.scratch, 0);
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
    pub(super) fn gate_truncated_fraction(&self) -> f64 {
        let g2 = self.filter.tuning().gate_sigma * self.filter.tuning().gate_sigma;
        let tail = (-g2 / 2.0).exp();
        (1.0 - (1.0 + g2 / 2.0) * tail) / (1.0 - tail)
    }

    /// Folds the residuals of the step's frames into the noise estimate: each frame's blobs (those that share one
    /// time) with its pose alone fitted, the twist held at the filter's, of redundancy `2 m - 6`; frames of fewer
    /// than 4 blobs are left out, and so are the blobs the gate rejected, unless they are more than a quarter of
    /// their frame. Corrected for the gate's truncation as the windows are: the first blobs of a frame meet a gate
    /// widened by the prediction's spread, but the frame's later ones, once those have pinned the pose, one not much
    /// wider than the noise: without the correction the learnt noise is biased low and the filter tracks worse than
    /// one told the true noise; with it, as well (measured in docs/results.md, "Design measurements behind the
    /// code").
    ///
    /// The newest frame's residuals at that fit are also compared with those of the frame sampled before it
    /// ([`FrameResiduals`]), which samples the white part of the noise.
    pub(super) fn learn_noise_from_frames(&mut self, core: &mut TrackCore, t_new_s: f64) {
        let step = core.step_measurements;
        let (mut cost_px2, mut dof, mut taken) = (0.0, 0.0, 0);
        while taken < step {
            let count = core.fill_scratch_with_instant(step, taken);
            if count == 0 {
                break;
            }
            let newest = taken == 0;
            taken += count;
            drop_gated(&self.gated_at, &mut core.scratch, FRAME_SAMPLE_MIN_BLOBS);
            if core.scratch.len() < FRAME_SAMPLE_MIN_BLOBS {
                continue;
            }
            let problem = core.window_problem(t_new_s);
            let frame = problem.normal_equations(&core.state);
            if let Some((pose_step, frame_cost_px2)) = pose_only_optimum(&frame) {
                cost_px2 += frame_cost_px2;
                dof += (2 * frame.count() - 6) as f64;
                if newest
                    && let Some((change_px2, change_dof)) =
                        self.frame_residuals
                            .sample(&problem, &core.state, &pose_step)
                {
                    self.white_noise.add(change_px2 / change_dof, change_dof);
                }
            }
        }
        if dof > 0.0 {
            self.noise
                .add(cost_px2 / dof / self.gate_truncated_fraction(), dof);
            core.noise_px = self.noise.noise_px();
        }
    }
}

/// The distance (px) of each blob of a readout of one instant from where the current state projects its point
/// (blobs whose point does not project left out).
pub(super) fn residuals_px<'a>(
    core: &'a TrackCore,
    batch: &'a [Observation],
) -> impl Iterator<Item = f64> + 'a {
    batch.iter().filter_map(|obs| {
        let p = &core.target.points()[obs.point_index].point_in_obj_m;
        core.model
            .project(&core.state, p, 0.0)
            .map(|pixel| (obs.ideal_px - pixel).norm())
    })
}

/// How many blobs of a readout of one instant the current state puts within the gate of their noise.
pub(super) fn explained(tuning: &KalmanTuning, core: &TrackCore, batch: &[Observation]) -> usize {
    let radius_px = tuning.gate_sigma * core.noise_px;
    residuals_px(core, batch).filter(|&r| r < radius_px).count()
}

/// Whether `batch` measures at least `needed` distinct points.
pub(super) fn distinct_points(batch: &[Observation], needed: usize) -> bool {
    let mut distinct = 0;
    for (i, obs) in batch.iter().enumerate() {
        if batch[..i].iter().all(|o| o.point_index != obs.point_index) {
            distinct += 1;
            if distinct >= needed {
                return true;
            }
        }
    }
    false
}
