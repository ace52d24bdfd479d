//! The window path: each target point's blob predicted from the last estimate at the time its row is read, and
//! measured in a window there ([`roitrack_image::window`]), the ROI path of the paper.

use std::cell::RefCell;

use nalgebra::{Vector2, Vector3};
use rayon::prelude::*;
use roitrack_core::Acceleration;
use roitrack_estimators::Observation;
use roitrack_image::photo::OutlineScratch;
use roitrack_image::window::{flatten_window, measure_flat_window, window_outline_centre};
use roitrack_image::{BlobRejection, CentroidOptions, Frame, Polarity};

use super::FrameTracker;
use super::centre_blend::CentreBlend;
use crate::scheduler::{Predictor, RoiRequest, RoiScheduler};
use roitrack_core::projection::disk_centre_displacement_px;

/// The window path's state: the scheduler that sizes each window, and the buffers a frame's windows reuse.
#[derive(Debug)]
pub(super) struct Windows {
    pub(super) scheduler: RoiScheduler,
    /// Each point's window in the frame being measured.
    pub(super) requests: Vec<Option<RoiRequest>>,
    /// The windows' predicted centres by their column, to find those near a blob; `None` when a prediction is not
    /// finite (every window is then compared).
    pub(super) by_column: Option<Vec<(f64, usize)>>,
    /// What each point's window gave (`None` for a point without a window).
    pub(super) outcomes: Vec<Option<WindowOutcome>>,
    /// The frame's window centres of both kinds, their weights, and the static fits' observations.
    pub(super) centres: Vec<WindowCentres>,
    pub(super) blend: CentreBlend,
    pub(super) fit_observations: Vec<Observation>,
}

impl Windows {
    /// The window path of a target of `points` points.
    pub(super) fn new(scheduler: RoiScheduler, points: usize) -> Self {
        Self {
            scheduler,
            requests: Vec::with_capacity(points),
            by_column: Some(Vec::with_capacity(points)),
            outcomes: Vec::with_capacity(points),
            centres: Vec::with_capacity(points),
            blend: CentreBlend::default(),
            fit_observations: Vec::with_capacity(points),
        }
    }
}

/// Windows measured one after the other on a thread before another takes the next ones: a window is a few
/// microseconds of work, a hand-over between threads about one.
const WINDOWS_PER_TASK_MIN: usize = 8;

/// What one point's window gave, measured apart from the other windows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum WindowOutcome {
    /// A blob, nearest to this point's prediction: its centre by the moments and by its outline (raw px, before the
    /// disk's perspective shift).
    Found {
        moments_px: Vector2<f64>,
        outline_px: Vector2<f64>,
    },
    /// The blob nearest the prediction is nearer another point's.
    Neighbour,
    /// No blob, or one the centroid refused.
    Rejected(BlobRejection),
}

thread_local! {
    /// The flattened window and the outline's rays of the window a thread is measuring (kept between frames: no
    /// allocation once every thread has measured its largest window).
    static WINDOW_SCRATCH: RefCell<(Vec<u16>, OutlineScratch)> = RefCell::new(Default::default());
}

/// Measures point `i`'s blob in its window `request` of `frame`: the blob nearest its prediction, by the moments of
/// the flattened window and by its outline. Reads nothing but its arguments, so that the windows of a frame can be
/// measured on several threads.
fn measure_window(
    frame: &Frame,
    request: &RoiRequest,
    polarity: Polarity,
    centroid: &CentroidOptions,
    requests: &[Option<RoiRequest>],
    by_column: Option<&[(f64, usize)]>,
    i: usize,
) -> WindowOutcome {
    WINDOW_SCRATCH.with_borrow_mut(|(pixels, outline)| {
        let roi = request.roi;
        let flat = flatten_window(frame, &roi, polarity, pixels);
        // The blob nearest the prediction, not the brightest: a window sized for an uncertain prediction holds
        // whole neighbours of a dense target, of the same contrast, and the rims of others at its edge (on a
        // 24 x 28 hexagonal grid, the brightest blob was a neighbour's in up to 60 of 230 windows a frame, and
        // the frames went to whole-frame searches; 45 of 60 frames in windows, 58 now).
        let near_px = Some([request.predicted_px.x, request.predicted_px.y]);
        match measure_flat_window(pixels, &roi, &flat, centroid, near_px) {
            Ok(c) if !is_nearest_request(requests, by_column, i, c.u_px, c.v_px) => {
                WindowOutcome::Neighbour
            }
            Ok(c) => WindowOutcome::Found {
                moments_px: Vector2::new(c.u_px, c.v_px),
                outline_px: window_outline_centre(pixels, &roi, &c, outline),
            },
            Err(r) => WindowOutcome::Rejected(r),
        }
    })
}

