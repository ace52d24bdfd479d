//! Frame cameras on simulated image sequences: the frame tracker's accuracy on global- and rolling-shutter frames of
//! bright and dark blobs, each tracked with the right time model and (rolling frames) with the wrong one, and the
//! checks of the frame-camera targets (`roitrack frame-study`, the table of `docs/results.md`).
//!
//! Each sequence ([`FrameSequence`]) is rendered once per seed and tracked by a [`FrameTracker`] per time model
//! ([`CASES`]): the rolling-shutter frames are tracked both with the rolling model (each blob at its row's time) and
//! with the global model (every blob at the frame's time), so the two see the very same pixels. Every estimate is
//! scored by [`roitrack_eval`] against the true state at its own time (the mean time of the frame's blobs), except
//! the first [`FrameStudyOptions::settling_estimates`] of each run, while the velocity converges from a static start.
//! Figures of several seeds are pooled: an RMSE over all the scored estimates of every seed, the worst over all.
//!
//! The targets ([`FrameStudy::checks`]): on rolling-shutter frames the rolling model's position and velocity RMSE are
//! at most a third of the global model's, and within 1.5 times those of global-shutter frames of the same motion (or
//! [`POSITION_FLOOR_MM`], whichever is larger, for the position); dark blobs on a light, uneven background are within
//! twice the errors of bright ones.
//!
//! ```
//! use roitrack_experiments::frames::{FrameStudyOptions, frame_study};
//!
//! // Ten frames of one seed: a smoke run (the study proper takes the whole sweep, 181 frames, several seeds).
//! let options = FrameStudyOptions { seeds: vec![1], frame_count: Some(10), ..FrameStudyOptions::default() };
//! let study = frame_study(&options, None).unwrap();
//! assert_eq!(study.rows.len(), 6);
//! assert!(study.rows.iter().all(|row| row.estimates == 10));
//! assert!(study.markdown().contains("| sequence | model |"));
//! assert_eq!(study.checks().len(), 8);
//! ```

use std::fmt::Write as _;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use roitrack_core::time::Readout;
use roitrack_core::{PoseSample, TwistSample};
use roitrack_estimators::{ConfigError, Estimate, TrackStatus};
use roitrack_eval::{EvalError, EvalOptions, Metrics, PooledErrors, evaluate};
use roitrack_image::{Frame, Polarity};
use roitrack_pipeline::frames::{FrameError, FrameTracker, FrameTrackerConfig};
use roitrack_sim::{FrameOptions, FrameSequence, FrameSequenceError, Scenario, ScenarioKind};
use serde::Serialize;
use thiserror::Error;

/// Estimates left out at the start of each run: the track starts from a static pose found in the first frame, and
/// its velocity needs a few frames to converge (the tracker tests leave out as many).
///
/// ```
/// assert_eq!(roitrack_experiments::frames::SETTLING_ESTIMATES, 5);
/// ```
pub const SETTLING_ESTIMATES: usize = 5;

/// The position target of rolling frames against global ones is 1.5 times the global figure or this (mm), whichever
/// is larger: a floor under which a difference is no longer worth a target.
///
/// ```
/// assert_eq!(roitrack_experiments::frames::POSITION_FLOOR_MM, 0.2);
/// ```
pub const POSITION_FLOOR_MM: f64 = 0.2;

/// How a sequence's rows are read, or how a tracker assumes they are.
///
/// ```
/// use roitrack_core::time::Readout;
/// use roitrack_experiments::frames::Shutter;
///
/// assert_eq!(Shutter::Rolling.readout(30e-6), Readout::RollingShutter { line_delay_s: 30e-6 });
/// assert_eq!(Shutter::Global.name(), "global");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Shutter {
    /// Every row at the frame's time.
    Global,
    /// Row `v` at the frame's time plus `v` line delays.
    Rolling,
}

impl Shutter {
    /// `global` or `rolling`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Global => "global",
            Self::Rolling => "rolling",
        }
    }

    /// The readout of this shutter with `line_delay_s` between rows (ignored for a global shutter).
    pub fn readout(self, line_delay_s: f64) -> Readout {
        match self {
            Self::Global => Readout::GlobalShutter,
            Self::Rolling => Readout::RollingShutter { line_delay_s },
        }
    }
}

/// One row of the study: which frames (shutter, blobs) tracked with which time model.
///
/// ```
/// use roitrack_experiments::frames::{CASES, Shutter};
///
/// // The rolling-shutter frames of bright blobs tracked as if they came from a global shutter.
/// let case = CASES[2];
/// assert_eq!((case.shutter, case.model), (Shutter::Rolling, Shutter::Global));
/// assert_eq!(case.sequence_label(), "rolling shutter, bright");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct FrameCase {
    /// The sequence's shutter.
    pub shutter: Shutter,
    /// The sequence's blobs: bright, or dark on a light, uneven background.
    #[serde(serialize_with = "serialize_polarity")]
    pub polarity: Polarity,
    /// The time model the tracker is given.
    pub model: Shutter,
}

