//! ROI scheduling: which point to read next, and where and how large its ROI must be.
//!
//! Each ROI is centred on the point's predicted raw pixel at the ROI's exposure midpoint, using the latest estimate
//! (pose and twist) carried forward to that time. Its size is the predicted blob diameter, plus the blob's motion
//! during the exposure (the camera's time model), plus the optical blur, plus `sigma_margin` standard deviations of the prediction's image
//! uncertainty (the state covariance pushed through the exact 2 x 12 Jacobian at the exposure time), clamped to
//! `[min_size_px, max_size_px]` and to the sensor.

use nalgebra::{Matrix2, SMatrix, Vector2};
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_core::{CameraModel, JacobianKind, MotionState, SpatioTemporalModel, Target};
use roitrack_estimators::Matrix12;
use roitrack_image::Roi;

/// What the estimation side tells the camera side: the latest estimate, from which ROIs are placed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Predictor {
    /// Reference time of `state` (s).
    pub t_ref_s: f64,
    /// The estimated pose of the target in the camera frame and its twist at `t_ref_s`, carried by the twist to
    /// each ROI's exposure.
    pub state: MotionState,
    /// Covariance of the error state (v, w, dV, dW), if the estimator has one.
    pub covariance: Option<Matrix12>,
}

/// The order in which points are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ScheduleOrder {
    /// Bit-reversed cycle (docs/model.md), the default.
    #[default]
    BitReversed,
    /// 0, 1, ..., n-1 (degenerate windows on planar grids: for tests and comparison).
    RowMajor,
    /// The point whose measurement brings the most information about the state: the largest
    /// `log det(I + H P Hᵀ / σ²)` under the predictor's covariance, updated locally after each scheduled ROI so that
    /// one point is not read again and again between two estimates. Falls back to bit-reversed without a covariance.
    Active,
}

/// Options of the scheduler.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SchedulerConfig {
    /// The order in which the points are read.
    pub order: ScheduleOrder,
    /// Smallest ROI side (px): a smaller computed size is raised to it.
    pub min_size_px: u32,
    /// Largest ROI side (px): a larger computed size is cut to it. The real-time loop and the frame tracker take at
    /// most 64 ([`roitrack_image::MAX_ROI_WIDTH`]).
    pub max_size_px: u32,
    /// Standard deviations of the predicted image position added on each side.
    pub sigma_margin: f64,
    /// Extra margin on each side for the optical blur and the blob's edge (px).
    pub blur_margin_px: f64,
    /// Consecutive misses after which a point counts as lost.
    pub misses_for_lost: u32,
    /// Lost points at which the camera side re-initialises from a full frame.
    pub lost_points_for_reinit: usize,
    /// Default blob diameter (m) when the target file gives none.
    pub default_diameter_m: f64,
    /// Image uncertainty (px, 1 sigma) assumed when the estimator gives no covariance.
    pub fallback_sigma_px: f64,
    /// Smallest image uncertainty (px, 1 sigma) used for sizing: the covariance of a well-converged filter does not
    /// cover what its motion model leaves out (a jerk), nor the error of the blob-centre model.
    pub min_sigma_px: f64,
}

impl Default for SchedulerConfig {
    fn default() -> Self {
        Self {
            order: ScheduleOrder::BitReversed,
            min_size_px: 12,
            max_size_px: 64,
            sigma_margin: 4.0,
            blur_margin_px: 3.0,
            misses_for_lost: 2,
            lost_points_for_reinit: 4,
            default_diameter_m: 0.006,
            fallback_sigma_px: 2.0,
            min_sigma_px: 1.0,
        }
    }
}

/// One scheduled ROI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoiRequest {
    /// The point to read: its index in the target's points (not its id).
    pub point_index: usize,
    /// The square ROI to read (px): centred on `predicted_px` to the nearest pixel, moved as little as needed to lie
    /// on the sensor.
    pub roi: Roi,
    /// Predicted raw pixel of the blob centre.
    pub predicted_px: Vector2<f64>,
    /// Predicted 1-sigma image uncertainty (px, largest axis), if known.
    pub sigma_px: Option<f64>,
}

