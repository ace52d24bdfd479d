//! The whole-frame search: the target found and identified in the whole frame with no prior ([`detect_target`]), or,
//! when it cannot be identified, the frame's blobs matched to the running track's predicted points.

use nalgebra::Vector2;
use roitrack_core::target::Symmetry;
use roitrack_core::{Measurement, MotionState};
use roitrack_estimators::Estimator;
use roitrack_image::{Frame, PhotoBlobOptions, PhotoScratch, Polarity, detect_photo_blobs};

use super::{FrameError, FrameMethod, FrameTracker};
use crate::scheduler::Predictor;
use roitrack_detect::photo::{PolarityChoice, detect_target};

/// The whole-frame search's settings and buffers, the polarity it decided, and the target's symmetric twins.
#[derive(Debug)]
pub(super) struct WholeFrameSearch {
    pub(super) blob_options: PhotoBlobOptions,
    pub(super) scratch: PhotoScratch,
    /// The polarity in use: the configured one, or the first identified frame's.
    pub(super) polarity: Option<Polarity>,
    /// The target's symmetries that identification cannot tell apart, each with the point it takes every point to
    /// (by index): the labellings of a whole-frame detection that fit as well as the one it gives.
    pub(super) twins: Vec<(Symmetry, Vec<usize>)>,
}

impl FrameTracker {
    /// Searches the whole frame; fills `self.measurements` and says whether the track goes on, restarts, or the target
    /// was not found, with the target's static pose when it was identified. The target identified whole comes first:
    /// blobs matched to the running track's predictions are only as right as those predictions, and a grid that moved
    /// by one spacing more than predicted matches its neighbours, giving an estimate that agrees with its blobs yet is
    /// far off (docs/frames.md, step 2). Identified blobs continue a running track (whose estimate [`Self::process`]
    /// then checks against the frame); matching is for frames where the target cannot be identified whole (part of it
    /// hidden or out of the image).
    pub(super) fn search_whole_frame(
        &mut self,
        frame: &Frame,
    ) -> Result<(FrameMethod, Option<MotionState>), FrameError> {
        self.measurements.clear();
        let running = self.memory.predictor.is_some() && self.tracker.state().is_some();
        if let Some(found) = self.find_whole(frame) {
            self.windows.scheduler.reset();
            if running {
                return Ok((FrameMethod::FullFrame, Some(found)));
            }
            self.restart(frame.t_s, found)?;
            return Ok((FrameMethod::Restart, Some(found)));
        }
        if let (true, Some(predictor), Some(polarity)) =
            (running, self.memory.predictor, self.search.polarity)
            && self.associate_blobs(frame, &predictor, polarity) >= self.min_window_points()
        {
            self.windows.scheduler.reset();
            return Ok((FrameMethod::FullFrame, None));
        }
        self.measurements.clear();
        Ok((FrameMethod::NotFound, None))
    }

    /// Finds and identifies the target in the whole frame: its blobs into `self.measurements` (each at its row's
    /// time), and its static pose; `None` if it is not there.
    pub(super) fn find_whole(&mut self, frame: &Frame) -> Option<MotionState> {
        let mut options = self.config.detection;
        if let Some(polarity) = self.search.polarity {
            options.polarity = match polarity {
                Polarity::Bright => PolarityChoice::Bright,
                Polarity::Dark => PolarityChoice::Dark,
            };
        }
        let detection = detect_target(&self.camera, &self.target, frame, &options).ok()?;
        if self.search.polarity.is_none() {
            self.search.polarity = Some(detection.polarity);
            self.report.polarity = Some(detection.polarity);
        }
        let time = self.camera.time;
        let (state, twin) = self.nearest_twin(frame.t_s, detection.state);
        let target = &self.target;
        let relabel = |id: u32| match (twin, target.index_of(id)) {
            (Some(k), Some(i)) => target.points()[self.search.twins[k].1[i]].id,
            _ => id,
        };
        self.measurements
            .extend(detection.points.iter().map(|p| Measurement {
                t_s: time.blob_time_s(frame.t_s, p.centre_px.y),
                id: relabel(p.id),
                u_px: p.centre_px.x,
                v_px: p.centre_px.y,
            }));
        Some(state)
    }

    /// The frame's blobs attributed to the running track's points: each point takes the blob nearest its prediction
    /// when that blob has no other point nearer, within half the distance between predicted points (so that no blob
    /// can be given to two points however far the target strayed from the prediction). For frames whose blobs left
    /// their windows (a sudden acceleration); returns how many points were measured (in `self.measurements`).
    pub(super) fn associate_blobs(
        &mut self,
        frame: &Frame,
        predictor: &Predictor,
        polarity: Polarity,
    ) -> usize {
        let blobs = detect_photo_blobs(
            &frame.pixels,
            frame.width,
            frame.height,
            frame.bit_depth,
            polarity,
            &self.search.blob_options,
            &mut self.search.scratch,
        );
        let predicted: Vec<(usize, Vector2<f64>)> = (0..self.target.len())
            .filter_map(|i| {
                self.request_at_row_time(predictor, i, frame.t_s)
                    .map(|r| (i, r.predicted_px))
            })
            .collect();
        let mut spacing_px = f64::INFINITY;
        for (a, (_, pa)) in predicted.iter().enumerate() {
            for (_, pb) in &predicted[a + 1..] {
                spacing_px = spacing_px.min((pa - pb).norm());
            }
        }
        let gate_px = 0.5 * spacing_px;
        let nearest = |p: &Vector2<f64>, candidates: &mut dyn Iterator<Item = Vector2<f64>>| {
            candidates
                .enumerate()
                .map(|(k, c)| (k, (c - p).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
        };
        let time = self.camera.time;
        for &(i, p) in &predicted {
            let Some((b, distance)) =
                nearest(&p, &mut blobs.iter().map(|b| Vector2::new(b.u_px, b.v_px)))
            else {
                continue;
            };
            let blob = Vector2::new(blobs[b].u_px, blobs[b].v_px);
            let mutual = nearest(&blob, &mut predicted.iter().map(|(_, q)| *q))
                .is_some_and(|(k, _)| predicted[k].0 == i);
            if distance < gate_px && mutual {
                let t_s = time.blob_time_s(frame.t_s, blob.y);
                let centre = blob - self.disk_centre_shift_px(predictor, i, t_s);
                self.measurements.push(Measurement {
                    t_s,
                    id: self.target.points()[i].id,
                    u_px: centre.x,
                    v_px: centre.y,
                });
            }
        }
        self.measurements.len()
    }
}