/// The centres of one blob measured in its window (raw px, corrected for perspective), by the window's moments and
/// by the blob's outline (the moments when the outline could not be found).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct WindowCentres {
    pub(super) point_index: usize,
    pub(super) t_s: f64,
    pub(super) moments_px: Vector2<f64>,
    pub(super) outline_px: Vector2<f64>,
}

impl FrameTracker {
    pub(super) fn min_window_points(&self) -> usize {
        self.config
            .min_window_points
            .unwrap_or(self.target.len().div_ceil(2).max(4))
            .clamp(1, self.target.len())
    }

    /// The window of point `i` at the time its predicted row is read in the frame whose row 0 is read at `t_frame_s`.
    pub(super) fn request_at_row_time(
        &self,
        predictor: &Predictor,
        i: usize,
        t_frame_s: f64,
    ) -> Option<RoiRequest> {
        let time = self.camera.time;
        let mut request = self.windows.scheduler.request(predictor, i, t_frame_s);
        if time.is_rolling() {
            // The row gives the time and the time the row: two rounds are plenty for any real line delay.
            for _ in 0..2 {
                let r = request?;
                request = self.windows.scheduler.request(
                    predictor,
                    i,
                    time.blob_time_s(t_frame_s, r.predicted_px.y),
                );
            }
        }
        request
    }

    /// Places each point's window (`self.windows.requests`) in the frame whose row 0 is read at `frame.t_s`; `false`
    /// if a prediction is too uncertain for the largest window.
    fn place_windows(&mut self, frame: &Frame, predictor: &Predictor) -> bool {
        self.windows.requests.clear();
        for i in 0..self.target.len() {
            let request = self.request_at_row_time(predictor, i, frame.t_s);
            // A prediction too uncertain for the largest window (the velocity right after a new track, before a
            // second frame has measured it) could put a neighbouring blob in the window: search the frame instead.
            let largest = f64::from(self.config.windows.max_size_px);
            if request.is_some_and(|r| {
                r.sigma_px
                    .is_some_and(|sigma| 2.0 * self.config.windows.sigma_margin * sigma > largest)
            }) {
                return false;
            }
            self.windows.requests.push(request);
        }
        true
    }

    /// Measures every predicted blob in its window; returns how many were found (in `self.measurements`).
    pub(super) fn measure_windows(&mut self, frame: &Frame, predictor: &Predictor) -> usize {
        self.measurements.clear();
        self.windows.centres.clear();
        let polarity = self.search.polarity.unwrap_or(Polarity::Bright);
        let time = self.camera.time;
        if !self.place_windows(frame, predictor) {
            return 0;
        }
        sort_by_column(&self.windows.requests, &mut self.windows.by_column);
        // Each window is measured apart from the others, on as many threads as rayon has: a dense grid's hundreds of
        // windows are most of a frame's work, and the frames of a video wait for them. What the windows tell the
        // scheduler and the report is then taken in the points' order, as one thread would.
        let (requests, by_column) = (&self.windows.requests, self.windows.by_column.as_deref());
        let centroid = &self.config.centroid;
        requests
            .par_iter()
            .enumerate()
            .with_min_len(WINDOWS_PER_TASK_MIN)
            .map(|(i, request)| {
                request
                    .map(|r| measure_window(frame, &r, polarity, centroid, requests, by_column, i))
            })
            .collect_into_vec(&mut self.windows.outcomes);
        let mut cut = 0;
        for i in 0..self.windows.outcomes.len() {
            let Some(outcome) = self.windows.outcomes[i] else {
                continue;
            };
            match outcome {
                // The blob nearest the prediction is some other point's (the point's own was occluded, or the
                // prediction missed it by half the distance to a neighbour): never measured twice, never swapped.
                WindowOutcome::Neighbour => {
                    self.windows.scheduler.report(i, false);
                    self.report.neighbour_blobs += 1;
                    cut += 1;
                }
                WindowOutcome::Found {
                    moments_px,
                    outline_px,
                } => {
                    self.windows.scheduler.report(i, true);
                    let t_s = time.blob_time_s(frame.t_s, moments_px.y);
                    let shift = self.disk_centre_shift_px(predictor, i, t_s);
                    self.windows.centres.push(WindowCentres {
                        point_index: i,
                        t_s,
                        moments_px: moments_px - shift,
                        outline_px: outline_px - shift,
                    });
                }
                WindowOutcome::Rejected(r) => {
                    self.windows.scheduler.report(i, false);
                    self.report.window_rejections.count(&r);
                    if r == BlobRejection::TouchesBorder {
                        cut += 1;
                    }
                }
            }
        }
        // Blobs cut by their window's edge, or nearer another point's prediction: a few are (a blob at the frame's
        // edge, one merged with a neighbour by blur), and those points are left out of the frame; a prediction that
        // missed the target makes most of them so, and then the blobs the other windows hold may be neighbours too:
        // the frame is measured whole instead. (Abandoning the windows at the first cut blob sent 51 of 60 frames of
        // an 8 x 10 grid to whole-frame searches.)
        let windows = self.windows.requests.iter().filter(|r| r.is_some()).count();
        // Points missing from their windows of a track not yet `tracking`, while a window's reach (its margin of
        // the prediction's sigmas) passes half the distance between two predicted blobs: a new track's covariance
        // may be far too sure of its twist, differenced from two poses, and a prediction a whole spacing of a regular
        // target off puts each window on its neighbour's blob, right where its own was predicted; the blobs found
        // agree with a pose a spacing off (the servo loop's 30 Hz frames of a 4 x 4 grid: 9 of 16 windows found
        // blobs after a new track's first frame, 9.6 px sigmas against 46 px spacings, and the estimate, 28 mm off,
        // was marked converging). The frame is identified whole instead. (A track `tracking` keeps its windows: a
        // dense grid loses a few circles at the frame's edge on most frames, its reach near half its spacing.)
        if !self.memory.tracking
            && self.windows.centres.len() < windows
            && self.windows_may_hold_neighbours()
        {
            self.windows.centres.clear();
            return 0;
        }
        if 4 * cut >= windows {
            self.windows.centres.clear();
            return 0;
        }
        self.take_window_centres(predictor);
        self.measurements.len()
    }

