//! The frame-tracking benchmark: a [`FrameTracker`] following the 16 blobs of [`Target::grid4x4`] through 640 x 480
//! frames of the sweep scenario at 30 Hz, pre-rendered in memory so that neither rendering nor decoding counts
//! ([`FrameBench::time_steady`]), and the same frames streamed from a decoder through [`track_frame_stream`] against
//! the decoder alone ([`FrameBench::decode_and_track`]).
//!
//! The speed targets of frame streams: tracking 16 blobs on 640 x 480 frames at 5,000 frames/s or more excluding
//! decoding ([`TRACKING_TARGET_FRAMES_PER_S`]), and tracking from PNG files end to end within 1.2 times the time of
//! decoding them alone ([`END_TO_END_TARGET_RATIO`]). `cargo bench -p roitrack-bench --bench frame_tracking` measures
//! both (`benches/frame_tracking.rs`).
//!
//! The scene: camera [`camera_640x480`] (fx = fy = 700 px, the canonical camera's field of view on a 640 x 480
//! sensor, no distortion), the sweep scenario ([`ScenarioKind::Sweep`], seed [`SEED`]: up to 0.5 m/s and 1.5 rad/s,
//! 0.45 to 0.8 m away; each 6 mm blob 5 to 9 px across), bright blobs, the default sensor (8 bits, shot and read
//! noise), 1 ms exposure, a global shutter or a rolling shutter reading a row every [`ROLLING_LINE_DELAY_S`].
//!
//! The tracker measured is in its steady state: the first [`WARM_UP_FRAMES`] frames of each pass (the search of the
//! first frame with no prior, the whole-frame search of the second, the velocity settling) are processed outside
//! the timing. [`FrameBench::time_steady`] times the later frames measured in their predicted windows
//! ([`FrameMethod::Windows`], the path whose speed is the target), each frame on its own clock: a frame measured
//! otherwise (a blob rejected in its window sends the frame to the whole-frame search) is processed, so that the
//! track goes on as it would, but not counted; [`FrameBench::time_all`] counts every frame after the warm-up.
//! [`FrameBench::check`] makes sure that the timed path is the real one: nearly every frame after the warm-up
//! measured in its windows ([`MIN_WINDOWS_FRACTION`]), all 16 blobs measured, every estimate within
//! [`MAX_POSITION_ERROR_M`] of the truth.

use std::fmt::Debug;
use std::hint::black_box;
use std::time::{Duration, Instant};

use roitrack_core::camera::{PinholeIntrinsics, PlumbBob};
use roitrack_core::time::Readout;
use roitrack_core::{CameraModel, Target};
use roitrack_image::Frame;
use roitrack_pipeline::frames::{
    FrameMethod, FrameTrackReport, FrameTracker, FrameTrackerConfig, track_frame_stream,
};
use roitrack_sim::{FrameOptions, FrameSequence, FrameSequenceError, Scenario, ScenarioKind};

/// Frame width (px).
pub const WIDTH_PX: u32 = 640;
/// Frame height (px).
pub const HEIGHT_PX: u32 = 480;
/// Focal length (px): a vertical field of view of 37.8°, the canonical camera's (1500 px on 1024 rows).
pub const FOCAL_PX: f64 = 700.0;
/// Frame rate (Hz).
pub const FPS_HZ: f64 = 30.0;
/// Exposure of each row (s).
pub const EXPOSURE_S: f64 = 1e-3;
/// Line delay of the rolling-shutter variant (s): 480 rows read in 28.8 ms, within the 33.3 ms frame period with the
/// exposure.
pub const ROLLING_LINE_DELAY_S: f64 = 60e-6;
/// Seed of the sweep's motion and of the sensor noise.
pub const SEED: u64 = 1;
/// Frames of a pass processed before the timing: the first is searched whole, the second associated whole, the
/// velocity settles over the next few (in the global-shutter sweep frames 1 to 4 are measured whole, frame 3 starting
/// a new track).
pub const WARM_UP_FRAMES: usize = 8;
/// Largest position error of a timed frame's estimate (m).
pub const MAX_POSITION_ERROR_M: f64 = 1e-3;
/// Smallest fraction of the frames after the warm-up measured in their windows.
pub const MIN_WINDOWS_FRACTION: f64 = 0.9;
/// The speed target of tracking without decoding (frames/s).
pub const TRACKING_TARGET_FRAMES_PER_S: f64 = 5000.0;
/// The speed target of tracking from PNG files: end-to-end time over decoding time.
pub const END_TO_END_TARGET_RATIO: f64 = 1.2;

