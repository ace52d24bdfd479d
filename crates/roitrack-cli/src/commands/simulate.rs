//! `roitrack simulate`: write a scenario's camera, target, measurements and ground truth (and optionally a recording
//! of rendered ROIs), or with `--frames` the full frames a global- or rolling-shutter camera takes of it.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, Result, anyhow, bail};
use clap::{Args, ValueEnum};
use roitrack::core::RoiOrder;
use roitrack::core::time::Readout;
use roitrack::estimators::rig::Rig;
use roitrack::formats::AtomicFile;
use roitrack::image::{Frame, Polarity};
use roitrack::nalgebra::Vector3;
use roitrack::sim::multi_camera::{CameraRigScene, RigFrames, draw_clocks, simulate_rig};
use roitrack::sim::{
    DEFAULT_TRUTH_RATE_HZ, Excursion, FrameOptions, FrameSequence, Jump, Occlusion,
    ReflectionFault, RoiBurst, RoiImageRenderer, Scenario, ScenarioKind, SensorModel, SimulatedRun,
    Simulation, SimulationOptions, TimeGap,
};

use crate::args::{ScenarioArg, ShutterArg};
use crate::ranges;

/// File names inside a simulation folder.
pub const CAMERA_FILE: &str = "camera.yaml";
pub const TARGET_FILE: &str = "target.csv";
pub const MEASUREMENTS_FILE: &str = "measurements.csv";
pub const TRUTH_POSES_FILE: &str = "gt_poses.tum";
pub const TRUTH_TWISTS_FILE: &str = "gt_twists.csv";
pub const ROIS_FILE: &str = "rois.bin";
/// The files every simulated run writes ([`write_run`]).
pub const RUN_FILES: [&str; 5] = [
    CAMERA_FILE,
    TARGET_FILE,
    MEASUREMENTS_FILE,
    TRUTH_POSES_FILE,
    TRUTH_TWISTS_FILE,
];
/// With `--frames`: the folder of the frames (`frame_00000.png`, ...), their times, and how to track them.
pub const FRAMES_DIR: &str = "frames";
pub const TIMESTAMPS_FILE: &str = "timestamps.csv";
pub const FRAMES_README_FILE: &str = "README.txt";
/// How that README begins: a measurement run removes a README.txt only if it is this one.
const README_START: &str = "Simulated frames of";

/// With `--frames`: the blobs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FramePolarityArg {
    /// Bright blobs on a dark background (LEDs, retro-reflective markers).
    Bright,
    /// Dark printed circles on a light, unevenly lit background.
    Dark,
}

