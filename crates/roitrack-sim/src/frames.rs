//! Image sequences: the full frames a global- or rolling-shutter camera takes of a scenario, with the ground truth
//! to score a tracker that reads them.
//!
//! A [`FrameSequence`] renders frame `k` at `t_k = start_s + k / fps_hz`, the mid-exposure time of its row 0; with
//! a rolling shutter row `v` is exposed around `t_k + v * line_delay_s` (the camera's [`TimeModel`], which the
//! sequence puts into its [`FrameSequence::camera`]: a tracker of these frames must use that camera so that it times
//! each blob as the images were made).
//!
//! - **Bright blobs** ([`Polarity::Bright`]) are what [`RoiRenderer::render_frame`] makes: perspective disks, optical
//!   and motion blur over the exposure, every row at its own time, shot and read noise, quantisation.
//! - **Dark blobs** ([`Polarity::Dark`], printed circles on paper) are the same blob images (the renderer's coverage,
//!   drawn noiselessly at 16 bits, so with the same blur, motion blur and row times) composed onto a light, uneven
//!   background: `mean = peak_e * light(u, v) * (1 - DARK_BLOB_CONTRAST * coverage)`, then the sensor's shot and
//!   read noise and quantisation. `peak_e` is the sensor's `background_e + blob_signal_e` (a bright blob's peak: 90 %
//!   of full well by default), and the light falls by half from the top-left corner to the bottom-right one (a lamp
//!   off to one side, times a broad vignetting), with a soft shadow band crossing the image diagonally (light down to
//!   0.65 on its axis). The blobs are a quarter of the light around them ([`DARK_BLOB_CONTRAST`]).
//!
//! Each frame has its own random generator, seeded from the sequence's seed and the frame's index, so a frame's
//! pixels do not depend on which frames were rendered before it.
//!
//! The ground truth ([`FrameSequence::truth_samples`]) is the scenario's state, sampled densely enough over the
//! span of the blob times ([`FrameSequence::span_s`]) to be interpolated at any time a tracker reports;
//! [`FrameSequence::true_blob_centres`] gives each visible blob's true image centre at its own row time.
//!
//! ```
//! use roitrack_core::time::Readout;
//! use roitrack_image::Frame;
//! use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
//!
//! let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
//! let options = FrameOptions {
//!     readout: Readout::RollingShutter { line_delay_s: 30e-6 },
//!     frame_count: Some(2),
//!     ..FrameOptions::default()
//! };
//! let mut frames = FrameSequence::new(&scenario, &options).unwrap();
//! let mut frame = Frame::default();
//! frames.render(1, &mut frame);
//! assert_eq!(frame.t_s, 1.0 / 30.0);
//! // Every blob of the grid is seen, each at the time of its own row.
//! let blobs = frames.true_blob_centres(1);
//! assert_eq!(blobs.len(), 16);
//! assert!(blobs.iter().all(|b| (b.t_s - (frame.t_s + b.v_px * 30e-6)).abs() < 1e-9));
//! ```

use nalgebra::Vector2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::time::{Readout, TimeModel, TimeModelError};
use roitrack_core::{CameraModel, Measurement, MotionState, PoseSample, TwistSample};
use roitrack_estimators::rig::{CameraMount, ClockModel, RigCamera};
use roitrack_image::{Frame, Polarity};
use thiserror::Error;

use crate::{RenderScratch, RoiRenderer, Scenario, SensorError, SensorModel};

/// Fraction of the local light that a dark blob does not reflect: its ink reflects a quarter of what the paper does.
///
/// ```
/// // A fully inked pixel is a quarter of the paper around it.
/// assert_eq!(1.0 - roitrack_sim::DARK_BLOB_CONTRAST, 0.25);
/// ```
pub const DARK_BLOB_CONTRAST: f64 = 0.75;

/// Default rate of the ground-truth samples (Hz): linear interpolation between them is within 1e-6 m of the truth
/// at the scenarios' accelerations (a dt² / 8).
///
/// ```
/// assert_eq!(1.0 / roitrack_sim::DEFAULT_TRUTH_RATE_HZ, 0.5e-3);
/// ```
pub const DEFAULT_TRUTH_RATE_HZ: f64 = 2000.0;

/// Mixed into the seed so that a sequence's noise is not the same stream as the other simulators' with that seed.
const FRAME_SEED_SALT: u64 = 0x00f7_a3e5_5eed_0001;

/// Row-time iterations of [`FrameSequence::true_blob_centres`]: each divides the error by the blob's vertical image
/// speed times the line delay (under 0.1 for 2.5 m/s at 0.6 m and 30 µs a row), so 8 are far beyond the float's
/// precision; the loop stops earlier once the row no longer moves.
const ROW_TIME_ITERATIONS: usize = 8;