fn serialize_polarity<S: serde::Serializer>(p: &Polarity, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(p.name())
}

impl FrameCase {
    /// `global shutter, bright`, `rolling shutter, dark`, ...
    pub fn sequence_label(&self) -> String {
        format!("{} shutter, {}", self.shutter.name(), self.polarity.name())
    }
}

const fn case(shutter: Shutter, polarity: Polarity, model: Shutter) -> FrameCase {
    FrameCase {
        shutter,
        polarity,
        model,
    }
}

/// The cases, in the table's order: each sequence with its own model, and the rolling-shutter sequences also with
/// the global model (the error the rolling model removes).
///
/// ```
/// use roitrack_experiments::frames::{CASES, Shutter};
///
/// assert_eq!(CASES.len(), 6);
/// assert_eq!(CASES.iter().filter(|c| c.shutter != c.model).count(), 2);
/// ```
pub const CASES: [FrameCase; 6] = [
    case(Shutter::Global, Polarity::Bright, Shutter::Global),
    case(Shutter::Rolling, Polarity::Bright, Shutter::Rolling),
    case(Shutter::Rolling, Polarity::Bright, Shutter::Global),
    case(Shutter::Global, Polarity::Dark, Shutter::Global),
    case(Shutter::Rolling, Polarity::Dark, Shutter::Rolling),
    case(Shutter::Rolling, Polarity::Dark, Shutter::Global),
];

const GLOBAL_BRIGHT: FrameCase = CASES[0];
const ROLLING_BRIGHT: FrameCase = CASES[1];
const ROLLING_BRIGHT_GLOBAL_MODEL: FrameCase = CASES[2];
const GLOBAL_DARK: FrameCase = CASES[3];
const ROLLING_DARK: FrameCase = CASES[4];

/// What the study runs.
///
/// ```
/// use roitrack_experiments::frames::FrameStudyOptions;
/// use roitrack_sim::ScenarioKind;
///
/// let options = FrameStudyOptions::default();
/// assert_eq!(options.scenario, ScenarioKind::Sweep);
/// assert_eq!((options.seeds.clone(), options.fps_hz, options.line_delay_s), (vec![1, 2, 3], 30.0, 30e-6));
/// // 6 s at 30 Hz, every row of the last frame exposed within the sweep.
/// assert_eq!(options.frames_per_sequence().unwrap(), 180);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct FrameStudyOptions {
    /// The motion. Default [`ScenarioKind::Sweep`] (0.5 m/s, 1.5 rad/s: what a 30 Hz camera can follow).
    pub scenario: ScenarioKind,
    /// Each seed is a motion (the sweep is random) and the noise of its frames. Default 1, 2, 3.
    pub seeds: Vec<u64>,
    /// Frames per second. Default 30.
    pub fps_hz: f64,
    /// The rolling shutter's time between rows (s). Default 30 µs (1,024 rows in 30.7 ms).
    pub line_delay_s: f64,
    /// Exposure of each row (s). Default 1 ms.
    pub exposure_s: f64,
    /// Frames per sequence; `None` (the default): as many as every sequence has (the rolling one's last frame must
    /// be read out within the scenario), the same for all so that they are compared on the same motion.
    pub frame_count: Option<usize>,
    /// Estimates left out at the start of each run. Default [`SETTLING_ESTIMATES`].
    pub settling_estimates: usize,
    /// Sequences rendered and tracked at once. Default: the machine's cores.
    pub threads: usize,
}

impl Default for FrameStudyOptions {
    fn default() -> Self {
        Self {
            scenario: ScenarioKind::Sweep,
            seeds: vec![1, 2, 3],
            fps_hz: 30.0,
            line_delay_s: 30e-6,
            exposure_s: 1e-3,
            frame_count: None,
            settling_estimates: SETTLING_ESTIMATES,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        }
    }
}

/// The sequences of a seed: every shutter and polarity of [`CASES`], in their order.
fn sequences() -> Vec<(Shutter, Polarity)> {
    let mut out: Vec<(Shutter, Polarity)> = Vec::new();
    for c in CASES {
        if !out.contains(&(c.shutter, c.polarity)) {
            out.push((c.shutter, c.polarity));
        }
    }
    out
}