impl From<FramePolarityArg> for Polarity {
    fn from(p: FramePolarityArg) -> Self {
        match p {
            FramePolarityArg::Bright => Polarity::Bright,
            FramePolarityArg::Dark => Polarity::Dark,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OrderArg {
    /// 0 8 4 12 2 10 6 14 1 9 5 13 3 11 7 15 (docs/model.md)
    Bitrev,
    /// 0 1 2 ... 15: singular one-cycle windows on the planar grid
    Rowmajor,
    /// a new random permutation every cycle
    Random,
}

impl From<OrderArg> for RoiOrder {
    fn from(o: OrderArg) -> Self {
        match o {
            OrderArg::Bitrev => RoiOrder::BitReversed,
            OrderArg::Rowmajor => RoiOrder::RowMajor,
            OrderArg::Random => RoiOrder::Random,
        }
    }
}

/// Simulate a scenario one ROI at a time and write camera.yaml, target.csv, measurements.csv, gt_poses.tum and
/// gt_twists.csv into a folder; or, with --frames, the full frames a global- or rolling-shutter camera takes of it
/// (camera.yaml, target.csv, frames/frame_00000.png ..., timestamps.csv, gt_poses.tum, gt_twists.csv, README.txt).
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Which motion: static (bench pose), orthoglide (docs/model.md), spin (3 rev/s), random (smooth 6-dof), sweep
    /// (0.5 m/s, 1.5 rad/s: what a 30 Hz frame camera can follow).
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    /// Output folder (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub rig: crate::args::RigArgs,
    /// Several ROI cameras around the scenario, none sharing a clock: the rig file's cameras (docs/rig.md; the
    /// scenario's camera frame is the rig's frame), each camera's measurements on its own clock, with the rig file's
    /// clock offsets and drifts (those it leaves out drawn within ±50 ms and ±100 ppm from --seed). Writes a folder
    /// per camera, NAME/measurements.csv and NAME/camera.yaml, and target.csv, gt_poses.tum and gt_twists.csv in
    /// the rig's frame on the rig's clock, rig.yaml (the rig as given, for `track --rig`) and rig_truth.yaml (every
    /// clock). With --frames: each camera's frames instead of its measurements, NAME/frames/frame_00000.png ...,
    /// NAME/timestamps.csv on its own clock (frame k at k / --fps), NAME/camera.yaml, NAME/target.csv and
    /// NAME/README.txt, the truth on the rig's clock over every frame's exposure. Default: one camera.
    #[arg(long = "rig", value_name = "RIG.yaml", conflicts_with_all = [
        "rois", "reflections", "occlusions", "gaps", "bursts", "jump", "excursion", "drop_fraction",
        "outlier_fraction", "order", "rig_cameras",
    ])]
    pub camera_rig: Option<PathBuf>,
    /// As --rig, with a rig of N cameras (2 to 8) drawn from --seed around the built-in scene: the first the
    /// scenario's camera, the others 30-50 degrees aside looking at the scene's centre, their clocks within ±50 ms and
    /// ±100 ppm; rig.yaml then leaves their clocks out (to be learnt by `track --rig`). Also with --frames. Default:
    /// one camera.
    #[arg(long, value_name = "N", conflicts_with_all = [
        "rois", "reflections", "occlusions", "gaps", "bursts", "jump", "excursion", "drop_fraction",
        "outlier_fraction", "order",
    ], value_parser = ranges::count(2..=8, "cameras around one scene"))]
    pub rig_cameras: Option<usize>,
    /// Seed of the noise, drops, outliers, random order and random motion.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Centroid noise standard deviation per axis (px), at most 100.
    #[arg(long, default_value_t = 0.1, value_parser = ranges::within(0.0..=roitrack::estimators::MAX_NOISE_PX, " px", "more than a ROI's half-width is no centroid"))]
    pub noise_px: f64,
    /// ROI rate (Hz), at most a million.
    #[arg(long, default_value_t = 4000.0, value_parser = ranges::positive_up_to(roitrack::sim::MAX_ROI_RATE_HZ, " Hz", "beyond any ROI camera"))]
    pub rate_hz: f64,
    /// Order in which ROIs visit the points.
    #[arg(long, value_enum, default_value = "bitrev")]
    pub order: OrderArg,
    /// Fraction of ROIs lost, in [0, 1).
    #[arg(long = "drop", default_value_t = 0.0, value_parser = parse_drop_fraction)]
    pub drop_fraction: f64,
    /// Fraction of centroids moved 5-20 px, in [0, 1].
    #[arg(long = "outliers", default_value_t = 0.0, value_parser = parse_fraction)]
    pub outlier_fraction: f64,
    /// Also render the ROI of every measurement (40 x 40 px, placed with a random error of up to 4 px as a real
    /// scheduler would) and write them to rois.bin, a recording `roitrack track --rois` replays.
    #[arg(long)]
    pub rois: bool,
    /// Fault, with --rois: a reflection (a spot of sigma 1.2 px, 0.5-1.5 times the blob's peak, 6-10 px from the
    /// ROI's centre, so often merged with the blob) in this fraction of the ROIs, in [0, 1]. Default: none.
    #[arg(long, value_name = "FRACTION", requires = "rois", value_parser = parse_fraction)]
    pub reflections: Option<f64>,
    /// Fault: hide points during [T0, T1) s, e.g. `0,5,10,15@1.0:1.2` (repeatable). Default: none.
    #[arg(long = "occlude", value_name = "IDS@T0:T1", value_parser = parse_occlusion)]
    pub occlusions: Vec<Occlusion>,
    /// Fault: no measurement during [T0, T0 + DURATION) s, e.g. `2.0:0.05` (repeatable). Default: none.
    #[arg(long = "gap", value_name = "T0:DURATION", value_parser = parse_gap)]
    pub gaps: Vec<TimeGap>,
    /// Fault: COUNT consecutive ROIs lost from time T0 s, e.g. `1.5:40` (repeatable). Default: none.
    #[arg(long = "burst", value_name = "T0:COUNT", value_parser = parse_burst)]
    pub bursts: Vec<RoiBurst>,
    /// Fault: from time T s the target is translated by (DX, DY, DZ) m in the camera frame, ground truth included,
    /// e.g. `2.5:0.02,0,0`. Default: none.
    #[arg(long, value_name = "T:DX,DY,DZ", value_parser = parse_jump, allow_hyphen_values = true)]
    pub jump: Option<Jump>,
    /// Fault: during [T0, T1] s the target makes a smooth sideways excursion of (DX, DY, DZ) m at its peak and comes
    /// back, ground truth included, e.g. `1.0:1.4:0.12,0,0`; with `--skip-off-image`, far enough to take blobs out
    /// of the image. Default: none.
    #[arg(long, value_name = "T0:T1:DX,DY,DZ", value_parser = parse_excursion, allow_hyphen_values = true)]
    pub excursion: Option<Excursion>,
    /// Drop the measurements of blobs outside the image instead of failing.
    #[arg(long)]
    pub skip_off_image: bool,
    /// Instead of measurements: render the full frames of a frame camera (PNG, with sensor noise; the
    /// measurement-level options do not apply), their times (timestamps.csv), and a dense ground truth.
    #[arg(long, conflicts_with_all = [
        "noise_px", "rate_hz", "order", "drop_fraction", "outlier_fraction", "rois", "reflections", "occlusions",
        "gaps", "bursts", "jump", "excursion", "skip_off_image",
    ])]
    pub frames: bool,
    /// With --frames: frames per second (0.001 to 1e7; at most 100,000 frames in all); frame k is at k / F s (the
    /// mid-exposure time of its row 0).
    #[arg(long, value_name = "F", default_value_t = 30.0, requires = "frames", value_parser = ranges::within(roitrack::formats::MIN_FRAME_RATE_HZ..=roitrack::formats::MAX_FRAME_RATE_HZ, " Hz", "a frame every 1,000 s to beyond the fastest cameras"))]
    pub fps: f64,
    /// With --frames: how the camera reads its rows: global (every row at once) or rolling (row v read
    /// v * --line-delay-s after row 0).
    #[arg(long, value_enum, default_value = "global", requires = "frames")]
    pub shutter: ShutterArg,
    /// With --shutter rolling: the time between two rows (s), e.g. 30e-6 (1,024 rows read in 30.7 ms).
    /// Default: none; required with --shutter rolling.
    #[arg(long, value_name = "D", requires = "frames", value_parser = ranges::within(0.0..=roitrack::core::time::MAX_LINE_DELAY_S, " s", "a 1,000-row frame read in a second"))]
    pub line_delay_s: Option<f64>,
    /// With --frames: the exposure of each row (s, at most 10), centred on the row's time.
    #[arg(long, value_name = "E", default_value_t = 1e-3, requires = "frames", value_parser = ranges::within(0.0..=roitrack::core::time::MAX_EXPOSURE_S, " s", "beyond, a moving blob is a streak"))]
    pub exposure_s: f64,
    /// With --frames: bright blobs, or dark printed circles on a light, unevenly lit background.
    #[arg(long, value_enum, default_value = "bright", requires = "frames")]
    pub polarity: FramePolarityArg,
    /// With --frames: how many frames, at most 100,000 (default: every frame whose rows are all exposed within the
    /// scenario).
    #[arg(long, value_name = "N", requires = "frames", value_parser = ranges::count(1..=roitrack::sim::MAX_FRAMES, "each frame is a file"))]
    pub frame_count: Option<usize>,
}