/// The 640 x 480 camera of the bench: fx = fy = [`FOCAL_PX`], centre (319.5, 239.5), no skew, no distortion
/// (sequential-ROI time model: [`FrameBench`] gives it the shutter of its frames).
pub fn camera_640x480() -> CameraModel {
    let intrinsics = PinholeIntrinsics {
        fx_px: FOCAL_PX,
        fy_px: FOCAL_PX,
        skew_px: 0.0,
        cx_px: (f64::from(WIDTH_PX) - 1.0) / 2.0,
        cy_px: (f64::from(HEIGHT_PX) - 1.0) / 2.0,
    };
    CameraModel::new(
        "bench 640x480",
        WIDTH_PX,
        HEIGHT_PX,
        intrinsics,
        PlumbBob::default(),
    )
    .expect("a valid camera")
}

/// The rolling shutter of the rolling variant.
pub fn rolling_shutter() -> Readout {
    Readout::RollingShutter {
        line_delay_s: ROLLING_LINE_DELAY_S,
    }
}

/// What [`FrameBench::check`] found over one pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyCheck {
    /// Frames per pass after the warm-up.
    pub steady_frames: usize,
    /// Of those, frames measured in their windows (around the predicted blobs).
    pub by_windows: usize,
    /// Of those, frames with an estimate.
    pub estimates: usize,
    /// Blobs measured per frame, fewest.
    pub min_blobs: usize,
    /// Largest position error of the estimates (m).
    pub max_position_error_m: f64,
    /// RMS position error of the estimates (m).
    pub rms_position_error_m: f64,
}

impl SteadyCheck {
    /// At least [`MIN_WINDOWS_FRACTION`] of the frames after the warm-up measured in their windows, all 16 blobs of
    /// every frame measured, every estimate within [`MAX_POSITION_ERROR_M`]: `Err` says what is not so.
    pub fn ensure(&self) -> Result<(), String> {
        if (self.by_windows as f64) < MIN_WINDOWS_FRACTION * self.steady_frames as f64
            || self.estimates != self.steady_frames
            || self.min_blobs < 16
            || self.max_position_error_m > MAX_POSITION_ERROR_M
        {
            return Err(format!(
                "the frames after the warm-up are not tracked in their windows within {MAX_POSITION_ERROR_M} m: \
                 {self:?}"
            ));
        }
        Ok(())
    }
}

/// Figures of [`FrameBench::decode_and_track`]: the best of its passes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamFigures {
    /// Frames per pass.
    pub frames: usize,
    /// Decoding every frame alone (s).
    pub decode_s: f64,
    /// Decoding on its own thread beside the tracker, [`track_frame_stream`] (s).
    pub end_to_end_s: f64,
}

impl StreamFigures {
    /// End-to-end time over decoding time.
    pub fn ratio(&self) -> f64 {
        self.end_to_end_s / self.decode_s
    }
}

/// Frames of the sweep pre-rendered in memory, with their camera, target and truth.
///
/// ```
/// use roitrack_bench::frame_bench::{FrameBench, WARM_UP_FRAMES};
/// use roitrack_core::time::Readout;
///
/// let bench = FrameBench::new(Readout::GlobalShutter, WARM_UP_FRAMES + 3).unwrap();
/// bench.check().ensure().unwrap();
/// assert!(bench.time_steady(5) > std::time::Duration::ZERO);
/// assert!(bench.time_all(5) > std::time::Duration::ZERO);
/// ```
pub struct FrameBench {
    sequence: FrameSequence,
    frames: Vec<Frame>,
}

impl FrameBench {
    /// Renders frames 0 to `count - 1` of the sweep (at least [`WARM_UP_FRAMES`] + 1, at most the 181 of its 6 s)
    /// seen by [`camera_640x480`] with `readout`.
    pub fn new(readout: Readout, count: usize) -> Result<Self, FrameSequenceError> {
        let scenario = Scenario::new(ScenarioKind::Sweep, SEED).with_camera(camera_640x480());
        let options = FrameOptions {
            fps_hz: FPS_HZ,
            readout,
            exposure_s: EXPOSURE_S,
            seed: SEED,
            frame_count: Some(count.max(WARM_UP_FRAMES + 1)),
            ..FrameOptions::default()
        };
        let mut sequence = FrameSequence::new(&scenario, &options)?;
        let frames = (0..sequence.len())
            .map(|k| {
                let mut frame = Frame::default();
                sequence.render(k, &mut frame);
                frame
            })
            .collect();
        Ok(Self { sequence, frames })
    }