/// The coverage of dark blobs is rendered at 16 bits: steps of 1.5e-5, far below the noise.
const COVERAGE_FULL_SCALE: f64 = 65_535.0;

/// How a sequence is taken: frame rate, shutter, exposure, blobs, sensor, seed and time span.
///
/// ```
/// use roitrack_core::time::Readout;
/// use roitrack_image::Polarity;
/// use roitrack_sim::FrameOptions;
///
/// // Dark printed circles, a rolling shutter reading a row every 30 µs, 2 ms exposure, 20 frames from t = 1 s.
/// let options = FrameOptions {
///     readout: Readout::RollingShutter { line_delay_s: 30e-6 },
///     exposure_s: 2e-3,
///     polarity: Polarity::Dark,
///     start_s: 1.0,
///     frame_count: Some(20),
///     ..FrameOptions::default()
/// };
/// assert_eq!(options.fps_hz, 30.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOptions {
    /// Frames per second (Hz). Default 30.
    pub fps_hz: f64,
    /// [`Readout::GlobalShutter`] (the default) or [`Readout::RollingShutter`]; sequential ROIs are refused.
    pub readout: Readout,
    /// Exposure of each row (s), centred on the row's time. Default 1 ms (2.5 px of motion blur at 1 m/s and 0.6 m
    /// on the canonical camera).
    pub exposure_s: f64,
    /// Bright blobs (the default) or dark ones on an uneven light background (see the [module docs](self)).
    pub polarity: Polarity,
    /// Photometry, optics blur, noise, bit depth and rendering resolution. Default [`SensorModel::default`].
    pub sensor: SensorModel,
    /// Seed of the noise. Default 1.
    pub seed: u64,
    /// Time of frame 0 (s). Default 0.
    pub start_s: f64,
    /// Number of frames; `None` (the default): every frame whose rows are all exposed by the scenario's end.
    pub frame_count: Option<usize>,
}

impl Default for FrameOptions {
    fn default() -> Self {
        Self {
            fps_hz: 30.0,
            readout: Readout::GlobalShutter,
            exposure_s: 1e-3,
            polarity: Polarity::Bright,
            sensor: SensorModel::default(),
            seed: 1,
            start_s: 0.0,
            frame_count: None,
        }
    }
}

/// Why a frame sequence cannot be made.
///
/// ```
/// use roitrack_core::time::Readout;
/// use roitrack_sim::{FrameOptions, FrameSequence, FrameSequenceError, Scenario, ScenarioKind};
///
/// // 1024 rows at 40 µs take 41 ms: more than the 33 ms between frames at 30 fps.
/// let options = FrameOptions {
///     readout: Readout::RollingShutter { line_delay_s: 40e-6 },
///     ..FrameOptions::default()
/// };
/// let error = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &options).unwrap_err();
/// assert!(matches!(error, FrameSequenceError::ReadoutTooLong { rows: 1024, .. }));
/// assert!(error.to_string().contains("0.04096 s"));
/// ```
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FrameSequenceError {
    /// The frame rate is not a finite positive number.
    #[error("the frame rate must be a finite positive number, got {fps_hz} Hz")]
    FrameRate {
        /// The frame rate given (Hz).
        fps_hz: f64,
    },
    /// The first frame's time is not finite.
    #[error("the start time must be finite, got {start_s} s")]
    StartTime {
        /// The start time given (s).
        start_s: f64,
    },
    /// The time model reads one ROI at a time: a frame needs a global or a rolling shutter.
    #[error("frames are read by a global or a rolling shutter, not one ROI at a time")]
    SequentialRois,
    /// The camera's time model is invalid.
    #[error("the time model: {0}")]
    TimeModel(#[from] TimeModelError),
    /// The exposure does not fit in one frame period.
    #[error(
        "the exposure ({exposure_s} s) is longer than the frame period ({period_s} s at {fps_hz} Hz)"
    )]
    ExposureTooLong {
        /// The exposure (s).
        exposure_s: f64,
        /// The frame period, `1 / fps_hz` (s).
        period_s: f64,
        /// The frame rate (Hz).
        fps_hz: f64,
    },
    /// A rolling shutter's readout plus the exposure does not fit in one frame period.
    #[error(
        "a rolling shutter reading {rows} rows {line_delay_s} s apart takes {readout_s} s; with the {exposure_s} s \
         exposure that is more than the frame period ({period_s} s at {fps_hz} Hz): lower the frame rate, the line \
         delay or the exposure"
    )]
    ReadoutTooLong {
        /// The sensor's rows.
        rows: u32,
        /// The time between the starts of two consecutive rows (s).
        line_delay_s: f64,
        /// The time from the first row to the last, `rows * line_delay_s` (s).
        readout_s: f64,
        /// The exposure (s).
        exposure_s: f64,
        /// The frame period, `1 / fps_hz` (s).
        period_s: f64,
        /// The frame rate (Hz).
        fps_hz: f64,
    },
    /// No frame fits in the scenario from the start time on.
    #[error(
        "no frame: {frame_count} frames asked for from {start_s} s (the scenario lasts {duration_s} s, a frame's \
         readout {readout_s} s)"
    )]
    NoFrames {
        /// The frames asked for, or the number that fit when none was asked for.
        frame_count: usize,
        /// The first frame's time (s).
        start_s: f64,
        /// The scenario's end (s; its length, or for a rig's camera its end on the camera's clock).
        duration_s: f64,
        /// A frame's readout, first row to last (s; 0 for a global shutter).
        readout_s: f64,
    },
    /// The sensor model is invalid.
    #[error("the sensor: {0}")]
    Sensor(#[from] SensorError),
    /// The rate of the ground-truth samples is not a finite positive number.
    #[error("the truth rate must be a finite positive number, got {rate_hz} Hz")]
    TruthRate {
        /// The rate given (Hz).
        rate_hz: f64,
    },
    /// More than [`MAX_FRAMES`] frames would be written.
    #[error(
        "{frame_count} frames at {fps_hz} Hz: a simulated sequence has at most {MAX_FRAMES} frames (each a PNG file); \
         lower the frame rate or the duration"
    )]
    TooManyFrames {
        /// The frames the sequence would have.
        frame_count: usize,
        /// The frame rate (Hz).
        fps_hz: f64,
    },
}

