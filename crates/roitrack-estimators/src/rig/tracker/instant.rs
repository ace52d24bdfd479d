//! Covariance matching on the blobs of one camera's instant (a global-shutter frame's): the pose fitted to the
//! whole frame, the fused covariance widened to meet it when the prediction was too confident.

use std::cmp::Reverse;

use nalgebra::{Matrix6, Vector2, Vector3, Vector6};
use roitrack_core::stats::chi2_upper_0_1_percent;
use roitrack_core::{Measurement, MotionState, SpatioTemporalModel, Vector12};

use super::{Pending, RigTracker};
use crate::kalman::pose_matching_scale;
use crate::rig::{CameraMount, ClockModel, rig_projection};

/// Gauss-Newton steps of an instant's pose fit ([`RigTracker::match_instant`]): from a prediction millimetres off,
/// the third step moves the pose by nanometres.
const POSE_FIT_ITERATIONS: usize = 4;

impl RigTracker {
    /// Covariance matching on the blobs of one camera's instant (a global-shutter frame's), before the first of them
    /// is fused; returns whether it took them all. A fast target seen at frame rates strays from a constant-twist
    /// prediction by more than its covariance allows (9 mm in 1/30 s at 17 m/s²), and blob after blob would be
    /// rejected by the gate until the track is lost. As the single-camera filter does with a frame: the blobs' fit
    /// of the pose alone (Gauss-Newton from the prediction) moves it by `x` with covariance
    /// `C = (Σ Jᵢᵀ Jᵢ / σ²)⁻¹`; if the prediction is right, `xᵀ (P_pose + C)⁻¹ x` is a chi-square of 6 degrees of
    /// freedom. Within its 99.9 % point, nothing is done and the blobs are fused one by one. Beyond it, the pose and
    /// twist block of the covariance is scaled by the `α` that makes it its expected 6 (the clocks' variances kept,
    /// their cross-covariances scaled by `√α`, which keeps the covariance positive), and the fitted pose is taken
    /// as one measurement of the pose with covariance `C`: one update, linearised where the fit converged, instead
    /// of blob-by-blob updates from a prediction millimetres off, which a widened covariance lets run away.
    pub(super) fn match_instant(&mut self, first: &Pending) -> bool {
        let c = first.camera;
        let same_instant = |p: &Pending| p.camera == c && p.t_rig_s == first.t_rig_s;
        let blobs: Vec<Measurement> = std::iter::once(first.measurement)
            .chain(
                self.pending
                    .iter()
                    .map(|Reverse(p)| p)
                    .filter(|p| same_instant(p))
                    .map(|p| p.measurement),
            )
            .collect();
        // A pose of 6 degrees of freedom from 2 coordinates per blob: fewer than 4 blobs leave its fit too weak to
        // test.
        if blobs.len() < 4 {
            return false;
        }
        let camera = &self.rig.cameras()[c];
        let clock = self.clocks[c];
        let noise2 = self.noise_px[c] * self.noise_px[c];
        let tuning = self.tuning;
        let Some(f) = self.fused.as_mut() else {
            return false;
        };
        let dt = clock.rig_time_s(first.measurement.t_s) - f.t_s;
        if dt <= 0.0 || noise2 <= 0.0 {
            return false;
        }
        f.predict(dt, &tuning);
        let points: Vec<(Vector3<f64>, Vector2<f64>, f64)> = blobs
            .iter()
            .filter_map(|m| {
                let index = self.target.index_of(m.id)?;
                let ideal_px = camera
                    .camera
                    .undistort_pixel(&Vector2::new(m.u_px, m.v_px))
                    .ok()?;
                Some((self.target.points()[index].point_in_obj_m, ideal_px, m.t_s))
            })
            .collect();
        let instant = InstantView {
            model: &self.models[c],
            mount: &camera.mount,
            clock: &clock,
            t_ref_s: f.t_s,
            noise2_px2: noise2,
        };
        let Some(PoseFit {
            x,
            covariance: fit_covariance,
            sum_squares_px2,
        }) = instant.fit_pose(&f.state, &points)
        else {
            return false;
        };
        let pose = f.p.fixed_view::<6, 6>(0, 0).into_owned();
        let Some(alpha) =
            pose_matching_scale(&pose, &fit_covariance, &x, chi2_upper_0_1_percent(6.0))
        else {
            return false;
        };
        let root = alpha.sqrt();
        let n = f.p.nrows();
        for j in 0..n {
            for i in 0..n {
                let scale = if i < 12 { root } else { 1.0 } * if j < 12 { root } else { 1.0 };
                f.p[(i, j)] *= scale;
            }
        }
        // The fitted pose as one measurement of the pose: K = P Hᵀ (H P Hᵀ + C)⁻¹ with H = [I₆ 0], P ← P - K H P.
        let p_h_t = f.p.columns(0, 6).into_owned();
        let innovation_covariance = f.p.fixed_view::<6, 6>(0, 0).into_owned() + fit_covariance;
        let Some(s_inv) = innovation_covariance.try_inverse() else {
            return false;
        };
        let gain = &p_h_t * s_inv;
        let correction = &gain * x;
        let delta = Vector12::from_fn(|i, _| correction[i]);
        let corrected = f.state.corrected(&delta);
        if !corrected.is_finite() {
            return false;
        }
        f.state = corrected;
        let (offset_index, drift_index) = self.clock_states[c];
        if let Some(i) = offset_index {
            self.clocks[c].offset_s += correction[i];
        }
        if let Some(j) = drift_index {
            self.clocks[c].drift_ppm += correction[j];
        }
        f.p -= &gain * p_h_t.transpose();
        // Symmetric again after the downdate's rounding.
        let symmetric = (&f.p + f.p.transpose()) * 0.5;
        f.p = symmetric;
        let taken = blobs.len();
        f.count += taken;
        f.sum_squares_px2 += sum_squares_px2;
        f.gated_in_a_row = 0;
        f.newest_gated = false;
        self.pending.retain(|Reverse(p)| !same_instant(p));
        self.report.fused += taken;
        self.report.instants_widened += 1;
        self.camera_counts[c].fused += taken;
        self.camera_counts[c].gated_in_a_row = 0;
        self.since_estimate += taken;
        true
    }
}