    /// The frames, in time order (frame `k` at `k / 30` s).
    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }

    /// The camera the frames were taken with (its time model that of the frames).
    pub fn camera(&self) -> &CameraModel {
        self.sequence.camera()
    }

    /// The target the frames show ([`Target::grid4x4`]).
    pub fn target(&self) -> &Target {
        &self.sequence.scenario().target
    }

    /// The smallest distance (px) of a blob centre to the image border over the sweep.
    pub fn min_image_margin_px(&self) -> f64 {
        self.sequence.scenario().min_image_margin_px()
    }

    /// A new tracker for the frames (default settings).
    pub fn tracker(&self) -> FrameTracker {
        FrameTracker::new(
            self.camera().clone(),
            self.target().clone(),
            FrameTrackerConfig::default(),
        )
        .expect("the default settings are valid")
    }

    /// A new tracker that has processed the first [`WARM_UP_FRAMES`] frames.
    pub fn warmed_up_tracker(&self) -> FrameTracker {
        let mut tracker = self.tracker();
        for frame in &self.frames[..WARM_UP_FRAMES] {
            tracker.process(frame).expect("the frames are in order");
        }
        tracker
    }

    /// One pass over the frames: how the timed frames (after the warm-up) were measured and how far their estimates
    /// are from the truth.
    pub fn check(&self) -> SteadyCheck {
        let mut tracker = self.warmed_up_tracker();
        let steady = &self.frames[WARM_UP_FRAMES..];
        let (mut by_windows, mut estimates, mut min_blobs) = (0, 0, usize::MAX);
        let (mut max_error, mut sum_squares) = (0.0f64, 0.0);
        for frame in steady {
            let outcome = tracker.process(frame).expect("the frames are in order");
            by_windows += usize::from(outcome.method == FrameMethod::Windows);
            min_blobs = min_blobs.min(outcome.measured);
            if let Some(e) = outcome.estimate {
                estimates += 1;
                let truth = self.sequence.state_at(e.t_ref_s);
                let error = (e.state.cam_t_obj_m - truth.cam_t_obj_m).norm();
                max_error = max_error.max(error);
                sum_squares += error * error;
            }
        }
        SteadyCheck {
            steady_frames: steady.len(),
            by_windows,
            estimates,
            min_blobs,
            max_position_error_m: max_error,
            rms_position_error_m: (sum_squares / estimates.max(1) as f64).sqrt(),
        }
    }

    /// The time of processing `frames` frames in their windows: passes over the frames after the warm-up, one after
    /// the other, each frame timed on its own and counted if it was measured in its windows; at the end of a pass
    /// (times cannot go back) a new tracker is warmed up on the first frames, outside the timing.
    ///
    /// # Panics
    /// If a whole pass has no frame measured in its windows.
    pub fn time_steady(&self, frames: usize) -> Duration {
        self.time_frames(frames, true)
    }

    /// The time of processing `frames` frames after the warm-up, however they are measured (as
    /// [`Self::time_steady`], every frame counted).
    pub fn time_all(&self, frames: usize) -> Duration {
        self.time_frames(frames, false)
    }

    fn time_frames(&self, frames: usize, windows_only: bool) -> Duration {
        let mut elapsed = Duration::ZERO;
        let mut timed = 0;
        while timed < frames {
            let mut tracker = self.warmed_up_tracker();
            let timed_before = timed;
            for frame in &self.frames[WARM_UP_FRAMES..] {
                let start = Instant::now();
                let outcome = tracker
                    .process(black_box(frame))
                    .expect("the frames are in order");
                let dt = start.elapsed();
                if !windows_only || black_box(outcome).method == FrameMethod::Windows {
                    elapsed += dt;
                    timed += 1;
                    if timed == frames {
                        break;
                    }
                }
            }
            assert!(
                timed > timed_before,
                "no frame of a pass was measured in its windows"
            );
        }
        elapsed
    }

    /// Frames processed per second in their windows ([`Self::time_steady`]), over passes until about `budget` of
    /// wall time has gone (warm-ups and frames measured otherwise included; at least one pass).
    pub fn tracking_frames_per_s(&self, budget: Duration) -> f64 {
        let start = Instant::now();
        let pass = self.frames.len() - WARM_UP_FRAMES;
        let (mut frames, mut elapsed) = (0usize, Duration::ZERO);
        while frames == 0 || start.elapsed() < budget {
            elapsed += self.time_steady(pass);
            frames += pass;
        }
        frames as f64 / elapsed.as_secs_f64()
    }

    /// Decoding alone against decoding beside the tracker: `open` gives a fresh decoder of these frames (as
    /// [`track_frame_stream`] takes it: it fills the frame it is given, `None` at the end), e.g. a
    /// `roitrack_formats::FrameSource` of them written as PNG files. Each of `repeats` rounds (at least one) times a
    /// pass of decoding every frame and a pass of [`track_frame_stream`] with a new tracker; the best of each is kept.
    ///
    /// # Panics
    /// If the decoder fails or the stream stops with an error.
    pub fn decode_and_track<N, I, S>(
        &self,
        mut open: impl FnMut() -> N,
        repeats: usize,
    ) -> StreamFigures
    where
        N: FnMut(&mut Frame) -> Option<Result<I, S>> + Send,
        I: Send + Debug,
        S: Send + Debug,
    {
        let (mut decode_s, mut end_to_end_s, mut frames) = (f64::INFINITY, f64::INFINITY, 0);
        let mut frame = Frame::default();
        for _ in 0..repeats.max(1) {
            let mut next = open();
            let start = Instant::now();
            frames = decode_all(&mut next, &mut frame);
            decode_s = decode_s.min(start.elapsed().as_secs_f64());

            let mut tracker = self.tracker();
            let next = open();
            let start = Instant::now();
            let report = stream(&mut tracker, next).expect("the stream runs to its end");
            end_to_end_s = end_to_end_s.min(start.elapsed().as_secs_f64());
            assert_eq!(report.frames, frames, "every frame decoded is tracked");
        }
        StreamFigures {
            frames,
            decode_s,
            end_to_end_s,
        }
    }
}