/// The most frames a sequence may have: 100,000 (55 minutes at 30 Hz), each written as a file of up to a few MB.
pub const MAX_FRAMES: usize = 100_000;

/// The ground truth of a sequence: poses and twists at the same times, increasing.
///
/// ```
/// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
///
/// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &FrameOptions::default()).unwrap();
/// let truth = frames.truth_samples(100.0).unwrap();
/// assert_eq!(truth.poses.len(), truth.twists.len());
/// assert_eq!(truth.poses[0].t_s, frames.span_s().0);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTruth {
    /// The true pose of the target in the camera frame at each time.
    pub poses: Vec<PoseSample>,
    /// The true twist at the same times as [`Self::poses`].
    pub twists: Vec<TwistSample>,
}

/// The frames a camera takes of a [`Scenario`] (see the [module documentation](self)).
///
/// ```
/// use roitrack_image::{Frame, Polarity};
/// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
///
/// let scenario = Scenario::new(ScenarioKind::Static, 1);
/// let options = FrameOptions { polarity: Polarity::Dark, ..FrameOptions::default() };
/// let mut frames = FrameSequence::new(&scenario, &options).unwrap();
/// assert_eq!(frames.len(), 31); // 1 s at 30 fps, both ends
/// let mut frame = Frame::default();
/// frames.render(0, &mut frame);
/// // Light paper, darker in the bottom-right corner than in the top-left one.
/// assert!(frame.pixels[frame.index(5, 5)] > 150);
/// assert!(frame.pixels[frame.index(1018, 1018)] < 120);
/// ```
#[derive(Debug, Clone)]
pub struct FrameSequence {
    scenario: Scenario,
    /// A rig's camera: where it is in the scenario's camera frame and its clock (None: the scenario's own camera).
    view: Option<(CameraMount, ClockModel)>,
    options: FrameOptions,
    frame_count: usize,
    /// The blobs as the camera sees them (bright), or their coverage at 16 bits (dark).
    renderer: RoiRenderer,
    /// Relative light of each pixel (dark blobs only), row-major: computed once, it does not move.
    light: Vec<f32>,
    scratch: RenderScratch,
    coverage: Frame,
}

impl FrameSequence {
    /// The sequence of `options` of `scenario` (its motion, camera and target; the camera's time model is replaced by
    /// the options' shutter and exposure).
    ///
    /// Refuses a frame rate that is not finite and positive, a non-finite start, sequential ROIs, a negative or
    /// non-finite exposure or line delay, an exposure longer than the frame period, a rolling shutter whose readout
    /// (line delay times rows) plus exposure is longer than the frame period, no frame, and an invalid sensor.
    ///
    /// ```
    /// use roitrack_core::time::Readout;
    /// use roitrack_sim::{FrameOptions, FrameSequence, FrameSequenceError, Scenario, ScenarioKind};
    ///
    /// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    /// let frames = FrameSequence::new(&scenario, &FrameOptions::default()).unwrap();
    /// assert_eq!(frames.len(), 148); // 4.91 s at 30 fps
    /// assert_eq!(frames.camera().time.readout, Readout::GlobalShutter);
    /// let still = FrameOptions { fps_hz: 0.0, ..FrameOptions::default() };
    /// assert_eq!(
    ///     FrameSequence::new(&scenario, &still).unwrap_err(),
    ///     FrameSequenceError::FrameRate { fps_hz: 0.0 }
    /// );
    /// ```
    pub fn new(scenario: &Scenario, options: &FrameOptions) -> Result<Self, FrameSequenceError> {
        Self::with_view(scenario, &scenario.camera, None, options)
    }