impl FrameStudyOptions {
    /// The options of the sequence of `seed` with this shutter and blobs (`frame_count` as in `self`).
    fn frame_options(&self, seed: u64, shutter: Shutter, polarity: Polarity) -> FrameOptions {
        FrameOptions {
            fps_hz: self.fps_hz,
            readout: shutter.readout(self.line_delay_s),
            exposure_s: self.exposure_s,
            polarity,
            seed,
            frame_count: self.frame_count,
            ..FrameOptions::default()
        }
    }

    fn sequence(
        &self,
        seed: u64,
        shutter: Shutter,
        polarity: Polarity,
        frame_count: usize,
    ) -> Result<FrameSequence, FrameStudyError> {
        let options = FrameOptions {
            frame_count: Some(frame_count),
            ..self.frame_options(seed, shutter, polarity)
        };
        FrameSequence::new(&Scenario::new(self.scenario, seed), &options)
            .map_err(|source| FrameStudyError::Sequence { seed, source })
    }

    /// Frames in each sequence: [`Self::frame_count`] if given, else the fewest any sequence has. Fails like [`FrameSequence::new`] (a readout too long for the frame rate, say) and without seeds.
    pub fn frames_per_sequence(&self) -> Result<usize, FrameStudyError> {
        let mut fewest = usize::MAX;
        if self.seeds.is_empty() {
            return Err(FrameStudyError::NoSeeds);
        }
        for &seed in &self.seeds {
            let scenario = Scenario::new(self.scenario, seed);
            for (shutter, polarity) in sequences() {
                let options = self.frame_options(seed, shutter, polarity);
                let sequence = FrameSequence::new(&scenario, &options)
                    .map_err(|source| FrameStudyError::Sequence { seed, source })?;
                fewest = fewest.min(sequence.len());
            }
        }
        Ok(fewest)
    }

    /// Frames rendered (and tracked) by the whole study: for a progress bar.
    ///
    /// ```
    /// use roitrack_experiments::frames::FrameStudyOptions;
    ///
    /// let options = FrameStudyOptions { seeds: vec![4, 5], frame_count: Some(20), ..FrameStudyOptions::default() };
    /// assert_eq!(options.total_frames().unwrap(), 2 * 4 * 20);
    /// ```
    pub fn total_frames(&self) -> Result<usize, FrameStudyError> {
        Ok(self.frames_per_sequence()? * sequences().len() * self.seeds.len())
    }
}