/// Decodes every frame of `next` into `frame`; returns how many.
///
/// # Panics
/// If a frame cannot be decoded.
pub fn decode_all<I, S: Debug>(
    mut next: impl FnMut(&mut Frame) -> Option<Result<I, S>>,
    frame: &mut Frame,
) -> usize {
    let mut frames = 0;
    while let Some(item) = next(frame) {
        black_box(item.expect("the frame decodes"));
        black_box(&frame.pixels);
        frames += 1;
    }
    frames
}

/// [`track_frame_stream`] over `next` with `tracker`, every outcome dropped; an error as text.
pub fn stream<N, I, S>(tracker: &mut FrameTracker, next: N) -> Result<FrameTrackReport, String>
where
    N: FnMut(&mut Frame) -> Option<Result<I, S>> + Send,
    I: Send + Debug,
    S: Send + Debug,
{
    track_frame_stream(tracker, next, |_, outcome, _| {
        black_box(outcome);
        Ok::<_, std::convert::Infallible>(())
    })
    .map_err(|e| format!("{e:?}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_timed_frames_are_tracked_in_their_windows() {
        for readout in [Readout::GlobalShutter, rolling_shutter()] {
            let bench = FrameBench::new(readout, WARM_UP_FRAMES + 15).unwrap();
            assert!(bench.min_image_margin_px() > 10.0);
            let frame = &bench.frames()[3];
            assert_eq!((frame.width, frame.height), (WIDTH_PX, HEIGHT_PX));
            let check = bench.check();
            eprintln!("{readout:?}: {check:?}");
            check.ensure().unwrap();
            assert_eq!(check.by_windows, check.steady_frames);
        }
    }

    #[test]
    fn streamed_frames_are_all_tracked() {
        let bench = FrameBench::new(Readout::GlobalShutter, 12).unwrap();
        assert_eq!(bench.frames().len(), 12);
        // An in-memory "decoder": copies the frames.
        let frames = bench.frames();
        let open = || {
            let mut k = 0;
            move |frame: &mut Frame| {
                let source = frames.get(k)?;
                frame.clone_from(source);
                k += 1;
                Some(Ok::<_, std::convert::Infallible>(k))
            }
        };
        let figures = bench.decode_and_track(open, 1);
        assert_eq!(figures.frames, 12);
        assert!(figures.decode_s > 0.0 && figures.end_to_end_s > 0.0);
        let report = stream(&mut bench.tracker(), open()).unwrap();
        assert_eq!(report.estimates, 12);
        assert!(report.by_windows >= 12 - WARM_UP_FRAMES);
    }
}