    /// The sequence of `options` that a rig's `camera` takes of `scenario`, whose camera frame and clock are the
    /// rig's: the camera's calibration (its time model replaced as in [`Self::new`]), the target seen through its
    /// mount, and every time of the sequence (`start_s`, the frames', the truth's) on the camera's own clock, frame
    /// `k`'s rows exposed around the rig times `clock.rig_time_s(t_k + v * line_delay_s)`. By default the frames
    /// are those whose rows are all exposed by the scenario's end on the rig's clock. [`Self::state_at`] and the
    /// truth are the camera's view: `camera_T_object` on the camera's clock. A rig camera with the identity mount and
    /// the rig's clock gives the frames of [`Self::new`].
    ///
    /// ```
    /// use roitrack_estimators::rig::{CameraMount, ClockModel, RigCamera};
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    /// let late = ClockModel { offset_s: 0.01, drift_ppm: 0.0 };
    /// let camera = RigCamera::known("late", scenario.camera.clone(), CameraMount::IDENTITY, late);
    /// let frames = FrameSequence::seen_by(&scenario, &camera, &FrameOptions::default()).unwrap();
    /// // Its frame at 1 s of its clock is the scene at 1.01 s of the rig's.
    /// assert_eq!(frames.state_at(1.0), scenario.state_at(1.01));
    /// ```
    pub fn seen_by(
        scenario: &Scenario,
        camera: &RigCamera,
        options: &FrameOptions,
    ) -> Result<Self, FrameSequenceError> {
        Self::with_view(
            scenario,
            &camera.camera,
            Some((camera.mount, camera.clock)),
            options,
        )
    }

    fn with_view(
        scenario: &Scenario,
        camera: &CameraModel,
        view: Option<(CameraMount, ClockModel)>,
        options: &FrameOptions,
    ) -> Result<Self, FrameSequenceError> {
        let (time, readout_s) = Self::check_timing(options, camera.height_px)?;
        // The scenario's end on the camera's clock.
        let end_s = view.map_or(scenario.duration_s, |(_, clock)| {
            clock.camera_time_s(scenario.duration_s)
        });
        let frame_count = Self::frame_count(camera.height_px, end_s, options, &time, readout_s)?;
        let &FrameOptions {
            polarity, sensor, ..
        } = options;
        let camera = CameraModel {
            time,
            ..camera.clone()
        };
        sensor.validate()?;
        let (render_sensor, light) = match polarity {
            Polarity::Bright => (sensor, Vec::new()),
            Polarity::Dark => (coverage_sensor(&sensor), light_field(&camera)),
        };
        let renderer = RoiRenderer::new(camera, scenario.target.clone(), render_sensor)?;
        Ok(Self {
            scenario: scenario.clone(),
            view,
            options: *options,
            frame_count,
            renderer,
            light,
            scratch: RenderScratch::new(),
            coverage: Frame::default(),
        })
    }

    /// The time model of `options` for a camera of `rows` rows, and its readout time (s), if every frame's exposure
    /// and readout fit in its period.
    fn check_timing(
        options: &FrameOptions,
        rows: u32,
    ) -> Result<(TimeModel, f64), FrameSequenceError> {
        let &FrameOptions {
            fps_hz,
            readout,
            exposure_s,
            start_s,
            ..
        } = options;
        if !(fps_hz.is_finite() && fps_hz > 0.0) {
            return Err(FrameSequenceError::FrameRate { fps_hz });
        }
        if !start_s.is_finite() {
            return Err(FrameSequenceError::StartTime { start_s });
        }
        let time = TimeModel {
            readout,
            exposure_s,
        };
        time.validate()?;
        let period_s = 1.0 / fps_hz;
        let readout_s = match readout {
            Readout::SequentialRois => return Err(FrameSequenceError::SequentialRois),
            Readout::GlobalShutter => 0.0,
            Readout::RollingShutter { line_delay_s } => {
                let readout_s = line_delay_s * f64::from(rows);
                if readout_s + exposure_s > period_s {
                    return Err(FrameSequenceError::ReadoutTooLong {
                        rows,
                        line_delay_s,
                        readout_s,
                        exposure_s,
                        period_s,
                        fps_hz,
                    });
                }
                readout_s
            }
        };
        if exposure_s > period_s {
            return Err(FrameSequenceError::ExposureTooLong {
                exposure_s,
                period_s,
                fps_hz,
            });
        }
        Ok((time, readout_s))
    }