/// Why the study could not run.
///
/// ```
/// use roitrack_experiments::frames::{FrameStudyError, FrameStudyOptions, frame_study};
///
/// // 60 frames a second leave no time for a 30.7 ms rolling readout.
/// let options = FrameStudyOptions { fps_hz: 60.0, ..FrameStudyOptions::default() };
/// let error = frame_study(&options, None).unwrap_err();
/// assert!(matches!(error, FrameStudyError::Sequence { seed: 1, .. }));
/// assert!(error.to_string().contains("lower the frame rate"));
/// ```
#[derive(Debug, Error)]
pub enum FrameStudyError {
    /// The options list no seed.
    #[error("no seed given")]
    NoSeeds,
    /// Zero threads asked for.
    #[error("the study needs at least one thread")]
    NoThreads,
    /// A seed's frame sequence could not be simulated.
    #[error("seed {seed}: {source}")]
    Sequence {
        /// The seed.
        seed: u64,
        /// Why the sequence was refused.
        #[source]
        source: FrameSequenceError,
    },
    /// The frame tracker refused its configuration.
    #[error("the frame tracker: {0}")]
    Tracker(#[from] ConfigError),
    /// The frame tracker failed on a frame.
    #[error("seed {seed}, {sequence} frames, {model} model: frame {frame}: {source}")]
    Frame {
        /// The seed.
        seed: u64,
        /// The sequence's shutter and blobs ([`FrameCase::sequence_label`]).
        sequence: String,
        /// The name of the time model the tracker was given.
        model: &'static str,
        /// The frame's index in the sequence, from 0.
        frame: usize,
        /// What failed.
        #[source]
        source: FrameError,
    },
    /// The estimates could not be scored against the truth.
    #[error("evaluation failed: {0}")]
    Evaluation(#[from] EvalError),
    /// A worker thread panicked.
    #[error("a worker thread panicked")]
    Panicked,
}

/// One case tracked on one seed's sequence.
///
/// ```
/// use roitrack_experiments::frames::{FrameStudyOptions, frame_study};
///
/// let options = FrameStudyOptions { seeds: vec![7], frame_count: Some(8), ..FrameStudyOptions::default() };
/// let study = frame_study(&options, None).unwrap();
/// let run = &study.runs[0];
/// assert_eq!((run.seed, run.frames, run.estimates, run.scored), (7, 8, 8, 3));
/// assert_eq!(run.by_windows + run.by_full_frame + run.restarts + run.not_found, 8);
/// ```
#[derive(Debug, Clone, Serialize)]
pub struct FrameRun {
    /// The case tracked.
    pub case: FrameCase,
    /// The seed of the sequence.
    pub seed: u64,
    /// Frames in the sequence.
    pub frames: usize,
    /// Estimates given (at most one per frame).
    pub estimates: usize,
    /// Estimates scored: those after the first `settling_estimates`.
    pub scored: usize,
    /// Estimates whose status is neither tracking nor converging (degenerate, disputed, lost).
    pub flagged: usize,
    /// The scored estimates' metrics (`None` when none is scored).
    pub metrics: Option<Metrics>,
    /// Frames measured in windows around the predicted blobs.
    pub by_windows: usize,
    /// Frames measured by a full-frame search continuing the track.
    pub by_full_frame: usize,
    /// Frames measured by a full-frame search starting a new track.
    pub restarts: usize,
    /// Frames where the target was not found.
    pub not_found: usize,
    /// Wall time of the tracker's processing of the frames (s), rendering not included.
    pub tracking_s: f64,
}

/// Sums of one or more runs' figures, and their errors pooled.
#[derive(Debug, Clone, Copy)]
struct Pool {
    frames: usize,
    estimates: usize,
    errors: PooledErrors,
    by_windows: usize,
    by_full_frame: usize,
    restarts: usize,
    not_found: usize,
    tracking_s: f64,
}

impl Pool {
    fn of<'a>(runs: impl IntoIterator<Item = &'a FrameRun> + Clone) -> Self {
        let sum = |f: fn(&FrameRun) -> usize| runs.clone().into_iter().map(f).sum();
        Self {
            frames: sum(|r| r.frames),
            estimates: sum(|r| r.estimates),
            errors: PooledErrors::of(runs.clone().into_iter().filter_map(|r| r.metrics.as_ref())),
            by_windows: sum(|r| r.by_windows),
            by_full_frame: sum(|r| r.by_full_frame),
            restarts: sum(|r| r.restarts),
            not_found: sum(|r| r.not_found),
            tracking_s: runs.into_iter().map(|r| r.tracking_s).sum(),
        }
    }

    fn row(&self, case: FrameCase) -> FrameStudyRow {
        FrameStudyRow {
            case,
            frames: self.frames,
            estimates: self.estimates,
            scored: self.errors.count,
            position_rmse_mm: self.errors.position_rmse_mm,
            velocity_rmse_mm_s: self.errors.velocity_rmse_mm_s,
            rotation_rmse_deg: self.errors.rotation_rmse_deg,
            worst_position_mm: self.errors.max_position_error_mm,
            by_windows: self.by_windows,
            by_full_frame: self.by_full_frame,
            restarts: self.restarts,
            not_found: self.not_found,
            ms_per_frame: 1e3 * self.tracking_s / self.frames.max(1) as f64,
        }
    }
}

/// One case over every seed: counts summed, RMSEs pooled over the scored estimates of every seed.
///
/// ```
/// use roitrack_experiments::frames::{FrameStudyOptions, frame_study};
///
/// let options = FrameStudyOptions { seeds: vec![1, 2], frame_count: Some(8), ..FrameStudyOptions::default() };
/// let study = frame_study(&options, None).unwrap();
/// let row = &study.rows[0];
/// assert_eq!((row.frames, row.scored), (16, 6));
/// // The pooled RMSE lies between the seeds' own.
/// let own: Vec<f64> = study.runs[..2].iter().map(|r| r.metrics.as_ref().unwrap().position_rmse_mm).collect();
/// assert!(row.position_rmse_mm >= own[0].min(own[1]) && row.position_rmse_mm <= own[0].max(own[1]));
/// ```
#[derive(Debug, Clone, Serialize)]
pub struct FrameStudyRow {
    /// The case.
    pub case: FrameCase,
    /// Frames, over every seed.
    pub frames: usize,
    /// Estimates given, over every seed.
    pub estimates: usize,
    /// Estimates scored, over every seed.
    pub scored: usize,
    /// RMS position error over the scored estimates of every seed (mm).
    pub position_rmse_mm: f64,
    /// RMS velocity error over the scored estimates of every seed (mm/s).
    pub velocity_rmse_mm_s: f64,
    /// RMS rotation error over the scored estimates of every seed (degrees).
    pub rotation_rmse_deg: f64,
    /// Largest position error of a scored estimate (mm).
    pub worst_position_mm: f64,
    /// Frames measured in windows, over every seed.
    pub by_windows: usize,
    /// Frames measured by a full-frame search continuing the track, over every seed.
    pub by_full_frame: usize,
    /// Frames measured by a full-frame search starting a new track, over every seed.
    pub restarts: usize,
    /// Frames where the target was not found, over every seed.
    pub not_found: usize,
    /// Tracking time per frame (ms): the frame tracker's processing only, one thread.
    pub ms_per_frame: f64,
}

/// Which error a check compares.
///
/// ```
/// use roitrack_experiments::frames::Quantity;
///
/// assert_eq!((Quantity::Velocity.name(), Quantity::Velocity.unit()), ("velocity", "mm/s"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Quantity {
    /// Position RMSE (mm).
    Position,
    /// Linear velocity RMSE (mm/s).
    Velocity,
}