/// One camera's view of an instant, for the pose fit: its projection, mount and clock, the fused filter's time and
/// the camera's centroid variance (px²).
struct InstantView<'a> {
    model: &'a SpatioTemporalModel,
    mount: &'a CameraMount,
    clock: &'a ClockModel,
    t_ref_s: f64,
    noise2_px2: f64,
}

/// The pose alone fitted to an instant's blobs ([`InstantView::fit_pose`]).
struct PoseFit {
    /// The fit's move of the pose from the prediction (the sum of its steps, each a correction on the left).
    x: Vector6<f64>,
    /// Its covariance, `(Σ Jᵢᵀ Jᵢ / σ²)⁻¹`.
    covariance: Matrix6<f64>,
    /// The blobs' squared residuals at the last linearisation (px²).
    sum_squares_px2: f64,
}

impl InstantView<'_> {
    /// The pose alone fitted to `points` (model point, ideal pixel, camera time) from `predicted`: a few
    /// Gauss-Newton steps, each a correction on the left as the filter's. `None` if the fit is singular or runs away.
    fn fit_pose(
        &self,
        predicted: &MotionState,
        points: &[(Vector3<f64>, Vector2<f64>, f64)],
    ) -> Option<PoseFit> {
        let mut fitted = *predicted;
        let mut x = Vector6::zeros();
        let mut fit_covariance = Matrix6::zeros();
        // The blobs' squared residuals at the last linearisation, for the estimate's residual RMS as blob-by-blob
        // updates add theirs.
        let mut sum_squares_px2 = 0.0;
        for _ in 0..POSE_FIT_ITERATIONS {
            let (mut information, mut gradient) = (Matrix6::zeros(), Vector6::zeros());
            sum_squares_px2 = 0.0;
            for (point, ideal_px, t_s) in points {
                let Some(projected) = rig_projection(
                    self.model,
                    self.mount,
                    self.clock,
                    &fitted,
                    point,
                    *t_s,
                    self.t_ref_s,
                ) else {
                    continue;
                };
                let j = projected.jacobian.fixed_view::<2, 6>(0, 0).into_owned();
                let residual_px = ideal_px - projected.pixel;
                sum_squares_px2 += residual_px.norm_squared();
                information += j.transpose() * j / self.noise2_px2;
                gradient += j.transpose() * residual_px / self.noise2_px2;
            }
            let covariance = information.try_inverse()?;
            let step = covariance * gradient;
            let mut delta = Vector12::zeros();
            delta.fixed_rows_mut::<6>(0).copy_from(&step);
            fitted = fitted.corrected(&delta);
            x += step;
            fit_covariance = covariance;
            if !x.iter().all(|v| v.is_finite()) {
                return None;
            }
        }
        Some(PoseFit {
            x,
            covariance: fit_covariance,
            sum_squares_px2,
        })
    }
}