/// A fraction in [0, 1).
fn parse_drop_fraction(text: &str) -> Result<f64, String> {
    let value = parse_number(text, "fraction")?;
    if (0.0..1.0).contains(&value) {
        Ok(value)
    } else {
        Err(format!(
            "{value} is not a fraction in [0, 1) (every ROI lost is no run)"
        ))
    }
}

/// A fraction in [0, 1].
fn parse_fraction(text: &str) -> Result<f64, String> {
    let value = parse_number(text, "fraction")?;
    if (0.0..=1.0).contains(&value) {
        Ok(value)
    } else {
        Err(format!("{value} is not a fraction in [0, 1]"))
    }
}

fn parse_number(text: &str, what: &str) -> Result<f64, String> {
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("{what} `{text}` is not a finite number"))
}

fn split_pair<'a>(text: &'a str, sep: char, form: &str) -> Result<(&'a str, &'a str), String> {
    text.split_once(sep)
        .ok_or_else(|| format!("expected {form}, got `{text}`"))
}

/// `IDS@T0:T1`, ids comma-separated.
pub fn parse_occlusion(text: &str) -> Result<Occlusion, String> {
    const FORM: &str = "IDS@T0:T1 (e.g. 0,5,10,15@1.0:1.2)";
    let (ids, times) = split_pair(text, '@', FORM)?;
    let (t0, t1) = split_pair(times, ':', FORM)?;
    let ids = ids
        .split(',')
        .map(|id| {
            id.trim()
                .parse::<u32>()
                .map_err(|_| format!("point id `{id}` is not a non-negative integer ({FORM})"))
        })
        .collect::<Result<Vec<u32>, String>>()?;
    let (t0_s, t1_s) = (parse_number(t0, "T0")?, parse_number(t1, "T1")?);
    if t1_s < t0_s {
        return Err(format!("T1 ({t1_s}) must not be before T0 ({t0_s})"));
    }
    Ok(Occlusion { ids, t0_s, t1_s })
}

/// `T0:DURATION`.
pub fn parse_gap(text: &str) -> Result<TimeGap, String> {
    let (t0, duration) = split_pair(text, ':', "T0:DURATION (e.g. 2.0:0.05)")?;
    let (t0_s, duration_s) = (parse_number(t0, "T0")?, parse_number(duration, "DURATION")?);
    if duration_s < 0.0 {
        return Err(format!("DURATION ({duration_s}) must be >= 0"));
    }
    Ok(TimeGap { t0_s, duration_s })
}

/// `T0:COUNT`.
pub fn parse_burst(text: &str) -> Result<RoiBurst, String> {
    let (t0, count) = split_pair(text, ':', "T0:COUNT (e.g. 1.5:40)")?;
    let t0_s = parse_number(t0, "T0")?;
    let count = count
        .trim()
        .parse::<usize>()
        .map_err(|_| format!("COUNT `{count}` is not a non-negative integer"))?;
    Ok(RoiBurst { t0_s, count })
}

/// `DX,DY,DZ` (metres).
fn parse_offset(offset: &str, form: &str) -> Result<Vector3<f64>, String> {
    let parts: Vec<&str> = offset.split(',').collect();
    let [dx, dy, dz] = parts[..] else {
        return Err(format!(
            "expected three offsets DX,DY,DZ, got `{offset}` ({form})"
        ));
    };
    Ok(Vector3::new(
        parse_number(dx, "DX")?,
        parse_number(dy, "DY")?,
        parse_number(dz, "DZ")?,
    ))
}

/// `T:DX,DY,DZ` (metres).
pub fn parse_jump(text: &str) -> Result<Jump, String> {
    const FORM: &str = "T:DX,DY,DZ in metres (e.g. 2.5:0.02,0,0)";
    let (t, offset) = split_pair(text, ':', FORM)?;
    Ok(Jump {
        t_s: parse_number(t, "T")?,
        offset_m: parse_offset(offset, FORM)?,
    })
}

/// `T0:T1:DX,DY,DZ` (seconds, metres).
pub fn parse_excursion(text: &str) -> Result<Excursion, String> {
    const FORM: &str = "T0:T1:DX,DY,DZ in seconds and metres (e.g. 1.0:1.4:0.12,0,0)";
    let (t0, rest) = split_pair(text, ':', FORM)?;
    let (t1, offset) = split_pair(rest, ':', FORM)?;
    let (t0_s, t1_s) = (parse_number(t0, "T0")?, parse_number(t1, "T1")?);
    if t1_s <= t0_s {
        return Err(format!("T1 ({t1_s}) must be after T0 ({t0_s})"));
    }
    Ok(Excursion {
        t0_s,
        t1_s,
        offset_m: parse_offset(offset, FORM)?,
    })
}

impl SimulateArgs {
    pub fn options(&self) -> SimulationOptions {
        SimulationOptions {
            seed: self.seed,
            noise_px: self.noise_px,
            rate_hz: self.rate_hz,
            order: self.order.into(),
            drop_fraction: self.drop_fraction,
            outlier_fraction: self.outlier_fraction,
            occlusions: self.occlusions.clone(),
            gaps: self.gaps.clone(),
            bursts: self.bursts.clone(),
            jump: self.jump,
            excursion: self.excursion,
            skip_off_image: self.skip_off_image,
        }
    }
}

pub fn run(args: &SimulateArgs) -> Result<()> {
    if args.camera_rig.is_some() || args.rig_cameras.is_some() {
        return if args.frames {
            run_rig_frames(args)
        } else {
            run_rig(args)
        };
    }
    if args.frames {
        return run_frames(args);
    }
    let scenario = args
        .rig
        .scenario(Scenario::new(args.scenario.into(), args.seed))?;
    // What this run writes, and what a previous run of the other kind (--frames) left, which it removes.
    let files = [
        RUN_FILES.as_slice(),
        &[ROIS_FILE, TIMESTAMPS_FILE, FRAMES_README_FILE, FRAMES_DIR],
    ]
    .concat();
    args.rig.check_outputs(&args.out, &files)?;
    let options = args.options();
    roitrack::formats::create_output_dir(&args.out)?;
    remove_other_runs_files(&args.out, false, args.rois)?;
    let reflections = args.reflections.map(|fraction| ReflectionFault {
        fraction,
        ..Default::default()
    });
    // Streamed: the memory does not grow with the duration.
    let measured = write_run_streamed(
        &scenario,
        &options,
        &args.out,
        args.rois.then_some(reflections),
        // A signal stops the run at its next ROI, through the error path (src/signals.rs).
        || Ok(crate::signals::check(&args.out.join(MEASUREMENTS_FILE))?),
    )?;
    eprintln!(
        "roitrack: {} scenario: {} measurements over {:.3} s written to {}",
        scenario.kind.name(),
        measured,
        scenario.duration_s,
        args.out.display()
    );
    Ok(())
}