impl Quantity {
    fn of(self, row: &FrameStudyRow) -> f64 {
        match self {
            Self::Position => row.position_rmse_mm,
            Self::Velocity => row.velocity_rmse_mm_s,
        }
    }

    /// `mm` or `mm/s`.
    pub fn unit(self) -> &'static str {
        match self {
            Self::Position => "mm",
            Self::Velocity => "mm/s",
        }
    }

    /// `position` or `velocity`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Position => "position",
            Self::Velocity => "velocity",
        }
    }
}

/// A target: `quantity` of `case` at most `factor` times that of `reference`, or `floor`, whichever is larger.
struct Target {
    what: &'static str,
    case: FrameCase,
    reference: FrameCase,
    quantity: Quantity,
    factor: f64,
    floor: f64,
}

fn targets() -> Vec<Target> {
    let mut out = Vec::new();
    for quantity in [Quantity::Position, Quantity::Velocity] {
        out.push(Target {
            what: "rolling frames: rolling model <= 1/3 of the global model",
            case: ROLLING_BRIGHT,
            reference: ROLLING_BRIGHT_GLOBAL_MODEL,
            quantity,
            factor: 1.0 / 3.0,
            floor: 0.0,
        });
    }
    for (quantity, floor) in [
        (Quantity::Position, POSITION_FLOOR_MM),
        (Quantity::Velocity, 0.0),
    ] {
        out.push(Target {
            what: if floor > 0.0 {
                "rolling frames, rolling model: <= 1.5x global-shutter frames or 0.2 mm"
            } else {
                "rolling frames, rolling model: <= 1.5x global-shutter frames"
            },
            case: ROLLING_BRIGHT,
            reference: GLOBAL_BRIGHT,
            quantity,
            factor: 1.5,
            floor,
        });
    }
    for (what, case, reference) in [
        (
            "dark blobs <= 2x bright, global shutter",
            GLOBAL_DARK,
            GLOBAL_BRIGHT,
        ),
        (
            "dark blobs <= 2x bright, rolling shutter (rolling model)",
            ROLLING_DARK,
            ROLLING_BRIGHT,
        ),
    ] {
        for quantity in [Quantity::Position, Quantity::Velocity] {
            out.push(Target {
                what,
                case,
                reference,
                quantity,
                factor: 2.0,
                floor: 0.0,
            });
        }
    }
    out
}

/// A target checked on the pooled figures, and on each seed alone.
///
/// ```
/// use roitrack_experiments::frames::{FrameStudyOptions, Quantity, frame_study};
///
/// let options = FrameStudyOptions { seeds: vec![1], frame_count: Some(8), ..FrameStudyOptions::default() };
/// let checks = frame_study(&options, None).unwrap().checks();
/// // The first: the rolling model's position error on rolling frames, at most a third of the global model's.
/// let first = &checks[0];
/// assert_eq!(first.quantity, Quantity::Position);
/// assert!((first.limit - first.reference / 3.0).abs() <= 1e-12 * first.reference);
/// assert_eq!(first.holds, first.value <= first.limit);
/// assert_eq!(first.seeds, 1);
/// ```
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// What is compared with what.
    pub target: &'static str,
    /// Which error is compared.
    pub quantity: Quantity,
    /// The figure checked (pooled over the seeds).
    pub value: f64,
    /// The reference figure (pooled).
    pub reference: f64,
    /// The limit the reference gives: `max(factor * reference, floor)`.
    pub limit: f64,
    /// `value / reference`.
    pub ratio: f64,
    /// Whether `value <= limit` (pooled figures).
    pub holds: bool,
    /// Seeds on which the target holds.
    pub seeds_holding: usize,
    /// Seeds checked.
    pub seeds: usize,
}