/// Places ROIs. Built once; `next` does not allocate.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_pipeline::scheduler::{Predictor, RoiScheduler, SchedulerConfig};
///
/// let mut scheduler =
///     RoiScheduler::new(CameraModel::canonical(), Target::grid4x4(), SchedulerConfig::default(), 0.1);
/// let state = MotionState::at_rest(Rotation3::identity(), Vector3::new(0.0, 0.0, 0.6));
/// let predictor = Predictor { t_ref_s: 0.0, state, covariance: None };
/// let request = scheduler.next(&predictor, 1e-3).unwrap();
/// assert_eq!(request.roi.width, request.roi.height);
/// assert!((12..=64).contains(&request.roi.width) && request.sigma_px.is_none());
/// // Two misses in a row lose a point; four lost points ask for a full frame.
/// for i in 0..4 {
///     scheduler.report(i, false);
///     scheduler.report(i, false);
/// }
/// assert!(scheduler.needs_reinitialisation());
/// ```
#[derive(Debug, Clone)]
pub struct RoiScheduler {
    camera: CameraModel,
    target: Target,
    model: SpatioTemporalModel,
    config: SchedulerConfig,
    /// Centroid noise (px): the information gain of the active order weighs the prediction's spread against it.
    noise_px: f64,
    cycle: Vec<usize>,
    slot: usize,
    misses: Vec<u32>,
    /// The predictor's covariance, updated locally by each scheduled ROI (active order).
    local_covariance: Option<(f64, Matrix12)>,
}

impl RoiScheduler {
    /// A scheduler for `camera` and `target`; `noise_px` is the centroid noise the estimator assumes (that of its
    /// [`roitrack_estimators::TrackerConfig`]), which the active order weighs the prediction's spread against.
    pub fn new(
        camera: CameraModel,
        target: Target,
        config: SchedulerConfig,
        noise_px: f64,
    ) -> Self {
        let n = target.len();
        let cycle = match config.order {
            ScheduleOrder::RowMajor => (0..n).collect(),
            _ => bit_reversed_indices(n),
        };
        Self {
            model: SpatioTemporalModel::new(camera.intrinsics),
            camera,
            misses: vec![0; n],
            target,
            config,
            noise_px,
            cycle,
            slot: 0,
            local_covariance: None,
        }
    }

    /// The options it was built with.
    pub fn config(&self) -> &SchedulerConfig {
        &self.config
    }

    /// Forgets the lost-point bookkeeping (after a re-initialisation).
    pub fn reset(&mut self) {
        self.misses.iter_mut().for_each(|m| *m = 0);
        self.local_covariance = None;
    }

    /// Records whether the blob of `point_index` was found in its ROI.
    pub fn report(&mut self, point_index: usize, found: bool) {
        let m = &mut self.misses[point_index];
        *m = if found { 0 } else { m.saturating_add(1) };
    }

    /// Number of points currently lost.
    pub fn lost_points(&self) -> usize {
        self.misses
            .iter()
            .filter(|&&m| m >= self.config.misses_for_lost)
            .count()
    }

    /// Too many points lost: re-initialise from a full frame.
    pub fn needs_reinitialisation(&self) -> bool {
        self.lost_points() >= self.config.lost_points_for_reinit
    }

