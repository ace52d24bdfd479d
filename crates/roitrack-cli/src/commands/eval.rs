//! `roitrack eval`: score estimated poses and twists against ground truth (see [`roitrack::eval`]).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use roitrack::eval::{Alignment, EvalOptions, TimeOffset, evaluate};

use super::simulate::{TRUTH_POSES_FILE, TRUTH_TWISTS_FILE};
use crate::ranges;

/// Score an estimated trajectory against ground truth: position, rotation, velocity and angular-velocity RMSE, max
/// position error, velocity lag; optionally after a clock offset and an alignment of frames, and the relative pose
/// error over an interval. The JSON output's fields are documented in docs/evaluation.md.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Folder holding gt_poses.tum and gt_twists.csv (as written by `roitrack simulate`).
    /// Default: none; this or --truth-poses is required.
    #[arg(long, conflicts_with_all = ["truth_poses", "truth_twists"], required_unless_present = "truth_poses")]
    pub truth: Option<PathBuf>,
    /// True poses (TUM: t x y z qx qy qz qw), any file name; instead of --truth. Default: none (then --truth).
    #[arg(long)]
    pub truth_poses: Option<PathBuf>,
    /// True twists (CSV t,vx,vy,vz,wx,wy,wz), at the true poses' times; with --truth-poses. Default: none (no
    /// velocity metrics).
    #[arg(long, requires = "truth_poses")]
    pub truth_twists: Option<PathBuf>,
    /// Estimated poses (TUM).
    #[arg(long)]
    pub poses: PathBuf,
    /// Estimated twists (CSV t,vx,vy,vz,wx,wy,wz), same times as the poses. Velocity metrics need twists on both
    /// sides. Default: none (no velocity metrics).
    #[arg(long)]
    pub twists: Option<PathBuf>,
    /// Transformation of the estimates onto the truth's frame, fitted to the paired positions (Umeyama): none (both
    /// in the camera frame, as simulated truth is), se3 (rotation and translation: truth in another frame, e.g. a
    /// motion-capture system's), sim3 (also a scale: a target or calibration of the wrong size).
    #[arg(long, value_enum, default_value_t = AlignArg::None)]
    pub align: AlignArg,
    /// Seconds added to the estimates' times to put them on the truth's clock, or `auto` to find the offset from the
    /// motion (speeds correlated within --max-time-offset-s, then refined on the positions).
    #[arg(long, default_value = "0", value_parser = parse_time_offset)]
    pub time_offset: TimeOffset,
    /// With --time-offset auto, the largest offset searched (s, at most an hour).
    #[arg(long, default_value_t = 5.0, value_parser = ranges::within(0.0..=3600.0, " s", "an hour"))]
    pub max_time_offset_s: f64,
    /// Also the relative pose error over this interval (s): the error of the target's estimated motion between
    /// estimates this far apart, independent of the frames and of a constant offset of the pose. Default: not
    /// computed.
    #[arg(long, value_parser = ranges::positive_up_to(86_400.0, " s", "a day"))]
    pub rpe_interval_s: Option<f64>,
    /// Leave out (and count) the estimates outside the truth's time span instead of refusing them.
    #[arg(long)]
    pub skip_outside_truth: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// The largest poses or twists file read (MiB; each is read whole, about half its size in memory). Default:
    /// 2048 (about 15 million poses, an hour of ground truth at 4 kHz).
    #[arg(long, value_name = "MIB", default_value_t = 2048, value_parser = ranges::count(1..=1 << 20, "up to a terabyte"))]
    pub max_file_mib: usize,
}

/// `--align`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AlignArg {
    None,
    Se3,
    Sim3,
}

/// The library's alignment for `--align`.
pub fn alignment(align: AlignArg) -> Alignment {
    match align {
        AlignArg::None => Alignment::None,
        AlignArg::Se3 => Alignment::Se3,
        AlignArg::Sim3 => Alignment::Sim3,
    }
}

fn parse_time_offset(text: &str) -> Result<TimeOffset, String> {
    if text.eq_ignore_ascii_case("auto") {
        return Ok(TimeOffset::Auto);
    }
    match text.parse::<f64>() {
        Ok(offset) if offset.is_finite() => Ok(TimeOffset::Fixed(offset)),
        _ => Err(format!(
            "`{text}` is neither a number of seconds nor `auto`"
        )),
    }
}

pub fn run(args: &EvalArgs) -> Result<()> {
    let (truth_poses_path, truth_twists_path) = match (&args.truth, &args.truth_poses) {
        (Some(dir), None) => (
            dir.join(TRUTH_POSES_FILE),
            args.twists.as_ref().map(|_| dir.join(TRUTH_TWISTS_FILE)),
        ),
        (None, Some(poses)) => (poses.clone(), args.truth_twists.clone()),
        _ => bail!("give the truth as --truth DIR or as --truth-poses FILE [--truth-twists FILE]"),
    };
    let max_bytes = (args.max_file_mib as u64) << 20;
    let read_tum = |path| roitrack::formats::read_tum_limited(path, max_bytes);
    let read_twists = |path| roitrack::formats::read_twists_csv_limited(path, max_bytes);
    let truth_poses = read_tum(&truth_poses_path)?;
    let estimated_poses = read_tum(&args.poses)?;
    let (truth_twists, estimated_twists) = match (&truth_twists_path, &args.twists) {
        (Some(truth), Some(estimated)) => {
            (Some(read_twists(truth)?), Some(read_twists(estimated)?))
        }
        (None, Some(_)) => bail!(
            "--twists needs the true twists too: --truth-twists FILE (or --truth DIR with gt_twists.csv)"
        ),
        _ => (None, None),
    };
    let options = EvalOptions {
        time_offset: args.time_offset,
        max_time_offset_s: args.max_time_offset_s,
        alignment: alignment(args.align),
        rpe_interval_s: args.rpe_interval_s,
        skip_outside_truth: args.skip_outside_truth,
        ..EvalOptions::default()
    };
    let metrics = evaluate(
        &truth_poses,
        truth_twists.as_deref(),
        &estimated_poses,
        estimated_twists.as_deref(),
        &options,
    )
    .with_context(|| {
        format!(
            "evaluating {} against {}",
            args.poses.display(),
            truth_poses_path.display()
        )
    })?;
    if args.json {
        println!("{}", metrics.to_json());
    } else {
        print!("{}", metrics.to_table());
    }
    Ok(())
}