    /// The number of frames: the given one, or every frame whose rows are all exposed by the scenario's end; at
    /// least 1 and at most `MAX_FRAMES`.
    fn frame_count(
        rows: u32,
        end_s: f64,
        options: &FrameOptions,
        time: &TimeModel,
        readout_s: f64,
    ) -> Result<usize, FrameSequenceError> {
        let &FrameOptions {
            fps_hz,
            start_s,
            frame_count,
            ..
        } = options;
        // The last row of a frame is at t_k + (rows - 1) * line_delay.
        let last_row_s = time.blob_time_s(0.0, f64::from(rows.saturating_sub(1)));
        let frame_count = frame_count.unwrap_or_else(|| {
            let room_s = end_s - start_s - last_row_s;
            if room_s < 0.0 {
                0
            } else {
                // A frame exactly at the end is kept despite rounding.
                (room_s * fps_hz + 1e-9).floor() as usize + 1
            }
        });
        if frame_count > MAX_FRAMES {
            return Err(FrameSequenceError::TooManyFrames {
                frame_count,
                fps_hz,
            });
        }
        if frame_count == 0 {
            return Err(FrameSequenceError::NoFrames {
                frame_count,
                start_s,
                duration_s: end_s,
                readout_s,
            });
        }
        Ok(frame_count)
    }

    /// Number of frames.
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let scenario = Scenario::new(ScenarioKind::Static, 1);
    /// let options = FrameOptions { fps_hz: 10.0, start_s: 0.5, ..FrameOptions::default() };
    /// // 0.5 s to the scenario's end (1 s) at 10 fps, both ends included.
    /// assert_eq!(FrameSequence::new(&scenario, &options).unwrap().len(), 6);
    /// ```
    pub fn len(&self) -> usize {
        self.frame_count
    }