    /// The next ROI, exposed at `t_mid_s`; `None` if no point projects onto the sensor.
    pub fn next(&mut self, predictor: &Predictor, t_mid_s: f64) -> Option<RoiRequest> {
        let n = self.target.len();
        let d_s = t_mid_s - predictor.t_ref_s;
        if self.config.order == ScheduleOrder::Active
            && let Some(covariance) = predictor.covariance
        {
            // A new predictor replaces the local covariance.
            if self
                .local_covariance
                .is_none_or(|(t, _)| t != predictor.t_ref_s)
            {
                self.local_covariance = Some((predictor.t_ref_s, covariance));
            }
            let (_, p) = self.local_covariance?;
            let mut best: Option<(usize, f64)> = None;
            for i in 0..n {
                let Some(h) = self.jacobian(predictor, i, d_s) else {
                    continue;
                };
                let s = h * p * h.transpose() / (self.noise_px * self.noise_px);
                let gain = (Matrix2::identity() + s).determinant().ln();
                // A lost point still gets tried now and then: its gain keeps growing as the state drifts.
                let gain = gain / (1.0 + self.misses[i] as f64);
                if best.is_none_or(|(_, g)| gain > g) {
                    best = Some((i, gain));
                }
            }
            let (i, _) = best?;
            if let Some(h) = self.jacobian(predictor, i, d_s) {
                let sigma2 = self.noise_px * self.noise_px;
                let ph_t: SMatrix<f64, 12, 2> = p * h.transpose();
                let s = h * ph_t + Matrix2::identity() * sigma2;
                if let Some(s_inv) = s.try_inverse() {
                    let updated = p - ph_t * s_inv * ph_t.transpose();
                    self.local_covariance = Some((predictor.t_ref_s, updated));
                }
            }
            return self.request(predictor, i, t_mid_s);
        }
        for _ in 0..n {
            let i = self.cycle[self.slot];
            self.slot = (self.slot + 1) % n;
            if let Some(request) = self.request(predictor, i, t_mid_s) {
                return Some(request);
            }
        }
        None
    }

    fn jacobian(&self, predictor: &Predictor, i: usize, d_s: f64) -> Option<SMatrix<f64, 2, 12>> {
        let p = &self.target.points()[i].point_in_obj_m;
        self.model
            .project_with_jacobian(JacobianKind::Exact, &predictor.state, p, d_s)
            .map(|pp| pp.jacobian)
    }

