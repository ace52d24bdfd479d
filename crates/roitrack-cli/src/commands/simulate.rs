//! `roitrack simulate`: write a scenario's camera, target, measurements and ground truth (and optionally a recording
//! of rendered ROIs).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use roitrack::image::{ReflectionFault, SensorModel};
use roitrack::math::RoiOrder;
use roitrack::nalgebra::Vector3;
use roitrack::sim::{
    Excursion, Jump, Occlusion, RoiBurst, Scenario, SimulatedRun, SimulationOptions, TimeGap,
    render_roi_images, simulate,
};

use crate::args::ScenarioArg;

/// File names inside a simulation folder.
pub const CAMERA_FILE: &str = "camera.yaml";
pub const TARGET_FILE: &str = "target.csv";
pub const MEASUREMENTS_FILE: &str = "measurements.csv";
pub const TRUTH_POSES_FILE: &str = "gt_poses.tum";
pub const TRUTH_TWISTS_FILE: &str = "gt_twists.csv";
pub const ROIS_FILE: &str = "rois.bin";

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OrderArg {
    /// 0 8 4 12 2 10 6 14 1 9 5 13 3 11 7 15 (SPEC section 6)
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
/// gt_twists.csv into a folder.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Which motion: static (bench pose), orthoglide (SPEC section 7), spin (3 rev/s), random (smooth 6-dof).
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    /// Output folder (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the noise, drops, outliers, random order and random motion.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Centroid noise standard deviation per axis (px).
    #[arg(long, default_value_t = 0.1)]
    pub noise_px: f64,
    /// ROI rate (Hz).
    #[arg(long, default_value_t = 4000.0)]
    pub rate_hz: f64,
    /// Order in which ROIs visit the points.
    #[arg(long, value_enum, default_value = "bitrev")]
    pub order: OrderArg,
    /// Fraction of ROIs lost, in [0, 1).
    #[arg(long = "drop", default_value_t = 0.0)]
    pub drop_fraction: f64,
    /// Fraction of centroids moved 5-20 px, in [0, 1].
    #[arg(long = "outliers", default_value_t = 0.0)]
    pub outlier_fraction: f64,
    /// Also render the ROI of every measurement (40 x 40 px, placed with a random error of up to 4 px as a real
    /// scheduler would) and write them to rois.bin, a recording `roitrack track --rois` replays.
    #[arg(long)]
    pub rois: bool,
    /// Fault, with --rois: a reflection (a spot of sigma 1.2 px, 0.5-1.5 times the blob's peak, 6-10 px from the
    /// ROI's centre, so often merged with the blob) in this fraction of the ROIs, in [0, 1].
    #[arg(long, value_name = "FRACTION", requires = "rois", value_parser = parse_fraction)]
    pub reflections: Option<f64>,
    /// Fault: hide points during [T0, T1) s, e.g. `0,5,10,15@1.0:1.2` (repeatable).
    #[arg(long = "occlude", value_name = "IDS@T0:T1", value_parser = parse_occlusion)]
    pub occlusions: Vec<Occlusion>,
    /// Fault: no measurement during [T0, T0 + DURATION) s, e.g. `2.0:0.05` (repeatable).
    #[arg(long = "gap", value_name = "T0:DURATION", value_parser = parse_gap)]
    pub gaps: Vec<TimeGap>,
    /// Fault: COUNT consecutive ROIs lost from time T0 s, e.g. `1.5:40` (repeatable).
    #[arg(long = "burst", value_name = "T0:COUNT", value_parser = parse_burst)]
    pub bursts: Vec<RoiBurst>,
    /// Fault: from time T s the target is translated by (DX, DY, DZ) m in the camera frame, ground truth included,
    /// e.g. `2.5:0.02,0,0`.
    #[arg(long, value_name = "T:DX,DY,DZ", value_parser = parse_jump, allow_hyphen_values = true)]
    pub jump: Option<Jump>,
    /// Fault: during [T0, T1] s the target makes a smooth sideways excursion of (DX, DY, DZ) m at its peak and comes
    /// back, ground truth included, e.g. `1.0:1.4:0.12,0,0`; with `--skip-off-image`, far enough to take blobs out
    /// of the image.
    #[arg(long, value_name = "T0:T1:DX,DY,DZ", value_parser = parse_excursion, allow_hyphen_values = true)]
    pub excursion: Option<Excursion>,
    /// Drop the measurements of blobs outside the image instead of failing.
    #[arg(long)]
    pub skip_off_image: bool,
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
    let scenario = Scenario::new(args.scenario.into(), args.seed);
    let options = args.options();
    let run = simulate(&scenario, &options).context("simulation failed")?;
    write_run(&run, &args.out)?;
    if args.rois {
        let reflections = args.reflections.map(|fraction| ReflectionFault {
            fraction,
            ..Default::default()
        });
        let mut writer = roitrack::formats::RoiRecordingWriter::create(args.out.join(ROIS_FILE))?;
        for image in render_roi_images(
            &scenario,
            &options,
            &run,
            SensorModel::default(),
            reflections,
        )? {
            writer.write(&image?)?;
        }
        writer.finish()?;
    }
    eprintln!(
        "roitrack: {} scenario: {} measurements over {:.3} s written to {}",
        scenario.kind.name(),
        run.measurements.len(),
        scenario.duration_s,
        args.out.display()
    );
    Ok(())
}

/// Writes the five files of a simulated run into `dir` (created if missing).
pub fn write_run(run: &SimulatedRun, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create folder {}", dir.display()))?;
    roitrack::formats::write_camera_yaml(dir.join(CAMERA_FILE), &run.camera)?;
    roitrack::formats::write_target_csv(dir.join(TARGET_FILE), &run.target)?;
    roitrack::formats::write_measurements_csv(dir.join(MEASUREMENTS_FILE), &run.measurements)?;
    roitrack::formats::write_tum(dir.join(TRUTH_POSES_FILE), &run.truth_poses)?;
    roitrack::formats::write_twists_csv(dir.join(TRUTH_TWISTS_FILE), &run.truth_twists)?;
    Ok(())
}