/// Removes, when the run's outputs are committed (as one step of the commit, undone if it fails), the files of a
/// previous simulation in `dir` that do not belong with this run's: with `frames`, the measurements and the ROI
/// recording; without, the frames (only our own `frame_NNNNN.png` names, and their folder if nothing else is in it),
/// their times and their README (only if it is ours), and the ROI recording unless `rois`. Until then they stay: an interrupted or failed run changes nothing, and a committed one never leaves the
/// files of two runs side by side.
pub fn remove_other_runs_files(dir: &Path, frames: bool, rois: bool) -> Result<()> {
    use roitrack::formats::remove_at_commit;
    if frames {
        remove_at_commit(&dir.join(MEASUREMENTS_FILE))?;
        return Ok(remove_at_commit(&dir.join(ROIS_FILE))?);
    }
    if !rois {
        remove_at_commit(&dir.join(ROIS_FILE))?;
    }
    remove_at_commit(&dir.join(TIMESTAMPS_FILE))?;
    let readme = dir.join(FRAMES_README_FILE);
    if std::fs::read_to_string(&readme).is_ok_and(|text| text.starts_with(README_START)) {
        remove_at_commit(&readme)?;
    }
    // The folder of frames goes whole if it holds only frames; else only the frames go.
    let frames_dir = dir.join(FRAMES_DIR);
    if frames_dir.is_dir() {
        remove_dead_frame_temporaries(&frames_dir);
        match foreign_entry(&frames_dir)? {
            None => remove_at_commit(&frames_dir)?,
            Some(_) => remove_stale_frames(&frames_dir, 0)?,
        }
    }
    Ok(())
}

/// Deletes the temporaries of frames that a killed run (`kill -9`) left in `frames_dir`: every finished frame of a run
/// waits as a temporary until the run's commit, and the next run may write fewer frames, or none.
fn remove_dead_frame_temporaries(frames_dir: &Path) {
    roitrack::formats::remove_dead_temporaries(frames_dir, |name| frame_index(name).is_some());
}

/// The index of a frame file name `frame_NNNNN.png` (at least five digits), if it is one.
fn frame_index(name: &str) -> Option<usize> {
    name.strip_prefix("frame_")
        .and_then(|n| n.strip_suffix(".png"))
        .filter(|digits| digits.len() >= 5 && digits.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|digits| digits.parse().ok())
}

/// The first entry of the folder `frames_dir` that is not a frame `simulate --frames` writes (`frame_NNNNN.png`), if
/// any.
fn foreign_entry(frames_dir: &Path) -> Result<Option<String>> {
    let entries = std::fs::read_dir(frames_dir)
        .with_context(|| format!("cannot list folder {}", frames_dir.display()))?;
    for entry in entries {
        let entry =
            entry.with_context(|| format!("cannot list folder {}", frames_dir.display()))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let ours = frame_index(&name).is_some() && entry.file_type().is_ok_and(|t| t.is_file());
        if !ours {
            return Ok(Some(name));
        }
    }
    Ok(None)
}

/// Writes the five files of a simulated run into `dir` (created if missing; removed again if the run fails).
pub fn write_run(run: &SimulatedRun, dir: &Path) -> Result<()> {
    roitrack::formats::create_output_dir(dir)?;
    roitrack::formats::write_camera_yaml(dir.join(CAMERA_FILE), &run.camera)?;
    roitrack::formats::write_target_csv(dir.join(TARGET_FILE), &run.target)?;
    roitrack::formats::write_measurements_csv(dir.join(MEASUREMENTS_FILE), &run.measurements)?;
    roitrack::formats::write_tum(dir.join(TRUTH_POSES_FILE), &run.truth_poses)?;
    roitrack::formats::write_twists_csv(dir.join(TRUTH_TWISTS_FILE), &run.truth_twists)?;
    Ok(())
}

/// Simulates `scenario` one ROI at a time and writes the run's files into `dir` (which must exist) as it goes:
/// camera.yaml, target.csv, measurements.csv, gt_poses.tum, gt_twists.csv, and with `rois` (its reflection fault,
/// if any) the rendered ROI of every measurement in rois.bin. The memory is the same whatever the duration: nothing
/// of the run is held but the ROI being written. `each_roi` runs before every ROI (to stop on a signal). Returns the
/// number of measurements. The files are those of [`write_run`] on [`simulate`]'s run, byte for byte.
fn write_run_streamed(
    scenario: &Scenario,
    options: &SimulationOptions,
    dir: &Path,
    rois: Option<Option<ReflectionFault>>,
    mut each_roi: impl FnMut() -> Result<()>,
) -> Result<usize> {
    let stream = Simulation::new(scenario, options).context("simulation failed")?;
    let file = |name: &str| dir.join(name);
    roitrack::formats::write_camera_yaml(file(CAMERA_FILE), &scenario.camera)?;
    roitrack::formats::write_target_csv(file(TARGET_FILE), &scenario.target)?;
    let mut measurements = roitrack::formats::MeasurementWriter::create(file(MEASUREMENTS_FILE))?;
    let mut poses = roitrack::formats::PoseWriter::create(file(TRUTH_POSES_FILE))?;
    let mut twists = roitrack::formats::TwistWriter::create(file(TRUTH_TWISTS_FILE))?;
    let mut recording = match rois {
        Some(reflections) => Some((
            roitrack::formats::RoiRecordingWriter::create(file(ROIS_FILE))?,
            RoiImageRenderer::new(scenario, options, SensorModel::default(), reflections)?,
        )),
        None => None,
    };
    let mut measured = 0;
    for roi in stream {
        each_roi()?;
        let roi = roi.context("simulation failed")?;
        poses.write(&roi.truth_pose)?;
        twists.write(&roi.truth_twist)?;
        if let Some(m) = roi.measurement {
            measurements.write(&m)?;
            measured += 1;
            if let Some((writer, renderer)) = &mut recording {
                writer.write(&renderer.render(&m)?)?;
            }
        }
    }
    measurements.finish()?;
    poses.finish()?;
    twists.finish()?;
    if let Some((writer, _)) = recording {
        writer.finish()?;
    }
    Ok(measured)
}