    /// Whether a window's reach, `sigma_margin` times its prediction's sigma, passes half the distance between two
    /// predicted blobs: then a prediction a whole spacing off would put each of them on a neighbour's blob.
    fn windows_may_hold_neighbours(&self) -> bool {
        let margin = self.config.windows.sigma_margin;
        let Some(reach_px) = self
            .windows
            .requests
            .iter()
            .flatten()
            .filter_map(|r| r.sigma_px)
            .map(|sigma| margin * sigma)
            .reduce(f64::max)
        else {
            return false;
        };
        let requests = &self.windows.requests;
        requests.iter().enumerate().any(|(i, a)| {
            a.is_some_and(|a| {
                requests[i + 1..]
                    .iter()
                    .flatten()
                    .any(|b| (a.predicted_px - b.predicted_px).norm() < 2.0 * reach_px)
            })
        })
    }

    /// How far the centre of point `i`'s image, read at `t_s`, lies from the image of its disk's centre (px, to be
    /// taken away from the measured centre): a disk seen at an angle is imaged as an ellipse whose centre is not the
    /// image of the disk's centre (perspective draws its near half larger), by hundredths of a pixel that move with the
    /// pose. Taken away as the full-frame identification does, with the pose `predictor` predicts (the displacement
    /// changes far less than it is with the pose that moves it); zero for a point without a diameter or a target that
    /// is not planar. Without it, the windows' centres carry a bias the full-frame detection's do not, and the frame
    /// study's global-shutter error is larger (measured in docs/frames.md, step 1, and docs/results.md, "Design
    /// measurements behind the code").
    pub(super) fn disk_centre_shift_px(
        &self,
        predictor: &Predictor,
        i: usize,
        t_s: f64,
    ) -> Vector2<f64> {
        let point = &self.target.points()[i];
        let (Some(plane), Some(diameter_m)) = (self.target.plane(), point.diameter_m) else {
            return Vector2::zeros();
        };
        let normal: Vector3<f64> = plane.obj_r_plane.column(2).into_owned();
        let state = predictor.state.predicted(t_s - predictor.t_ref_s);
        disk_centre_displacement_px(
            &self.camera,
            &state,
            &point.point_in_obj_m,
            &normal,
            diameter_m,
        )
        .unwrap_or_else(Vector2::zeros)
    }
}

/// `predictor` carried to `t_s` with `acceleration`: the scheduler predicts under a constant twist, and between
/// frames (33 ms at 30 Hz) an acceleration of 10 m/s² moves a blob 5.4 mm from that prediction. The covariance is
/// carried under the constant twist ([`MotionState::transition_jacobian`]), as the scheduler would have.
pub(super) fn carried_with_acceleration(
    predictor: Predictor,
    acceleration: &Acceleration,
    t_s: f64,
) -> Predictor {
    let dt_s = t_s - predictor.t_ref_s;
    let f = predictor.state.transition_jacobian(dt_s);
    Predictor {
        t_ref_s: t_s,
        state: acceleration.predicted(&predictor.state, dt_s),
        covariance: predictor.covariance.map(|p| f * p * f.transpose()),
    }
}