/// The study's result: every run, the rows pooled over the seeds, and the options; [`Self::markdown`] and
/// [`Self::json`] show it.
///
/// ```
/// use roitrack_experiments::frames::{FrameStudyOptions, frame_study};
///
/// let options = FrameStudyOptions { seeds: vec![1], frame_count: Some(8), ..FrameStudyOptions::default() };
/// let study = frame_study(&options, None).unwrap();
/// assert_eq!(study.runs.len(), 6);
/// assert_eq!(study.table().lines().count(), 2 + 6);
/// assert_eq!(study.checks_table().lines().count(), 2 + 8);
/// assert!(study.description().starts_with("sweep scenario, seed 1: 8 frames"));
/// let json: serde_json::Value = serde_json::from_str(&study.json()).unwrap();
/// assert_eq!(json["rows"][1]["case"]["shutter"], "rolling");
/// assert_eq!(json["rows"][1]["case"]["polarity"], "bright");
/// ```
#[derive(Debug, Clone)]
pub struct FrameStudy {
    /// What was run.
    pub options: FrameStudyOptions,
    /// Frames per sequence.
    pub frames_per_sequence: usize,
    /// Every case on every seed, by case (in [`CASES`] order) then seed.
    pub runs: Vec<FrameRun>,
    /// One per case, in [`CASES`] order.
    pub rows: Vec<FrameStudyRow>,
}

/// Renders every sequence of [`FrameStudyOptions`] and tracks it with each model (see the [module docs](self)).
/// `progress`, when given, counts the frames done (of [`FrameStudyOptions::total_frames`]).
///
/// ```
/// use std::sync::atomic::{AtomicUsize, Ordering};
/// use roitrack_experiments::frames::{FrameStudyOptions, frame_study};
///
/// let options = FrameStudyOptions { seeds: vec![3], frame_count: Some(6), threads: 2, ..FrameStudyOptions::default() };
/// let done = AtomicUsize::new(0);
/// let study = frame_study(&options, Some(&done)).unwrap();
/// assert_eq!(done.load(Ordering::Relaxed), options.total_frames().unwrap());
/// assert_eq!(study.frames_per_sequence, 6);
/// ```
pub fn frame_study(
    options: &FrameStudyOptions,
    progress: Option<&AtomicUsize>,
) -> Result<FrameStudy, FrameStudyError> {
    if options.threads == 0 {
        return Err(FrameStudyError::NoThreads);
    }
    let frame_count = options.frames_per_sequence()?;
    let jobs: Vec<(u64, Shutter, Polarity)> = options
        .seeds
        .iter()
        .flat_map(|&seed| sequences().into_iter().map(move |(s, p)| (seed, s, p)))
        .collect();
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Result<Vec<FrameRun>, FrameStudyError>>> = Mutex::new(Vec::new());
    // Each worker takes the next sequence, renders it and tracks it with its models: sequences are independent and
    // a frame's pixels depend only on its index, so the figures do not depend on the number of threads.
    let workers = options.threads.min(jobs.len());
    let panicked = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                scope.spawn(|| {
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed);
                        let Some(&(seed, shutter, polarity)) = jobs.get(k) else {
                            break;
                        };
                        let result =
                            run_sequence(options, seed, shutter, polarity, frame_count, progress);
                        let failed = result.is_err();
                        results
                            .lock()
                            .expect("no worker panics holding the lock")
                            .push(result);
                        if failed {
                            // Leave the remaining sequences: the study has failed.
                            next.store(jobs.len(), Ordering::Relaxed);
                            break;
                        }
                    }
                })
            })
            .collect();
        handles.into_iter().any(|h| h.join().is_err())
    });
    if panicked {
        return Err(FrameStudyError::Panicked);
    }
    let mut runs = Vec::new();
    for result in results.into_inner().expect("the workers have ended") {
        runs.extend(result?);
    }
    let case_index = |c: &FrameCase| CASES.iter().position(|x| x == c).unwrap_or(usize::MAX);
    runs.sort_by_key(|r| (case_index(&r.case), r.seed));
    let rows = CASES
        .iter()
        .map(|&c| Pool::of(runs.iter().filter(|r| r.case == c)).row(c))
        .collect();
    Ok(FrameStudy {
        options: options.clone(),
        frames_per_sequence: frame_count,
        runs,
        rows,
    })
}