    /// Always `false`: a sequence has at least one frame.
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &FrameOptions::default()).unwrap();
    /// assert!(!frames.is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.frame_count == 0
    }

    /// The camera the frames are taken with: the scenario's, with the sequence's time model (shutter, exposure).
    /// Track the frames with this camera, so that each blob is timed as it was rendered.
    ///
    /// ```
    /// use roitrack_core::time::Readout;
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let readout = Readout::RollingShutter { line_delay_s: 20e-6 };
    /// let options = FrameOptions { readout, exposure_s: 2e-3, ..FrameOptions::default() };
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &options).unwrap();
    /// assert_eq!(frames.camera().time.readout, readout);
    /// assert_eq!(frames.camera().time.exposure_s, 2e-3);
    /// assert_eq!(frames.camera().width_px, 1024);
    /// ```
    pub fn camera(&self) -> &CameraModel {
        self.renderer.camera()
    }

    /// The scenario the frames are taken of (its own camera keeps its own time model; see [`Self::camera`]).
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Spin, 1), &FrameOptions::default()).unwrap();
    /// assert_eq!(frames.scenario().kind, ScenarioKind::Spin);
    /// ```
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The options the sequence was made with (`frame_count` as given; [`Self::len`] is the number of frames).
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let options = FrameOptions { seed: 9, ..FrameOptions::default() };
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &options).unwrap();
    /// assert_eq!(frames.options(), &options);
    /// ```
    pub fn options(&self) -> &FrameOptions {
        &self.options
    }

    /// The time of frame `k` (s): the mid-exposure time of its row 0, `start_s + k / fps_hz`.
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let options = FrameOptions { fps_hz: 25.0, start_s: 0.1, ..FrameOptions::default() };
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &options).unwrap();
    /// assert!((frames.frame_time_s(5) - 0.3).abs() < 1e-12);
    /// ```
    pub fn frame_time_s(&self, k: usize) -> f64 {
        self.options.start_s + k as f64 / self.options.fps_hz
    }

    /// The interval (s) holding every blob time of the sequence: from frame 0's time to the time of the last
    /// frame's last row.
    ///
    /// ```
    /// use roitrack_core::time::Readout;
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let readout = Readout::RollingShutter { line_delay_s: 10e-6 };
    /// let options = FrameOptions { readout, frame_count: Some(3), ..FrameOptions::default() };
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &options).unwrap();
    /// let (start, end) = frames.span_s();
    /// assert_eq!(start, 0.0);
    /// assert!((end - (2.0 / 30.0 + 1023.0 * 10e-6)).abs() < 1e-12);
    /// ```
    pub fn span_s(&self) -> (f64, f64) {
        let rows = f64::from(self.camera().height_px.saturating_sub(1));
        let end = self.frame_time_s(self.frame_count - 1);
        (
            self.frame_time_s(0),
            self.camera().time.blob_time_s(end, rows),
        )
    }

    /// The true state at `t_s` (the scenario's; for [`Self::seen_by`], as the rig's camera sees it at `t_s` of its
    /// clock).
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    /// let frames = FrameSequence::new(&scenario, &FrameOptions::default()).unwrap();
    /// assert_eq!(frames.state_at(2.0), scenario.state_at(2.0));
    /// ```
    pub fn state_at(&self, t_s: f64) -> MotionState {
        view_state(&self.scenario, self.view.as_ref(), t_s)
    }

    /// Renders frame `k` into `frame` (resized to the camera and the sensor's bit depth; `frame.t_s` is the frame's
    /// time). The pixels depend only on the options and `k`; the buffers of the previous frames are reused.
    ///
    /// # Panics
    /// If `k >= self.len()`.
    ///
    /// ```
    /// use roitrack_image::Frame;
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    /// let mut frames = FrameSequence::new(&scenario, &FrameOptions::default()).unwrap();
    /// let (mut a, mut b) = (Frame::default(), Frame::default());
    /// frames.render(3, &mut a);
    /// frames.render(4, &mut b);
    /// frames.render(3, &mut b);
    /// assert_eq!(a, b);
    /// ```
    pub fn render(&mut self, k: usize, frame: &mut Frame) {
        assert!(
            k < self.frame_count,
            "frame {k} of a sequence of {}",
            self.frame_count
        );
        let t_s = self.frame_time_s(k);
        let mut rng = ChaCha8Rng::seed_from_u64(self.options.seed ^ FRAME_SEED_SALT);
        rng.set_stream(k as u64);
        let scenario = &self.scenario;
        let view = self.view.as_ref();
        let state_at = |t: f64| view_state(scenario, view, t);
        match self.options.polarity {
            Polarity::Bright => {
                self.renderer
                    .render_frame(&state_at, t_s, &mut rng, &mut self.scratch, frame);
            }
            Polarity::Dark => {
                // Noiseless: draws nothing from the generator.
                self.renderer.render_frame(
                    &state_at,
                    t_s,
                    &mut rng,
                    &mut self.scratch,
                    &mut self.coverage,
                );
                let sensor = &self.options.sensor;
                let camera = self.renderer.camera();
                frame.resize(camera.width_px, camera.height_px, sensor.bit_depth as u8);
                frame.t_s = t_s;
                let paper_e = sensor.background_e + sensor.blob_signal_e;
                for ((out, &coverage), &light) in frame
                    .pixels
                    .iter_mut()
                    .zip(&self.coverage.pixels)
                    .zip(&self.light)
                {
                    let ink = DARK_BLOB_CONTRAST * f64::from(coverage) / COVERAGE_FULL_SCALE;
                    let mean_e = paper_e * f64::from(light) * (1.0 - ink);
                    *out = sensor.quantise(sensor.sample_electrons(mean_e, &mut rng));
                }
            }
        }
    }

    /// Each visible blob's true image centre (raw pixels) at its own time in frame `k`, as a [`Measurement`]: for a
    /// rolling shutter the time of the row the centre is on (found by iterating time from row and row from time),
    /// for a global shutter the frame's time. The centre is that of the disk's perspective image
    /// ([`RoiRenderer::disk_image_centre_px`]); a blob is visible when its centre is on the sensor. In target order.
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Static, 1), &FrameOptions::default()).unwrap();
    /// let blobs = frames.true_blob_centres(2);
    /// assert_eq!(blobs.len(), 16);
    /// assert!(blobs.iter().all(|b| b.t_s == frames.frame_time_s(2)));
    /// ```
    pub fn true_blob_centres(&self, k: usize) -> Vec<Measurement> {
        let t_frame_s = self.frame_time_s(k);
        let camera = self.renderer.camera();
        let time = camera.time;
        let mut blobs = Vec::with_capacity(self.scenario.target.len());
        for (index, point) in self.scenario.target.points().iter().enumerate() {
            let centre_at = |t: f64| self.renderer.disk_image_centre_px(&self.state_at(t), index);
            let Some(mut centre) = centre_at(t_frame_s) else {
                continue;
            };
            let mut t_s = t_frame_s;
            if time.is_rolling() {
                for _ in 0..ROW_TIME_ITERATIONS {
                    t_s = time.blob_time_s(t_frame_s, centre.y);
                    let Some(next) = centre_at(t_s) else { break };
                    let moved_px = (next.y - centre.y).abs();
                    centre = next;
                    if moved_px < 1e-9 {
                        break;
                    }
                }
                t_s = time.blob_time_s(t_frame_s, centre.y);
            }
            if camera.contains_raw_pixel(&Vector2::new(centre.x, centre.y)) {
                blobs.push(Measurement {
                    t_s,
                    id: point.id,
                    u_px: centre.x,
                    v_px: centre.y,
                });
            }
        }
        blobs
    }

    /// The true poses and twists over [`Self::span_s`], at `rate_hz` (from the span's start) and at every frame's
    /// time and the span's end, so that linear (slerp) interpolation gives the truth at any time of the span; use
    /// [`DEFAULT_TRUTH_RATE_HZ`]. Refuses a rate that is not finite and positive.
    ///
    /// ```
    /// use roitrack_sim::{DEFAULT_TRUTH_RATE_HZ, FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    /// let frames = FrameSequence::new(&scenario, &FrameOptions::default()).unwrap();
    /// let truth = frames.truth_samples(DEFAULT_TRUTH_RATE_HZ).unwrap();
    /// let (start, end) = frames.span_s();
    /// assert_eq!((truth.poses[0].t_s, truth.poses.last().unwrap().t_s), (start, end));
    /// assert!(truth.poses.windows(2).all(|w| w[1].t_s - w[0].t_s <= 1.0 / DEFAULT_TRUTH_RATE_HZ + 1e-12));
    /// ```
    pub fn truth_samples(&self, rate_hz: f64) -> Result<FrameTruth, FrameSequenceError> {
        let mut truth = FrameTruth {
            poses: Vec::new(),
            twists: Vec::new(),
        };
        for (pose, twist) in self.truth_iter(rate_hz)? {
            truth.poses.push(pose);
            truth.twists.push(twist);
        }
        Ok(truth)
    }

    /// The samples of [`Self::truth_samples`], one at a time (in constant memory, for long sequences): the regular
    /// grid and the frames' times merged in order, a time within 1e-9 s of the one before left out.
    ///
    /// ```
    /// use roitrack_sim::{FrameOptions, FrameSequence, Scenario, ScenarioKind};
    ///
    /// let frames = FrameSequence::new(&Scenario::new(ScenarioKind::Sweep, 1), &FrameOptions::default()).unwrap();
    /// let streamed: Vec<_> = frames.truth_iter(2000.0).unwrap().map(|(pose, _)| pose).collect();
    /// assert_eq!(streamed, frames.truth_samples(2000.0).unwrap().poses);
    /// ```
    pub fn truth_iter(
        &self,
        rate_hz: f64,
    ) -> Result<impl Iterator<Item = (PoseSample, TwistSample)> + '_, FrameSequenceError> {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(FrameSequenceError::TruthRate { rate_hz });
        }
        let (start_s, end_s) = self.span_s();
        let regular = ((end_s - start_s) * rate_hz).floor() as usize;
        // The regular grid stops short of the end so that the end itself is never the duplicate dropped below.
        let mut grid = (0..=regular)
            .map(move |i| start_s + i as f64 / rate_hz)
            .filter(move |t| *t < end_s - 1e-9)
            .peekable();
        let mut frames = (0..self.frame_count)
            .map(|k| self.frame_time_s(k))
            .chain(std::iter::once(end_s))
            .peekable();
        let mut last: Option<f64> = None;
        let times = std::iter::from_fn(move || {
            loop {
                // The smaller of the two heads (both sequences increase), as a sort of their union would give.
                let t_s = match (grid.peek(), frames.peek()) {
                    (Some(&g), Some(&f)) if g.total_cmp(&f).is_le() => grid.next(),
                    (Some(_), Some(_)) | (None, Some(_)) => frames.next(),
                    (Some(_), None) => grid.next(),
                    (None, None) => None,
                }?;
                // A frame time on the regular grid would repeat a sample (up to rounding).
                if last.is_some_and(|previous| t_s - previous < 1e-9) {
                    continue;
                }
                last = Some(t_s);
                return Some(t_s);
            }
        });
        Ok(times.map(|t_s| {
            let state = self.state_at(t_s);
            (
                PoseSample::from_state(t_s, &state),
                TwistSample::from_state(t_s, &state),
            )
        }))
    }
}