impl SimulateArgs {
    fn readout(&self) -> Result<Readout> {
        self.shutter.readout(self.line_delay_s)
    }

    /// The frame camera's options (`--fps`, `--shutter`, `--exposure-s`, `--polarity`, `--seed`, `--frame-count`).
    fn frame_options(&self) -> Result<FrameOptions> {
        Ok(FrameOptions {
            fps_hz: self.fps,
            readout: self.readout()?,
            exposure_s: self.exposure_s,
            polarity: self.polarity.into(),
            sensor: SensorModel::default(),
            seed: self.seed,
            start_s: 0.0,
            frame_count: self.frame_count,
        })
    }

    /// The `roitrack simulate` command that makes these frames.
    fn frames_command(&self) -> String {
        let mut command = format!(
            "roitrack simulate --frames --scenario {} --seed {} --fps {} --shutter {}",
            ScenarioKind::from(self.scenario).name(),
            self.seed,
            self.fps,
            self.shutter.name()
        );
        if let Some(d) = self.line_delay_s {
            command += &format!(" --line-delay-s {d:e}");
        }
        command += &format!(
            " --exposure-s {:e} --polarity {}",
            self.exposure_s,
            Polarity::from(self.polarity).name()
        );
        if let Some(n) = self.frame_count {
            command += &format!(" --frame-count {n}");
        }
        if let Some(n) = self.rig_cameras {
            command += &format!(" --rig-cameras {n}");
        }
        if let Some(rig) = &self.camera_rig {
            command += &format!(" --rig {}", rig.display());
        }
        command + &format!(" --out {}", self.out.display())
    }

    /// The `roitrack track` options that tell it how these frames were taken (a camera_info file has no time model).
    fn track_time_options(&self) -> String {
        let mut options = format!("--shutter {}", self.shutter.name());
        if let Some(d) = self.line_delay_s {
            options += &format!(" --line-delay-s {d:e}");
        }
        options + &format!(" --exposure-s {:e}", self.exposure_s)
    }
}

/// The file name of frame `k`.
fn frame_file_name(k: usize) -> String {
    format!("frame_{k:05}.png")
}

/// `simulate --frames`: the frames of a frame camera, their times and a dense ground truth.
fn run_frames(args: &SimulateArgs) -> Result<()> {
    let scenario = args
        .rig
        .scenario(Scenario::new(args.scenario.into(), args.seed))?;
    args.rig.check_outputs(
        &args.out,
        &[
            CAMERA_FILE,
            TARGET_FILE,
            TIMESTAMPS_FILE,
            TRUTH_POSES_FILE,
            TRUTH_TWISTS_FILE,
            FRAMES_README_FILE,
            FRAMES_DIR,
            // A previous measurement run's, removed.
            MEASUREMENTS_FILE,
            ROIS_FILE,
        ],
    )?;

    let options = args.frame_options()?;
    let sequence =
        FrameSequence::new(&scenario, &options).context("cannot simulate these frames")?;
    let count = sequence.len();
    let dir = &args.out;
    let frames_dir = write_camera_frames(dir, &sequence, &scenario.target)?;
    write_dense_truth(
        dir,
        sequence
            .truth_iter(DEFAULT_TRUTH_RATE_HZ)
            .context("cannot sample the ground truth")?,
    )?;
    let track = track_command(args);
    write_text(
        &dir.join(FRAMES_README_FILE),
        &frames_readme(args, &sequence, &track),
    )?;
    eprintln!(
        "roitrack: {} scenario: {count} frames of {} x {} px ({} shutter, {} blobs) written to {}; a camera_info \
         file has no time model: track them with\n  {track}",
        scenario.kind.name(),
        sequence.camera().width_px,
        sequence.camera().height_px,
        args.shutter.name(),
        Polarity::from(args.polarity).name(),
        frames_dir.display(),
    );
    Ok(())
}

/// Removes, when the run's outputs are committed, the frames a previous, longer simulation left in `frames_dir` (only
/// our own `frame_NNNNN.png` names, from `count` on): a folder of frames is read whole, and the timestamps would not
/// match. Until then they stay, beside the new frames' temporaries: an interrupted run changes nothing.
fn remove_stale_frames(frames_dir: &Path, count: usize) -> Result<()> {
    let entries = std::fs::read_dir(frames_dir)
        .with_context(|| format!("cannot list folder {}", frames_dir.display()))?;
    for entry in entries {
        let entry =
            entry.with_context(|| format!("cannot list folder {}", frames_dir.display()))?;
        let name = entry.file_name();
        let Some(index) = name.to_str().and_then(frame_index) else {
            continue;
        };
        if index >= count && frame_file_name(index) == name.to_string_lossy() {
            roitrack::formats::remove_at_commit(&entry.path())?;
        }
    }
    Ok(())
}