    /// The ROI of point `i` at `t_mid_s`.
    pub fn request(&self, predictor: &Predictor, i: usize, t_mid_s: f64) -> Option<RoiRequest> {
        let point = &self.target.points()[i];
        let d_s = t_mid_s - predictor.t_ref_s;
        let projected = self.model.project_with_jacobian(
            JacobianKind::Exact,
            &predictor.state,
            &point.point_in_obj_m,
            d_s,
        )?;
        let predicted_px = self.camera.distort_pixel(&projected.pixel);
        let diameter_px = self.camera.intrinsics.fx_px
            * point.diameter_m.unwrap_or(self.config.default_diameter_m)
            / projected.point_in_cam_m.z;
        // Image motion over the exposure (the camera's), from the twist.
        let (start_s, end_s) = self.camera.time.exposure_interval_s(d_s);
        let smear_px = match (
            self.model
                .project(&predictor.state, &point.point_in_obj_m, start_s),
            self.model
                .project(&predictor.state, &point.point_in_obj_m, end_s),
        ) {
            (Some(a), Some(b)) => (b - a).norm(),
            _ => 0.0,
        };
        let sigma_px = predictor.covariance.map(|p| {
            let s = projected.jacobian * p * projected.jacobian.transpose();
            s.symmetric_eigenvalues().max().max(0.0).sqrt()
        });
        let size = diameter_px
            + smear_px
            + 2.0 * self.config.blur_margin_px
            + 2.0
                * self.config.sigma_margin
                * sigma_px
                    .unwrap_or(self.config.fallback_sigma_px)
                    .max(self.config.min_sigma_px);
        let size = (size.ceil() as u32).clamp(self.config.min_size_px, self.config.max_size_px);
        if !self.camera.contains_raw_pixel(&predicted_px) {
            return None;
        }
        let roi = Roi::centred(
            predicted_px.x,
            predicted_px.y,
            size,
            self.camera.width_px,
            self.camera.height_px,
        )?;
        Some(RoiRequest {
            point_index: i,
            roi,
            predicted_px,
            sigma_px,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    fn predictor(covariance: Option<Matrix12>) -> Predictor {
        Predictor {
            t_ref_s: 0.0,
            state: MotionState {
                cam_r_obj: Rotation3::from_euler_angles(0.17, -0.26, 0.09),
                cam_t_obj_m: Vector3::new(0.02, -0.01, 0.6),
                velocity_mps: Vector3::new(1.0, 0.0, 0.0),
                angular_velocity_radps: Vector3::zeros(),
            },
            covariance,
        }
    }

    #[test]
    fn roi_is_centred_on_the_prediction_at_its_exposure_time() {
        let camera = CameraModel::canonical();
        let mut s = RoiScheduler::new(
            camera.clone(),
            Target::grid4x4(),
            SchedulerConfig::default(),
            0.1,
        );
        let p = predictor(None);
        let r = s.next(&p, 0.004).unwrap();
        assert_eq!(r.point_index, 0);
        let truth = p
            .state
            .point_in_cam_at(&Target::grid4x4().points()[0].point_in_obj_m, 0.004);
        let px = camera.raw_pixel_from_cam(&truth).unwrap();
        assert!((r.predicted_px - px).norm() < 1e-9);
        let centre = Vector2::new(
            r.roi.x0 as f64 + (r.roi.width as f64 - 1.0) / 2.0,
            r.roi.y0 as f64 + (r.roi.height as f64 - 1.0) / 2.0,
        );
        assert!((centre - px).norm() < 1.0);
        // The 9 mm key blob is about 22 px across at 0.6 m: the ROI holds it with margins.
        // 22 px of key blob + blur margins + 4 sigma of the 1 px minimum uncertainty on each side.
        assert!(r.roi.width >= 28 && r.roi.width <= 48, "{:?}", r.roi);
        // Then the bit-reversed order.
        let ids: Vec<usize> = (0..4)
            .map(|_| s.next(&p, 0.004).unwrap().point_index)
            .collect();
        assert_eq!(ids, vec![8, 4, 12, 2]);
    }

    #[test]
    fn uncertainty_grows_the_roi_and_lost_points_trigger_reinit() {
        let mut s = RoiScheduler::new(
            CameraModel::canonical(),
            Target::grid4x4(),
            SchedulerConfig::default(),
            0.1,
        );
        let small = s.request(&predictor(None), 5, 0.0).unwrap().roi.width;
        let cov = Matrix12::identity() * 1e-6; // 1 mm, 1 mrad, 1 mm/s
        let large = s.request(&predictor(Some(cov)), 5, 0.0).unwrap().roi.width;
        assert!(large > small, "{large} vs {small}");
        for i in 0..4 {
            s.report(i, false);
            s.report(i, false);
        }
        assert!(s.needs_reinitialisation());
        s.reset();
        assert!(!s.needs_reinitialisation());
    }

    #[test]
    fn active_order_spreads_over_the_points() {
        let config = SchedulerConfig {
            order: ScheduleOrder::Active,
            ..Default::default()
        };
        let mut s = RoiScheduler::new(CameraModel::canonical(), Target::grid4x4(), config, 0.1);
        let p = predictor(Some(Matrix12::identity() * 1e-6));
        let chosen: Vec<usize> = (0..16)
            .map(|k| s.next(&p, k as f64 * 250e-6).unwrap().point_index)
            .collect();
        // Local covariance updates make it alternate between points rather than read one again and again. Under an
        // isotropic prior the corners of the grid carry the most information: it picks them.
        assert!(chosen.windows(2).all(|w| w[0] != w[1]), "{chosen:?}");
        let mut distinct = chosen.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert!(distinct.len() >= 4, "{chosen:?}");
    }
}