/// Renders one sequence and tracks it with each model of [`CASES`] for it, side by side, frame by frame.
fn run_sequence(
    options: &FrameStudyOptions,
    seed: u64,
    shutter: Shutter,
    polarity: Polarity,
    frame_count: usize,
    progress: Option<&AtomicUsize>,
) -> Result<Vec<FrameRun>, FrameStudyError> {
    let mut sequence = options.sequence(seed, shutter, polarity, frame_count)?;
    let cases: Vec<FrameCase> = CASES
        .into_iter()
        .filter(|c| (c.shutter, c.polarity) == (shutter, polarity))
        .collect();
    let mut trackers = Vec::with_capacity(cases.len());
    for c in &cases {
        let mut camera = sequence.camera().clone();
        camera.time.readout = c.model.readout(options.line_delay_s);
        let target = sequence.scenario().target.clone();
        trackers.push(FrameTracker::new(
            camera,
            target,
            FrameTrackerConfig::default(),
        )?);
    }
    let mut estimates: Vec<Vec<Estimate>> = vec![Vec::with_capacity(frame_count); cases.len()];
    let mut seconds = vec![0.0; cases.len()];
    let mut frame = Frame::default();
    for k in 0..sequence.len() {
        sequence.render(k, &mut frame);
        for (i, tracker) in trackers.iter_mut().enumerate() {
            let start = Instant::now();
            let outcome = tracker
                .process(&frame)
                .map_err(|source| FrameStudyError::Frame {
                    seed,
                    sequence: cases[i].sequence_label(),
                    model: cases[i].model.name(),
                    frame: k,
                    source,
                })?;
            seconds[i] += start.elapsed().as_secs_f64();
            estimates[i].extend(outcome.estimate);
        }
        if let Some(done) = progress {
            done.fetch_add(1, Ordering::Relaxed);
        }
    }
    let mut runs = Vec::with_capacity(cases.len());
    for (((c, tracker), estimates), tracking_s) in
        cases.iter().zip(&trackers).zip(estimates).zip(seconds)
    {
        let report = tracker.report();
        let scored = &estimates[estimates.len().min(options.settling_estimates)..];
        runs.push(FrameRun {
            case: *c,
            seed,
            frames: report.frames,
            estimates: estimates.len(),
            scored: scored.len(),
            flagged: estimates
                .iter()
                .filter(|e| !matches!(e.status, TrackStatus::Tracking | TrackStatus::Converging))
                .count(),
            metrics: score(&sequence, scored)?,
            by_windows: report.by_windows,
            by_full_frame: report.by_full_frame,
            restarts: report.restarts,
            not_found: report.not_found,
            tracking_s,
        });
    }
    debug_assert!(runs.iter().all(|r| r.frames == frame_count));
    Ok(runs)
}

/// The metrics of `estimates` against the true state at each one's own time (exact: no interpolation of the truth).
fn score(
    sequence: &FrameSequence,
    estimates: &[Estimate],
) -> Result<Option<Metrics>, FrameStudyError> {
    if estimates.is_empty() {
        return Ok(None);
    }
    let (poses, twists) = roitrack_eval::samples_of(estimates);
    let (truth_poses, truth_twists): (Vec<PoseSample>, Vec<TwistSample>) = estimates
        .iter()
        .map(|e| {
            let truth = sequence.state_at(e.t_ref_s);
            (
                PoseSample::from_state(e.t_ref_s, &truth),
                TwistSample::from_state(e.t_ref_s, &truth),
            )
        })
        .unzip();
    Ok(Some(evaluate(
        &truth_poses,
        Some(&truth_twists),
        &poses,
        Some(&twists),
        &EvalOptions::default(),
    )?))
}

impl FrameStudy {
    /// The pooled row of `case`.
    fn row(&self, case: FrameCase) -> Option<&FrameStudyRow> {
        self.rows.iter().find(|r| r.case == case)
    }

    /// The targets of the [module docs](self), each checked on the pooled figures and seed by seed.
    pub fn checks(&self) -> Vec<Check> {
        let seeds = &self.options.seeds;
        let per_seed: Vec<Vec<FrameStudyRow>> = seeds
            .iter()
            .map(|&seed| {
                CASES
                    .iter()
                    .map(|&c| {
                        Pool::of(self.runs.iter().filter(|r| r.case == c && r.seed == seed)).row(c)
                    })
                    .collect()
            })
            .collect();
        let limit = |t: &Target, reference: f64| (t.factor * reference).max(t.floor);
        let holds = |t: &Target, rows: &[FrameStudyRow]| {
            let find = |c: FrameCase| rows.iter().find(|r| r.case == c);
            match (find(t.case), find(t.reference)) {
                (Some(a), Some(b)) => t.quantity.of(a) <= limit(t, t.quantity.of(b)),
                _ => false,
            }
        };
        targets()
            .into_iter()
            .map(|t| {
                let value = self.row(t.case).map_or(f64::NAN, |r| t.quantity.of(r));
                let reference = self.row(t.reference).map_or(f64::NAN, |r| t.quantity.of(r));
                Check {
                    target: t.what,
                    quantity: t.quantity,
                    value,
                    reference,
                    limit: limit(&t, reference),
                    ratio: value / reference,
                    holds: holds(&t, &self.rows),
                    seeds_holding: per_seed.iter().filter(|rows| holds(&t, rows)).count(),
                    seeds: seeds.len(),
                }
            })
            .collect()
    }