/// Renders and writes every frame, on as many threads as there are cores: a frame's pixels depend only on its
/// index, so each thread renders its share with its own copy of the sequence.
fn render_frames(sequence: &FrameSequence, frames_dir: &Path) -> Result<()> {
    let count = sequence.len();
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(count);
    // Drawn on stderr, only when it is a terminal.
    let bar = indicatif::ProgressBar::new(count as u64).with_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} frames ({elapsed}, {eta} left)",
        )
        .expect("valid progress template"),
    );
    let next = AtomicUsize::new(0);
    let result = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                let mut sequence = sequence.clone();
                let (next, bar) = (&next, &bar);
                scope.spawn(move || -> Result<()> {
                    let mut frame = Frame::default();
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed);
                        if k >= count {
                            return Ok(());
                        }
                        // A signal stops every thread at its next frame (src/signals.rs).
                        if let Err(e) = crate::signals::check(frames_dir) {
                            next.store(count, Ordering::Relaxed);
                            return Err(e.into());
                        }
                        sequence.render(k, &mut frame);
                        if let Err(e) = roitrack::formats::write_frame_png(
                            frames_dir.join(frame_file_name(k)),
                            &frame,
                        ) {
                            // The others stop at their next frame.
                            next.store(count, Ordering::Relaxed);
                            return Err(e.into());
                        }
                        bar.inc(1);
                    }
                })
            })
            .collect();
        workers.into_iter().try_for_each(|w| {
            w.join()
                .map_err(|_| anyhow!("a rendering thread panicked"))?
        })
    });
    bar.finish_and_clear();
    result
}

/// Writes one camera's frames to `dir` (the folder of frames, the camera file, the target `target`, the timestamps),
/// first removing what a previous run there left that would not match them; the folder of frames.
fn write_camera_frames(
    dir: &Path,
    sequence: &FrameSequence,
    target: &roitrack::core::Target,
) -> Result<PathBuf> {
    let frames_dir = dir.join(FRAMES_DIR);
    roitrack::formats::create_output_dir(&frames_dir)?;
    remove_other_runs_files(dir, true, false)?;
    remove_dead_frame_temporaries(&frames_dir);
    remove_stale_frames(&frames_dir, sequence.len())?;
    roitrack::formats::write_camera_yaml(dir.join(CAMERA_FILE), sequence.camera())?;
    roitrack::formats::write_target_csv(dir.join(TARGET_FILE), target)?;
    render_frames(sequence, &frames_dir)?;
    write_timestamps(sequence, &dir.join(TIMESTAMPS_FILE))?;
    Ok(frames_dir)
}

/// `t,file`: each frame's time (s, the mid-exposure time of its row 0) and file name, as `roitrack track
/// --timestamps` reads them. Times are written in full (shortest round-trip form).
fn write_timestamps(sequence: &FrameSequence, path: &Path) -> Result<()> {
    let mut text = String::from("t,file\n");
    for k in 0..sequence.len() {
        text += &format!("{},{}\n", sequence.frame_time_s(k), frame_file_name(k));
    }
    write_text(path, &text)
}

/// Writes `text` to `path` atomically: nothing appears there until it is whole.
fn write_text(path: &Path, text: &str) -> Result<()> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(text.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))?;
    file.finish()?;
    Ok(())
}

/// The `roitrack track` command for the frames in `args.out`.
fn track_command(args: &SimulateArgs) -> String {
    let dir = |name: &str| args.out.join(name).display().to_string();
    format!(
        "roitrack track --camera {} --target {} --images {} --timestamps {} {} --polarity {} --poses poses.tum \
         --twists twists.csv",
        dir(CAMERA_FILE),
        dir(TARGET_FILE),
        dir(FRAMES_DIR),
        dir(TIMESTAMPS_FILE),
        args.track_time_options(),
        Polarity::from(args.polarity).name()
    )
}

/// What the folder holds and how to track and score it.
fn frames_readme(args: &SimulateArgs, sequence: &FrameSequence, track: &str) -> String {
    let camera = sequence.camera();
    let readout = match camera.time.readout {
        Readout::RollingShutter { line_delay_s } => format!(
            "a rolling shutter (row v read v x {line_delay_s:e} s after row 0: {:.4} s from the first row to the \
             last)",
            line_delay_s * f64::from(camera.height_px.saturating_sub(1)),
        ),
        _ => "a global shutter (every row at the frame's time)".to_owned(),
    };
    let (start, end) = sequence.span_s();
    format!(
        "{README_START} the {scenario} scenario (seed {seed}), made by\n\n    {command}\n\n\
         {count} frames of {w} x {h} px at {fps} Hz, {polarity} blobs, read by {readout}, each row exposed for {e:e} \
         s around its time.\n\n\
         {camera_file:<16} the camera (ROS camera_info). It has no time model: tell `roitrack track` how the rows \
         were read,\n{pad:<16} {options}\n\
         {target_file:<16} the target (id,x,y,z,diameter in metres)\n\
         {frames_dir:<16} frame_00000.png ...: grey PNGs, {bits} bits\n\
         {timestamps:<16} t,file: each frame's time (s: the mid-exposure time of its row 0) and file name\n\
         {poses:<16} the true poses (TUM, camera_T_object) every {dt:e} s and at every frame's time, from {start:.6} s \
         to {end:.6} s (the last frame's last row)\n\
         {twists:<16} the true twists (t,vx,vy,vz,wx,wy,wz) at the same times\n\n\
         Track and score them (`roitrack eval` interpolates the truth at each estimate's own time, the mean time of its \
         frame's blobs):\n\n    {track}\n    roitrack eval --truth {out} --poses poses.tum --twists twists.csv\n",
        scenario = sequence.scenario().kind.name(),
        seed = args.seed,
        command = args.frames_command(),
        count = sequence.len(),
        w = camera.width_px,
        h = camera.height_px,
        fps = args.fps,
        polarity = Polarity::from(args.polarity).name(),
        e = args.exposure_s,
        camera_file = CAMERA_FILE,
        pad = "",
        options = args.track_time_options(),
        target_file = TARGET_FILE,
        frames_dir = format!("{FRAMES_DIR}/"),
        bits = sequence.options().sensor.bit_depth,
        timestamps = TIMESTAMPS_FILE,
        poses = TRUTH_POSES_FILE,
        dt = 1.0 / DEFAULT_TRUTH_RATE_HZ,
        twists = TRUTH_TWISTS_FILE,
        out = args.out.display(),
    )
}