/// The windows' predicted centres `(column, point)` sorted by column into `by_column`; `None` there when a predicted
/// centre is not finite.
fn sort_by_column(requests: &[Option<RoiRequest>], by_column: &mut Option<Vec<(f64, usize)>>) {
    let mut sorted = by_column.take().unwrap_or_default();
    sorted.clear();
    let mut finite = true;
    for (i, r) in requests.iter().enumerate() {
        if let Some(r) = r {
            finite &= r.predicted_px.x.is_finite() && r.predicted_px.y.is_finite();
            sorted.push((r.predicted_px.x, i));
        }
    }
    sorted.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    *by_column = Some(sorted).filter(|_| finite);
}

/// Whether point `i`'s predicted blob centre is the nearest to `(u_px, v_px)` of all the points' (the first of them
/// in index order when several are as near): the distances compared by `f64::hypot` and `f64::total_cmp`, as a
/// search for the nearest would.
///
/// Another point's distance is computed only when both its offsets are within point `i`'s distance: `hypot(x, y)` is
/// at least `|x|` and `|y|` (glibc's rounds faithfully, never below a representable bound of the exact value), so a
/// point with a larger offset cannot be as near. With the predictions sorted by column (`by_column`, from
/// [`sort_by_column`]), only those within that distance (and a pixel, against rounding) of the blob's column are
/// looked at. A 336-point grid's windows spent a quarter of the frame tracker's time on the distances of every pair
/// before.
fn is_nearest_request(
    requests: &[Option<RoiRequest>],
    by_column: Option<&[(f64, usize)]>,
    i: usize,
    u_px: f64,
    v_px: f64,
) -> bool {
    let distance = |r: &RoiRequest| (r.predicted_px.x - u_px).hypot(r.predicted_px.y - v_px);
    let Some(own) = requests.get(i).and_then(Option::as_ref).map(distance) else {
        return false;
    };
    // Whether point j, nearer than point i or as near and listed first, is not there.
    let not_nearer = |j: usize| {
        let Some(r) = &requests[j] else {
            return true;
        };
        if j == i || (r.predicted_px.x - u_px).abs() > own || (r.predicted_px.y - v_px).abs() > own
        {
            return true;
        }
        match distance(r).total_cmp(&own) {
            std::cmp::Ordering::Less => false,
            std::cmp::Ordering::Equal => j > i,
            std::cmp::Ordering::Greater => true,
        }
    };
    match by_column {
        Some(sorted) if own.is_finite() && u_px.is_finite() => {
            let (low, high) = (u_px - own - 1.0, u_px + own + 1.0);
            let start = sorted.partition_point(|&(x, _)| x < low);
            sorted[start..]
                .iter()
                .take_while(|&&(x, _)| x <= high)
                .all(|&(_, j)| not_nearer(j))
        }
        _ => (0..requests.len()).all(not_nearer),
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector2;
    use roitrack_image::Roi;

    use super::*;

    /// The nearest request by the search it replaces: every distance, the first minimum.
    fn nearest_by_search(requests: &[Option<RoiRequest>], u_px: f64, v_px: f64) -> Option<usize> {
        requests
            .iter()
            .enumerate()
            .filter_map(|(i, r)| {
                r.as_ref()
                    .map(|r| (i, (r.predicted_px.x - u_px).hypot(r.predicted_px.y - v_px)))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }

    #[test]
    fn the_nearest_request_is_the_one_a_search_of_every_distance_finds() {
        let request = |k: usize, x: f64, y: f64| RoiRequest {
            point_index: k,
            roi: Roi::new(0, 0, 12, 12),
            predicted_px: Vector2::new(x, y),
            sigma_px: None,
        };
        // A grid with ties (points at the same place, centres halfway between two), a missing point, and centres
        // scattered around them by a fixed sequence.
        let mut requests: Vec<Option<RoiRequest>> = (0..30)
            .map(|k| Some(request(k, (k % 6) as f64 * 3.0, (k / 6) as f64 * 3.0)))
            .collect();
        requests[7] = None;
        requests.push(Some(request(30, 6.0, 3.0)));
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut by_column = None;
        sort_by_column(&requests, &mut by_column);
        assert!(by_column.as_ref().is_some_and(|b| b.len() == 30));
        let mut centres = vec![(1.5, 0.0), (6.0, 3.0), (4.5, 4.5), (3.0, 3.0), (-50.0, 2.0)];
        centres.extend((0..2000).map(|_| (next() * 20.0 - 2.0, next() * 17.0 - 2.0)));
        for (u, v) in centres {
            let nearest = nearest_by_search(&requests, u, v);
            for i in 0..requests.len() {
                for sorted in [by_column.as_deref(), None] {
                    assert_eq!(
                        is_nearest_request(&requests, sorted, i, u, v),
                        nearest == Some(i),
                        "point {i}, centre ({u}, {v})"
                    );
                }
            }
        }
    }
}
