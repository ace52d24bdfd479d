//! The verification of a hypothesis: the static pose from its correspondences, every target point projected with
//! it and matched to the nearest blob, its size checked, and the pose solved again on what was matched.

use nalgebra::{Vector2, Vector3};
use roitrack_core::{CameraModel, MotionState, SpatioTemporalModel, Target};
use roitrack_estimators::{Observation, best_static_pose, static_model_residual};
use std::collections::HashMap;

#[cfg(doc)]
use super::Work;
use super::index::PointIndex;
use super::judgement::{IDENTIFY_NOISE_PX, MODEL_BOUND_SIGMAS, SizeSpread, size_mismatches};

/// A verified hypothesis.
#[derive(Debug, Clone)]
pub(super) struct Verified {
    pub(super) state: MotionState,
    pub(super) pairs: Vec<(usize, usize)>,
    pub(super) residual_px: f64,
    /// The largest residual (RMS px per coordinate) the noise and the model's error explain at this pose: computed
    /// when first asked ([`Verified::accepted`]), since it costs as much as the pose and only the hypotheses
    /// ranked best are ever asked.
    pub(super) residual_bound_px: std::cell::OnceCell<f64>,
    pub(super) visible: usize,
    pub(super) missing: usize,
    pub(super) size_mismatches: usize,
    /// The matched blobs' areas over those the target file's diameters predict (their median; 1 without diameters).
    pub(super) area_scale: f64,
    /// How far the matched blobs' sizes spread about that common scale ([`SizeSpread`]).
    pub(super) size_spread: SizeSpread,
    /// The pose sees the target from its back (+z of the object frame).
    pub(super) from_back: bool,
}

/// A hypothesis's static pose and how well it fits.
#[derive(Clone, Copy)]
pub(super) struct Fitted {
    pub(super) state: MotionState,
    /// RMS reprojection residual (px per coordinate).
    pub(super) residual_px: f64,
    /// The pose sees the target from its back (+z of the object frame).
    from_back: bool,
}

/// A labelling: (point, blob) pairs in the points' order.
type Labelling = Vec<(usize, usize)>;

/// Everything the verification needs, computed once.
pub(super) struct Verifier<'a> {
    pub(super) camera: &'a CameraModel,
    pub(super) target: &'a Target,
    pub(super) model: SpatioTemporalModel,
    pub(super) ideal: &'a [Vector2<f64>],
    pub(super) areas_px: &'a [f64],
    pub(super) index: &'a PointIndex,
    /// For each target point, its nearest other point (for the projected spacing).
    pub(super) nearest_point: &'a [usize],
    pub(super) front_normal: Option<Vector3<f64>>,
    pub(super) centre_m: Vector3<f64>,
    /// Residual bounds computed ([`Work::bounds`]).
    pub(super) bounds: std::cell::Cell<usize>,
    /// The static pose of every labelling verified so far, by its sorted pairs ([`Self::pose_of`]).
    pub(super) poses: std::cell::RefCell<HashMap<Labelling, Option<Fitted>>>,
}

