//! The centre of a blob measured in its window, made of two: its moments and its outline, weighted by how well each
//! kind fits static poses of the frames ([`CentreBlend`]).

use roitrack_core::{Measurement, SpatioTemporalModel};
use roitrack_estimators::{Observation, refine_static_pose};

use super::FrameTracker;
use crate::scheduler::Predictor;

#[cfg(doc)]
use roitrack_image::photo::outline_centre;

/// Gauss-Newton steps of the static poses that compare the two kinds of centres (from the predicted pose).
const CENTRE_FIT_ITERATIONS: usize = 4;
/// Frames compared before the weights follow the comparison (equal weights until then), and the memory of the
/// comparison (frames).
const CENTRE_BLEND_MIN_FRAMES: usize = 5;
const CENTRE_BLEND_MEMORY_FRAMES: f64 = 20.0;
/// After the first [`CENTRE_BLEND_MEMORY_FRAMES`] frames, the two kinds are compared on one frame in this many (the
/// two static fits cost a tenth of a frame's work).
const CENTRE_BLEND_EVERY_FRAMES: usize = 5;

/// How the centre of a blob measured in its window is made of two: the window's threshold-weighted moments and the
/// centre of the blob's outline ([`outline_centre`], the full-frame detector's). Neither is better everywhere. On sharp
/// blobs under sensor noise and JPEG compression the outline's points average the noise over the whole edge, while the
/// moments move with the pixels near their threshold, and the outline is the closer to the true centre; on the soft
/// blobs of `roitrack simulate --frames`, the moments are the better. Their errors are far from equal, so their
/// weighted mean beats both: each is weighted by the inverse of its mean squared residual in static poses fitted to
/// each frame's centres of that kind, in an exponential average with a memory of [`CENTRE_BLEND_MEMORY_FRAMES`]
/// compared frames. Both kinds are fitted on the same blobs at the same poses, so what differs is mostly the centres'
/// own noise (the two come from the same pixels, and their errors are not independent: the weights are those of
/// independent errors, which is what the measurements bear out, not an optimum). With the mean, the clutter's frames
/// are measured as closely as by the detector and the simulated sequences jitter less than with either kind alone
/// (measured in docs/frames.md, step 1, and docs/results.md, "Design measurements behind the code").
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct CentreBlend {
    /// The averaged mean squared residuals (px²): by the moments, by the outlines.
    mean_rms2_px2: [f64; 2],
    /// Frames compared, and frames whose windows gave their centres.
    compared: usize,
    offered: usize,
}

impl CentreBlend {
    /// Whether this frame, whose windows gave their centres, compares the two kinds (counts the frame).
    fn compares_now(&mut self) -> bool {
        self.offered += 1;
        self.offered as f64 <= CENTRE_BLEND_MEMORY_FRAMES
            || self.offered.is_multiple_of(CENTRE_BLEND_EVERY_FRAMES)
    }

    /// Folds in one frame's mean squared residuals (px²): by the moments, by the outlines.
    fn add(&mut self, rms2_px2: [f64; 2]) {
        self.compared += 1;
        let weight = 1.0 / (self.compared as f64).min(CENTRE_BLEND_MEMORY_FRAMES);
        for (mean, sample) in self.mean_rms2_px2.iter_mut().zip(rms2_px2) {
            *mean += weight * (sample - *mean);
        }
    }

    /// The outline's weight in a blob's centre (the moments' is 1 minus it).
    fn outline_weight(&self) -> f64 {
        let [moments, outline] = self.mean_rms2_px2;
        if self.compared < CENTRE_BLEND_MIN_FRAMES || moments + outline <= 0.0 {
            return 0.5;
        }
        moments / (moments + outline)
    }
}

impl FrameTracker {
    /// The frame's window centres into `self.measurements`: the mean of their outlines' and their moments' centres,
    /// weighted by [`CentreBlend`] (after comparing them on this frame, if it is one it compares).
    pub(super) fn take_window_centres(&mut self, predictor: &Predictor) {
        if self.windows.blend.compares_now()
            && let Some(rms2) = self.static_fit_rms2_px2(predictor)
        {
            self.windows.blend.add(rms2);
        }
        let weight = self.windows.blend.outline_weight();
        self.report.outline_weight = weight;
        for w in &self.windows.centres {
            let centre = w.moments_px + weight * (w.outline_px - w.moments_px);
            self.measurements.push(Measurement {
                t_s: w.t_s,
                id: self.target.points()[w.point_index].id,
                u_px: centre.x,
                v_px: centre.y,
            });
        }
    }

    /// The mean squared residuals (px²) of the static poses fitted to the frame's window centres by their moments and
    /// by their outlines, each centre first moved along the predicted motion to the centres' mean time (a rolling
    /// shutter reads them at different times); `None` when the outlines changed no centre or the centres do not
    /// determine a pose.
    fn static_fit_rms2_px2(&mut self, predictor: &Predictor) -> Option<[f64; 2]> {
        let required = if self.target.is_planar() { 4 } else { 6 };
        if self.windows.centres.len() < required
            || self
                .windows
                .centres
                .iter()
                .all(|w| w.outline_px == w.moments_px)
        {
            return None;
        }
        let count = self.windows.centres.len() as f64;
        let mean_s = self.windows.centres.iter().map(|w| w.t_s).sum::<f64>() / count;
        let at_mean = predictor.state.predicted(mean_s - predictor.t_ref_s);
        let model = SpatioTemporalModel::new(self.camera.intrinsics);
        let mut rms2 = [0.0; 2];
        for (k, rms2) in rms2.iter_mut().enumerate() {
            self.windows.fit_observations.clear();
            for w in &self.windows.centres {
                let p = &self.target.points()[w.point_index].point_in_obj_m;
                let at_blob = predictor.state.predicted(w.t_s - predictor.t_ref_s);
                let moved = model.project(&at_mean, p, 0.0)? - model.project(&at_blob, p, 0.0)?;
                let raw = if k == 0 { w.moments_px } else { w.outline_px };
                let ideal = self.camera.undistort_pixel(&raw).ok()?;
                self.windows.fit_observations.push(Observation {
                    t_s: mean_s,
                    point_index: w.point_index,
                    ideal_px: ideal + moved,
                });
            }
            let fit = refine_static_pose(
                &model,
                &self.target,
                &self.windows.fit_observations,
                &at_mean,
                CENTRE_FIT_ITERATIONS,
            );
            *rms2 = fit.residual_rms_px * fit.residual_rms_px;
        }
        rms2.iter().all(|r| r.is_finite()).then_some(rms2)
    }
}
