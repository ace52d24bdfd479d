//! The centroid noise the filter learns: from the windows' and frames' residuals, and its white part apart from the
//! model's error on frames.

use super::*;

/// Degrees of freedom of the window residual that the noise estimate remembers (an exponential memory): 2,000 dof
/// (100 control steps of a 16-point window) estimate the variance to ±3 %.
pub(super) const NOISE_MEMORY_DOF: f64 = 2000.0;

/// Smallest redundancy (2 x measurements - 12) of a window that feeds the noise estimate.
pub(super) const MIN_NOISE_DOF: usize = 8;

/// Largest factor by which one window may raise the noise variance: a window that holds an outlier does not drag it
/// up.
pub(super) const NOISE_STEP_FACTOR: f64 = 4.0;

/// The centroid noise learnt from the redundancy of the measurement windows.
///
/// At every control step the window's least-squares residual at its own optimum, `eᵀe - eᵀJ (JᵀJ)⁻¹ Jᵀe`, divided by
/// its redundancy `2 m - 12` (m measurements, 12 parameters), is an unbiased sample of the noise variance per axis
/// as long as the constant twist holds over the window (a few milliseconds of ROIs). Unlike the innovations it does
/// not depend on the process noise: a filter that lags does not mistake its lag for noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct NoiseEstimate {
    pub(super) variance_px2: f64,
    /// Degrees of freedom behind the estimate (capped at [`NOISE_MEMORY_DOF`]).
    pub(super) dof: f64,
}

impl NoiseEstimate {
    pub(super) fn new(noise_px: f64, dof: f64) -> Self {
        Self {
            variance_px2: noise_px * noise_px,
            dof,
        }
    }

    /// Folds in one window's residual variance, worth `dof` degrees of freedom.
    pub(super) fn add(&mut self, sample_px2: f64, dof: f64) {
        if !(sample_px2.is_finite() && dof > 0.0) {
            return;
        }
        let floor = crate::track::MIN_NOISE_PX * crate::track::MIN_NOISE_PX;
        // Only upwards: a window that holds an outlier the gate let through must not drag the estimate up, but a
        // quiet window is no outlier (after a start from a noisy initial fit, the estimate must come down fast).
        let sample = sample_px2
            .min(self.variance_px2 * NOISE_STEP_FACTOR)
            .max(floor);
        let weight = dof / (self.dof.min(NOISE_MEMORY_DOF) + dof);
        self.variance_px2 += weight * (sample - self.variance_px2);
        self.dof += dof;
    }

    pub(super) fn noise_px(&self) -> f64 {
        self.variance_px2.sqrt()
    }
}

/// The fewest blobs of one frame that make a noise sample: a pose fitted to 4 blobs leaves 2 degrees of freedom.
pub(super) const FRAME_SAMPLE_MIN_BLOBS: usize = 4;

/// Leaves out of a noise sample's `scratch` the measurements the gate rejected (per point, the time of its newest
/// rejected one, `gated_at`): an outlier of 5-20 px would count as much noise as a hundred good centroids. Unless they
/// are more than a quarter of it: then the noise itself has grown beyond the estimate, and they must count for the
/// estimate to follow; or unless leaving them out would leave fewer than `min_kept`, too few for a sample: then
/// every sample of a 4-point target with one blob gated would be lost, and a noise started too low (a camera file
/// 2 % off leaves its 4 dots 0.5-1 px from any pose while the filter assumed 0.1 px) would gate one blob in every
/// frame and never grow. Returns whether any was left out.
pub(super) fn drop_gated(
    gated_at: &[Option<f64>],
    scratch: &mut Vec<Observation>,
    min_kept: usize,
) -> bool {
    let is_gated = |o: &Observation| gated_at.get(o.point_index) == Some(&Some(o.t_s));
    let gated = scratch.iter().filter(|o| is_gated(o)).count();
    let drop = gated > 0 && 4 * gated <= scratch.len() && scratch.len() - gated >= min_kept;
    if drop {
        scratch.retain(|o| !is_gated(o));
    }
    drop
}

/// The fit of `window` over the pose alone (the first six parameters; `H` and `g` their block of `JᵀJ` and `Jᵀe`),
/// the twist held: the solution `x = H⁻¹ g` (the pose moves by `-x`) and the least-squares residual `eᵀe - gᵀ x` at
/// it; `None` when that block is singular.
pub(super) fn pose_only_optimum(
    window: &roitrack_core::solver::NormalEquations<12>,
) -> Option<(Vector6<f64>, f64)> {
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
    let scaled_x = scaled.cholesky()?.solve(&scaled_g);
    let cost = window.cost_px2() - scaled_x.dot(&scaled_g);
    cost.is_finite()
        .then_some((scaled_x.component_mul(&scale), cost.max(0.0)))
}