/// The state of `scenario` that its camera sees at `t_s`, or with `view` a rig's camera (its mount and clock) at
/// `t_s` of its own clock: the twist as the camera's clock measures it.
fn view_state(
    scenario: &Scenario,
    view: Option<&(CameraMount, ClockModel)>,
    t_s: f64,
) -> MotionState {
    let Some((mount, clock)) = view else {
        return scenario.state_at(t_s);
    };
    let mut state = mount.camera_state(&scenario.state_at(clock.rig_time_s(t_s)));
    // d t_rig / d t_camera.
    let rate = 1.0 / (1.0 + clock.drift_ppm * 1e-6);
    state.velocity_mps *= rate;
    state.angular_velocity_radps *= rate;
    state
}

/// A noiseless sensor that writes a pixel's blurred blob coverage (0..1) as 0..65535, with the optics and sampling
/// of `sensor`.
fn coverage_sensor(sensor: &SensorModel) -> SensorModel {
    SensorModel {
        full_well_e: COVERAGE_FULL_SCALE,
        read_noise_e: 0.0,
        shot_noise: false,
        blob_signal_e: COVERAGE_FULL_SCALE,
        background_e: 0.0,
        bit_depth: 16,
        ..*sensor
    }
}

/// Relative light (0..1) on the paper at every pixel of `camera`'s image, row-major.
fn light_field(camera: &CameraModel) -> Vec<f32> {
    let (w, h) = (camera.width_px as usize, camera.height_px as usize);
    let mut light = Vec::with_capacity(w * h);
    for j in 0..h {
        light.extend((0..w).map(|i| light_at(i as f64, j as f64, w as f64, h as f64) as f32));
    }
    light
}