impl Verifier<'_> {
    /// The observations of `pairs`, in the order of their blobs.
    pub(super) fn observations(&self, pairs: &[(usize, usize)]) -> Vec<Observation> {
        let mut by_blob = pairs.to_vec();
        by_blob.sort_unstable_by_key(|&(_, b)| b);
        self.observations_as_listed(&by_blob)
    }

    /// The observations of `pairs` (point index, blob), in their order.
    fn observations_as_listed(&self, pairs: &[(usize, usize)]) -> Vec<Observation> {
        pairs
            .iter()
            .map(|&(point_index, b)| Observation {
                t_s: 0.0,
                point_index,
                ideal_px: self.ideal[b],
            })
            .collect()
    }

    /// The static pose, its residual, and whether it sees the target from its back.
    pub(super) fn pose(
        &self,
        pairs: &[(usize, usize)],
        centres: &[Vector2<f64>],
    ) -> Option<Fitted> {
        let obs: Vec<Observation> = pairs
            .iter()
            .zip(centres)
            .map(|(&(point_index, _), c)| Observation {
                t_s: 0.0,
                point_index,
                ideal_px: *c,
            })
            .collect();
        let fit = best_static_pose(&self.model, self.target, &obs, IDENTIFY_NOISE_PX).ok()?;
        let state = fit.state;
        if state.cam_t_obj_m.z <= 0.0 || !state.cam_t_obj_m.iter().all(|x| x.is_finite()) {
            return None;
        }
        let from_back = self.front_normal.is_some_and(|front| {
            let camera_in_obj = state.cam_r_obj.inverse() * (-state.cam_t_obj_m);
            (camera_in_obj - self.centre_m).dot(&front) <= 0.0
        });
        Some(Fitted {
            state,
            residual_px: fit.residual_rms_px,
            from_back,
        })
    }

    /// The residual (RMS px per coordinate) the noise explains at one chance in a thousand, plus what a model at the
    /// bounds users' files stay within leaves, for the static pose `state` of `pairs`; 0 if a point does not project
    /// (no residual is accepted then).
    pub(super) fn residual_bound_px(&self, pairs: &[(usize, usize)], state: &MotionState) -> f64 {
        self.bounds.set(self.bounds.get() + 1);
        let mut sorted = pairs.to_vec();
        sorted.sort_unstable();
        let obs = self.observations_as_listed(&sorted);
        static_model_residual(&self.model, self.target, &obs, state)
            .map_or(-1.0, |model_residual| {
                model_residual.bound_rms_px(IDENTIFY_NOISE_PX, MODEL_BOUND_SIGMAS)
            })
    }

    /// The static pose of the labelling `sorted` (pairs in order) on the blobs' centres, solved once per labelling: a
    /// small target's search verifies every hypothesis, and most of them, grown by projection and matching, end in
    /// one of a few labellings (a 4 x 4 grid: about 5,000 hypotheses, each solving the pose of its whole labelling
    /// again from every start).
    fn pose_of(&self, sorted: &[(usize, usize)]) -> Option<Fitted> {
        if let Some(fitted) = self.poses.borrow().get(sorted) {
            return *fitted;
        }
        let centres: Vec<Vector2<f64>> = sorted.iter().map(|&(_, b)| self.ideal[b]).collect();
        let fitted = self.pose(sorted, &centres);
        self.poses.borrow_mut().insert(sorted.to_vec(), fitted);
        fitted
    }

    /// Verifies a hypothesis: pose, then every point projected, matched, the pose solved again.
    pub(super) fn verify(&self, pairs: &[(usize, usize)]) -> Option<Verified> {
        let mut current: Vec<(usize, usize)> = pairs.to_vec();
        current.sort_unstable();
        let mut fitted = self.pose_of(&current)?;
        let mut result = None;
        for _ in 0..2 {
            let verified = self.project_and_match(&fitted.state)?;
            // The same correspondences (by point index, as matched): the pose is already theirs, and final.
            let settled = verified.pairs == current;
            if !settled {
                current.clone_from(&verified.pairs);
                fitted = self.pose_of(&current)?;
            }
            result = Some(Verified {
                state: fitted.state,
                residual_px: fitted.residual_px,
                from_back: fitted.from_back,
                ..verified
            });
            if settled {
                break;
            }
        }
        result
    }

    /// Matches every target point the pose projects well inside the image to the nearest unused blob within a
    /// quarter of its projected spacing, checking its size.
    fn project_and_match(&self, state: &MotionState) -> Option<Verified> {
        let points = self.target.points();
        // Each point in the camera frame once: its projection (as `SpatioTemporalModel::project` makes it), depth
        // and direction.
        let in_cam: Vec<Vector3<f64>> = points
            .iter()
            .map(|p| state.point_in_cam_at(&p.point_in_obj_m, 0.0))
            .collect();
        let projected: Vec<Option<(Vector2<f64>, f64)>> = in_cam
            .iter()
            .map(|c| {
                self.model
                    .intrinsics
                    .pixel_from_cam(c)
                    .map(|ideal| (ideal, c.z))
            })
            .collect();
        let focal = self
            .camera
            .intrinsics
            .fx_px
            .max(self.camera.intrinsics.fy_px);
        let front_in_cam = self.front_normal.map(|n| state.cam_r_obj * n);
        let mut used = vec![false; self.ideal.len()];
        let mut pairs = Vec::new();
        // Each matched blob's area over the area its point's diameter predicts at the pose, and what pixel
        // quantisation makes of their logarithms' spread ([`SizeSpread`]).
        let mut area_ratios: Vec<f64> = Vec::new();
        let mut quantisation = 0.0;
        let (mut visible, mut missing) = (0, 0);
        for (i, p) in points.iter().enumerate() {
            let Some((ideal, depth)) = projected[i] else {
                continue;
            };
            let Some((neighbour, _)) = projected[self.nearest_point[i]] else {
                continue;
            };
            let spacing = (neighbour - ideal).norm();
            let radius_px = p.diameter_m.map_or(0.0, |d| 0.5 * focal * d / depth);
            let raw = self.camera.distort_pixel(&ideal);
            let margin = radius_px + 2.0;
            let inside = raw.x >= margin
                && raw.y >= margin
                && raw.x <= f64::from(self.camera.width_px) - 1.0 - margin
                && raw.y <= f64::from(self.camera.height_px) - 1.0 - margin;
            let found = self
                .index
                .nearest(&ideal, (0.25 * spacing).max(1.5), |b| !used[b]);
            match found {
                Some((b, _)) => {
                    if inside {
                        visible += 1;
                    }
                    if let Some(d) = p.diameter_m {
                        // The disk's area foreshortened by its tilt to the line of sight.
                        let normal =
                            front_in_cam.map_or(1.0, |n| n.dot(&in_cam[i].normalize()).abs());
                        let expected =
                            std::f64::consts::FRAC_PI_4 * (focal * d / depth).powi(2) * normal;
                        area_ratios.push(self.areas_px[b] / expected);
                        quantisation += SizeSpread::quantisation(self.areas_px[b]);
                    }
                    used[b] = true;
                    pairs.push((i, b));
                }
                None if inside => {
                    visible += 1;
                    missing += 1;
                }
                None => {}
            }
        }
        let (size_mismatches, area_scale) = size_mismatches(&mut area_ratios);
        let size_spread = SizeSpread::of_sorted(&area_ratios, quantisation);
        (pairs.len() >= 4).then_some(Verified {
            state: *state,
            pairs,
            residual_px: f64::INFINITY,
            residual_bound_px: std::cell::OnceCell::new(),
            visible,
            missing,
            size_mismatches,
            area_scale,
            size_spread,
            from_back: false,
        })
    }
}