/// The truth of a simulated rig, and the rig as `track --rig` is told it.
fn rig_scene(args: &SimulateArgs, scenario: Scenario) -> Result<(CameraRigScene, Rig)> {
    if let Some(n) = args.rig_cameras {
        let scene = CameraRigScene::random(scenario, n, args.seed);
        let told = scene.rig_with_clocks_unknown();
        return Ok((scene, told));
    }
    let path = args.camera_rig.as_deref().expect("--rig or --rig-cameras");
    let file = roitrack::formats::read_rig_yaml(path, &Default::default())?;
    for camera in file.rig.cameras() {
        let name = &camera.name;
        if name.contains(['/', '\\']) || name == "." || name == ".." {
            bail!(
                "{}: camera '{name}': simulate writes a folder per camera, named after it; give it a name without path \
                 separators",
                path.display()
            );
        }
    }
    Ok((
        CameraRigScene {
            scenario,
            rig: draw_clocks(&file.rig, args.seed),
        },
        file.rig,
    ))
}

/// File names of a simulated rig's folder.
pub const RIG_FILE: &str = "rig.yaml";
pub const RIG_TRUTH_FILE: &str = "rig_truth.yaml";

/// The scene and the told rig of a rig run (`--rig` or `--rig-cameras`), once its outputs, the rig-level files and
/// `camera_files` in each camera's folder, are checked not to overwrite its inputs.
fn rig_setup(args: &SimulateArgs, camera_files: &[&str]) -> Result<(CameraRigScene, Rig)> {
    if args.rig.camera.is_some() {
        bail!("--rig gives the cameras: leave out --camera");
    }
    let scenario = args
        .rig
        .scenario(Scenario::new(args.scenario.into(), args.seed))?;
    let (scene, told) = rig_scene(args, scenario)?;
    let mut files = vec![
        TARGET_FILE.to_string(),
        TRUTH_POSES_FILE.to_string(),
        TRUTH_TWISTS_FILE.to_string(),
        RIG_FILE.to_string(),
        RIG_TRUTH_FILE.to_string(),
    ];
    for camera in scene.rig.cameras() {
        for file in camera_files {
            files.push(format!("{}/{file}", camera.name));
        }
    }
    let file_refs: Vec<&str> = files.iter().map(String::as_str).collect();
    args.rig.check_outputs(&args.out, &file_refs)?;
    if let Some(rig_path) = &args.camera_rig {
        let outputs: Vec<(String, PathBuf)> = files
            .iter()
            .map(|f| (format!("--out's {f}"), args.out.join(f)))
            .collect();
        let outputs: Vec<(&str, &Path)> = outputs
            .iter()
            .map(|(n, p)| (n.as_str(), p.as_path()))
            .collect();
        roitrack::formats::check_output_paths(&[("--rig", rig_path.as_path())], &outputs)?;
    }
    Ok((scene, told))
}

/// `simulate --rig` / `--rig-cameras`: a folder per camera, the truth in the rig's frame and clock, the rig files.
fn run_rig(args: &SimulateArgs) -> Result<()> {
    let (scene, told) = rig_setup(
        args,
        &[
            CAMERA_FILE,
            MEASUREMENTS_FILE,
            // A previous frames run's, removed.
            TARGET_FILE,
            TIMESTAMPS_FILE,
            FRAMES_README_FILE,
            FRAMES_DIR,
        ],
    )?;
    let names: Vec<String> = scene.rig.cameras().iter().map(|c| c.name.clone()).collect();
    let run = simulate_rig(&scene, args.rate_hz, args.noise_px, args.seed)
        .context("simulation failed")?;
    roitrack::formats::create_output_dir(&args.out)?;
    roitrack::formats::write_target_csv(args.out.join(TARGET_FILE), &scene.scenario.target)?;
    roitrack::formats::write_tum(args.out.join(TRUTH_POSES_FILE), &run.truth_poses)?;
    roitrack::formats::write_twists_csv(args.out.join(TRUTH_TWISTS_FILE), &run.truth_twists)?;
    let mut calibrations = Vec::with_capacity(names.len());
    for (camera, measurements) in scene.rig.cameras().iter().zip(&run.measurements) {
        let dir = args.out.join(&camera.name);
        roitrack::formats::create_output_dir(&dir)?;
        remove_other_runs_files(&dir, false, false)?;
        // A frames run's copy of the target (the rig's own is beside the folders).
        roitrack::formats::remove_at_commit(&dir.join(TARGET_FILE))?;
        roitrack::formats::write_camera_yaml(dir.join(CAMERA_FILE), &camera.camera)?;
        roitrack::formats::write_measurements_csv(dir.join(MEASUREMENTS_FILE), measurements)?;
        calibrations.push(format!("{}/{CAMERA_FILE}", camera.name));
    }
    write_rig_files(&args.out, &told, &scene.rig, &calibrations)?;
    let count: usize = run.measurements.iter().map(Vec::len).sum();
    eprintln!(
        "roitrack: {} scenario seen by {} cameras: {count} measurements over {:.3} s written to {}",
        scene.scenario.kind.name(),
        names.len(),
        scene.scenario.duration_s,
        args.out.display()
    );
    Ok(())
}

/// The two rig files of a simulated rig in `out`: `rig.yaml` as the tracker is told it (`told`: the clocks it must
/// learn left out) and `rig_truth.yaml` with every camera's true clock, both naming each camera's `calibrations`.
fn write_rig_files(out: &Path, told: &Rig, truth: &Rig, calibrations: &[String]) -> Result<()> {
    roitrack::formats::write_rig_yaml(out.join(RIG_FILE), told, calibrations, None)?;
    roitrack::formats::write_rig_yaml(out.join(RIG_TRUTH_FILE), truth, calibrations, None)?;
    Ok(())
}