/// Relative light at pixel (u, v) of a `w` x `h` image: a lamp off to the top left (the light falls linearly to half
/// at the bottom-right corner), a broad vignetting (0.8 in the corners), and the soft shadow of something between the
/// lamp and the paper, a band crossing the image from the top edge (at 62 % of the width) to the bottom edge (at 12
/// %), light down to 0.65 on its axis, a Gaussian across of 7 % of the image's height.
fn light_at(u: f64, v: f64, w: f64, h: f64) -> f64 {
    let (x, y) = (u / (w - 1.0).max(1.0), v / (h - 1.0).max(1.0));
    let gradient = 1.0 - 0.5 * (0.7 * x + 0.3 * y);
    // 0 at the centre, 1 in the corners.
    let corner2 = ((x - 0.5).powi(2) + (y - 0.5).powi(2)) / 0.5;
    let vignetting = 1.0 - 0.2 * corner2;
    // Distance (px) from the band's axis, through (0.62 w, 0) and (0.12 w, h).
    let (ax, ay) = (-0.5 * w, h);
    let norm = ax.hypot(ay);
    let distance_px = ((u - 0.62 * w) * ay - v * ax) / norm;
    let sigma_px = 0.07 * w.min(h);
    let shadow = 1.0 - 0.35 * (-0.5 * (distance_px / sigma_px).powi(2)).exp();
    gradient * vignetting * shadow
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rig_camera_at_the_origin_on_the_rigs_clock_takes_the_scenarios_frames() {
        let scenario = Scenario::new(crate::ScenarioKind::Orthoglide, 1);
        let options = FrameOptions {
            frame_count: Some(3),
            ..FrameOptions::default()
        };
        let camera = RigCamera::known(
            "only",
            scenario.camera.clone(),
            CameraMount::IDENTITY,
            ClockModel::REFERENCE,
        );
        let mut own = FrameSequence::new(&scenario, &options).unwrap();
        let mut rig = FrameSequence::seen_by(&scenario, &camera, &options).unwrap();
        let (mut a, mut b) = (Frame::default(), Frame::default());
        for k in 0..3 {
            own.render(k, &mut a);
            rig.render(k, &mut b);
            assert_eq!(a, b);
            assert_eq!(own.true_blob_centres(k), rig.true_blob_centres(k));
        }
        // Without a frame count, the frames of a late clock end earlier on its own clock.
        let late = RigCamera {
            clock: ClockModel {
                offset_s: 0.1,
                drift_ppm: 0.0,
            },
            ..camera
        };
        let all = FrameSequence::new(&scenario, &FrameOptions::default()).unwrap();
        let late = FrameSequence::seen_by(&scenario, &late, &FrameOptions::default()).unwrap();
        assert_eq!(late.len(), all.len() - 3);
    }

    #[test]
    fn light_falls_by_half_across_the_image() {
        let (w, h) = (1024.0, 1024.0);
        let tl = light_at(0.0, 0.0, w, h);
        let br = light_at(w - 1.0, h - 1.0, w, h);
        assert!((tl / br - 2.0).abs() < 0.05, "{tl} / {br}");
        // The shadow's axis at mid-height is darker than a point 300 px to its right.
        let axis_u = 0.62 * w - 0.25 * w;
        assert!(light_at(axis_u, 512.0, w, h) < 0.8 * light_at(axis_u + 300.0, 512.0, w, h));
        for (u, v) in [(0.0, 0.0), (512.0, 512.0), (1023.0, 0.0), (0.0, 1023.0)] {
            let l = light_at(u, v, w, h);
            assert!(l > 0.0 && l <= 1.0);
        }
    }
}