/// The fewest degrees of freedom behind the white part of the noise before the updates weigh it apart from the
/// model's error ([`CentroidNoise`]): a variance from 16 has a relative standard error of 35 %, from 8 of 50 %.
/// Eight frames of 4 blobs, one of 11 or more.
pub(super) const MIN_WHITE_NOISE_DOF: f64 = 16.0;

/// The blobs' residuals of the newest global-shutter frame at the fit of its pose alone, kept to sample the white
/// part of the centroid noise from the next frame's.
///
/// A blob's residual at the fit is `r = P (b + w)`: `b` the model's error at that pose, `w` white noise, `P` the
/// projection that removes what the pose absorbs (of rank `2 m - 6` for `m` blobs). From one frame to the next the
/// pose, hence `b` and `P`, hardly change, so `r₂ - r₁ = P (w₂ - w₁)`, whose squared norm is `2 σ²` times a
/// chi-square of `2 m - 6` degrees of freedom: the bias cancels. Blobs measured in one frame only are left out
/// (windows lose and regain blobs at the edge of a dense grid: asked for the same points in both frames, a
/// 336-point grid seldom had a sample, and its jitter stayed up to 4.7 times the per-frame poses'). What does not
/// cancel (the bias's change with the pose between frames, and with `P` as blobs come and go) can only raise the
/// sample on average: the white part it gives is at most too large, never too small.
#[derive(Debug, Clone, Default)]
pub(super) struct FrameResiduals {
    /// Per point, its residual (px) in the frame before, if it was measured there.
    pub(super) before: Vec<Option<Vector2<f64>>>,
    /// The frame being sampled (kept to reuse its allocation).
    pub(super) newest: Vec<(usize, Vector2<f64>)>,
}

impl FrameResiduals {
    pub(super) fn clear(&mut self) {
        self.before.fill(None);
    }

    /// Takes the residuals of the frame `problem` holds, at `state` moved by the pose-only fit's solution `x`
    /// ([`pose_only_optimum`]), and, when the frame before measured at least 4 of the same points, returns the
    /// sample of the white variance they give: `|r₂ - r₁|² / 2` summed over them (px²) and its degrees of freedom,
    /// `2 m - 6` for `m` of them.
    pub(super) fn sample(
        &mut self,
        problem: &crate::problem::WindowProblem<'_>,
        state: &MotionState,
        x: &Vector6<f64>,
    ) -> Option<(f64, f64)> {
        struct AtOptimum<'a> {
            x: &'a Vector6<f64>,
            residuals_px: &'a mut Vec<(usize, Vector2<f64>)>,
            points: std::slice::Iter<'a, Observation>,
        }
        impl roitrack_core::solver::ResidualSink<12> for AtOptimum<'_> {
            fn add(
                &mut self,
                jacobian: &SMatrix<f64, 2, 12>,
                residual: &Vector2<f64>,
                _weight: f64,
            ) {
                if let Some(obs) = self.points.next() {
                    let at_optimum = residual - jacobian.fixed_columns::<6>(0) * self.x;
                    self.residuals_px.push((obs.point_index, at_optimum));
                }
            }
            fn add_unevaluable(&mut self) {
                self.points.next();
            }
        }
        self.newest.clear();
        let mut sink = AtOptimum {
            x,
            residuals_px: &mut self.newest,
            points: problem.window.iter(),
        };
        roitrack_core::solver::LeastSquaresProblem::linearize(problem, state, &mut sink);
        let (mut change_px2, mut common) = (0.0, 0);
        for (point, residual_px) in &self.newest {
            if let Some(Some(before_px)) = self.before.get(*point) {
                change_px2 += (residual_px - before_px).norm_squared();
                common += 1;
            }
        }
        self.before.fill(None);
        for &(point, residual_px) in &self.newest {
            if point >= self.before.len() {
                self.before.resize(point + 1, None);
            }
            self.before[point] = Some(residual_px);
        }
        (common >= FRAME_SAMPLE_MIN_BLOBS).then(|| (change_px2 / 2.0, (2 * common - 6) as f64))
    }
}