    /// What was run, in one sentence.
    pub fn description(&self) -> String {
        let o = &self.options;
        let seeds: Vec<String> = o.seeds.iter().map(u64::to_string).collect();
        format!(
            "{} scenario, seed{} {}: {} frames a sequence at {} Hz (1024 x 1024 px, canonical camera, grid4x4 target), \
             exposure {} ms, rolling shutter {} µs a row; each estimate scored against the true state at its own \
             time, the first {} estimates of each run left out (the velocity converging from a static start); RMSEs \
             pooled over the seeds' scored estimates; tracking time per frame on one thread ({} sequence{} at once).",
            o.scenario.name(),
            if seeds.len() == 1 { "" } else { "s" },
            seeds.join(", "),
            self.frames_per_sequence,
            o.fps_hz,
            o.exposure_s * 1e3,
            o.line_delay_s * 1e6,
            o.settling_estimates,
            o.threads,
            if o.threads == 1 { "" } else { "s" },
        )
    }

    /// The rows as a markdown table.
    pub fn table(&self) -> String {
        let mut out = String::from(
            "| sequence | model | frames | estimates (scored) | position RMSE mm | velocity RMSE mm/s | rotation RMSE \
             deg | worst position mm | windows / full frame / restarts / not found | ms per frame |\n\
             |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for r in &self.rows {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} ({}) | {:.4} | {:.2} | {:.4} | {:.3} | {} / {} / {} / {} | {:.2} |",
                r.case.sequence_label(),
                r.case.model.name(),
                r.frames,
                r.estimates,
                r.scored,
                r.position_rmse_mm,
                r.velocity_rmse_mm_s,
                r.rotation_rmse_deg,
                r.worst_position_mm,
                r.by_windows,
                r.by_full_frame,
                r.restarts,
                r.not_found,
                r.ms_per_frame
            );
        }
        out
    }

    /// The checks as a markdown table.
    pub fn checks_table(&self) -> String {
        let mut out = String::from(
            "| target | figure | measured | reference | ratio | limit | holds | seeds holding |\n\
             |---|---|---:|---:|---:|---:|---|---:|\n",
        );
        for c in self.checks() {
            let unit = c.quantity.unit();
            let digits = if c.quantity == Quantity::Position {
                4
            } else {
                2
            };
            let _ = writeln!(
                out,
                "| {} | {} | {:.digits$} {unit} | {:.digits$} {unit} | {:.3} | {:.digits$} {unit} | {} | {}/{} |",
                c.target,
                c.quantity.name(),
                c.value,
                c.reference,
                c.ratio,
                c.limit,
                if c.holds { "yes" } else { "**no**" },
                c.seeds_holding,
                c.seeds
            );
        }
        out
    }

    /// Each case's position and velocity RMSE seed by seed, as a markdown table (what the checks' `seeds holding`
    /// count).
    pub fn per_seed_table(&self) -> String {
        let seeds = &self.options.seeds;
        let mut out = String::from("| sequence | model |");
        for seed in seeds {
            let _ = write!(out, " seed {seed}: mm, mm/s |");
        }
        out += "\n|---|---|";
        out += &"---:|".repeat(seeds.len());
        out += "\n";
        for c in CASES {
            let _ = write!(out, "| {} | {} |", c.sequence_label(), c.model.name());
            for &seed in seeds {
                let row =
                    Pool::of(self.runs.iter().filter(|r| r.case == c && r.seed == seed)).row(c);
                let _ = write!(
                    out,
                    " {:.4}, {:.2} |",
                    row.position_rmse_mm, row.velocity_rmse_mm_s
                );
            }
            out += "\n";
        }
        out
    }

    /// The description, the table, the checks and the figures seed by seed, in markdown.
    pub fn markdown(&self) -> String {
        let checks = self.checks();
        let failing = checks.iter().filter(|c| !c.holds).count();
        format!(
            "{}\n\n{}\n{}\n{}\n\nPosition and velocity RMSE seed by seed:\n\n{}",
            self.description(),
            self.table(),
            self.checks_table(),
            if failing == 0 {
                format!("All {} targets hold.", checks.len())
            } else {
                format!("{failing} of {} targets do not hold.", checks.len())
            },
            self.per_seed_table()
        )
    }

    /// Everything as one JSON object: `description`, `rows`, `checks` and `runs` (every case on every seed).
    pub fn json(&self) -> String {
        serde_json::json!({
            "description": self.description(),
            "frames_per_sequence": self.frames_per_sequence,
            "seeds": self.options.seeds,
            "rows": self.rows,
            "checks": self.checks(),
            "runs": self.runs,
        })
        .to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_case_has_its_sequence_and_the_targets_name_known_cases() {
        assert_eq!(sequences().len(), 4);
        for t in targets() {
            assert!(CASES.contains(&t.case) && CASES.contains(&t.reference));
        }
        assert_eq!(targets().len(), 8);
    }
}