/// `simulate --frames --rig` / `--rig-cameras`: a folder per camera of its frames on its own clock (as `--frames`
/// writes them for one camera), the truth in the rig's frame on the rig's clock, the rig files.
fn run_rig_frames(args: &SimulateArgs) -> Result<()> {
    let (scene, told) = rig_setup(
        args,
        &[
            CAMERA_FILE,
            TARGET_FILE,
            TIMESTAMPS_FILE,
            FRAMES_README_FILE,
            FRAMES_DIR,
            // A previous measurement run's, removed.
            MEASUREMENTS_FILE,
            ROIS_FILE,
        ],
    )?;
    let options = args.frame_options()?;
    let rig_frames = RigFrames::new(&scene, &options).context("cannot simulate these frames")?;
    let out = &args.out;
    roitrack::formats::create_output_dir(out)?;
    roitrack::formats::write_target_csv(out.join(TARGET_FILE), &scene.scenario.target)?;
    write_dense_truth(
        out,
        rig_frames
            .truth_iter(DEFAULT_TRUTH_RATE_HZ)
            .context("cannot sample the ground truth")?,
    )?;
    let track = rig_track_command(args, &scene);
    let mut calibrations = Vec::with_capacity(scene.rig.len());
    let mut counts = Vec::with_capacity(scene.rig.len());
    for (camera, sequence) in scene.rig.cameras().iter().zip(rig_frames.cameras()) {
        let dir = out.join(&camera.name);
        write_camera_frames(&dir, sequence, &scene.scenario.target)?;
        write_text(
            &dir.join(FRAMES_README_FILE),
            &rig_camera_readme(args, &camera.name, sequence, &track),
        )?;
        calibrations.push(format!("{}/{CAMERA_FILE}", camera.name));
        counts.push(format!("{} {}", camera.name, sequence.len()));
    }
    write_rig_files(out, &told, &scene.rig, &calibrations)?;
    eprintln!(
        "roitrack: {} scenario seen by {} cameras: frames ({}; {} shutter, {} blobs) written to {}, each camera's on \
         its own clock; track them with\n  {track}",
        scene.scenario.kind.name(),
        scene.rig.len(),
        counts.join(", "),
        args.shutter.name(),
        Polarity::from(args.polarity).name(),
        out.display(),
    );
    Ok(())
}

/// The `roitrack track --rig` command for the frames of every camera in `args.out`: frame k of each at k / --fps of
/// its own clock, as its timestamps.csv says.
fn rig_track_command(args: &SimulateArgs, scene: &CameraRigScene) -> String {
    let path = |name: &str| args.out.join(name).display().to_string();
    let images: Vec<String> = scene
        .rig
        .cameras()
        .iter()
        .map(|c| {
            format!(
                "--images {}={}",
                c.name,
                path(&format!("{}/{FRAMES_DIR}", c.name))
            )
        })
        .collect();
    format!(
        "roitrack track --rig {} --target {} {} --fps {} {} --polarity {} --poses poses.tum --twists twists.csv",
        path(RIG_FILE),
        path(TARGET_FILE),
        images.join(" "),
        args.fps,
        args.track_time_options(),
        Polarity::from(args.polarity).name()
    )
}

/// What one camera's folder of a rig of frames holds, and how to track and score the rig.
fn rig_camera_readme(
    args: &SimulateArgs,
    name: &str,
    sequence: &FrameSequence,
    track: &str,
) -> String {
    let camera = sequence.camera();
    let (start, end) = sequence.span_s();
    format!(
        "{README_START} the {scenario} scenario (seed {seed}) by camera '{name}' of a rig, made by\n\n    \
         {command}\n\n\
         {count} frames of {w} x {h} px at {fps} Hz of this camera's own clock ({shutter} shutter, {polarity} blobs, \
         each row exposed for {e:e} s around its time), from {start:.6} s to {end:.6} s of that clock. ../{rig} gives \
         the camera's pose in the rig and its clock as `track --rig` is told them, ../{truth} as simulated: \
         t_rig = clock_offset_s + t_camera / (1 + clock_drift_ppm 1e-6).\n\n\
         {camera_file:<16} the camera (ROS camera_info; no time model: tell `roitrack track` {options})\n\
         {target_file:<16} the target (id,x,y,z,diameter in metres)\n\
         {frames_dir:<16} frame_00000.png ...: grey PNGs, {bits} bits\n\
         {timestamps:<16} t,file: each frame's time on this camera's clock (s: the mid-exposure time of its row 0, \
         frame k at k / {fps})\n\n\
         The truth (../{poses}, ../{twists}) is rig_T_object and its twist in the rig's frame on the rig's clock. \
         Track every camera's frames and score them:\n\n    {track}\n    roitrack eval --truth {out} --poses \
         poses.tum --twists twists.csv\n",
        scenario = sequence.scenario().kind.name(),
        seed = args.seed,
        command = args.frames_command(),
        count = sequence.len(),
        w = camera.width_px,
        h = camera.height_px,
        fps = args.fps,
        shutter = args.shutter.name(),
        polarity = Polarity::from(args.polarity).name(),
        e = args.exposure_s,
        rig = RIG_FILE,
        truth = RIG_TRUTH_FILE,
        camera_file = CAMERA_FILE,
        options = args.track_time_options(),
        target_file = TARGET_FILE,
        frames_dir = format!("{FRAMES_DIR}/"),
        bits = sequence.options().sensor.bit_depth,
        timestamps = TIMESTAMPS_FILE,
        poses = TRUTH_POSES_FILE,
        twists = TRUTH_TWISTS_FILE,
        out = args.out.display(),
    )
}

/// Writes `truth` to `dir`'s gt_poses.tum and gt_twists.csv as it is sampled. Dense, so that `roitrack eval`
/// interpolates the truth at each estimate's own time (a frame's estimate is at the mean time of its blobs); streamed,
/// so that the memory does not grow with the duration.
fn write_dense_truth(
    dir: &Path,
    truth: impl Iterator<Item = (roitrack::core::PoseSample, roitrack::core::TwistSample)>,
) -> Result<()> {
    let mut poses = roitrack::formats::PoseWriter::create(dir.join(TRUTH_POSES_FILE))?;
    let mut twists = roitrack::formats::TwistWriter::create(dir.join(TRUTH_TWISTS_FILE))?;
    for (pose, twist) in truth {
        poses.write(&pose)?;
        twists.write(&twist)?;
    }
    poses.finish()?;
    twists.finish()?;
    Ok(())
}
