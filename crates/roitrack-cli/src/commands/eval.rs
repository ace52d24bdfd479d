//! `roitrack eval`: score estimated poses and twists against ground truth (see [`roitrack::eval`]).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use roitrack::eval::{EvalOptions, evaluate};

use super::simulate::{TRUTH_POSES_FILE, TRUTH_TWISTS_FILE};

/// Score an estimated trajectory against ground truth: position, rotation, velocity and angular-velocity RMSE, max
/// position error, velocity lag.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Folder holding gt_poses.tum and gt_twists.csv (as written by `roitrack simulate`).
    #[arg(long)]
    pub truth: PathBuf,
    /// Estimated poses (TUM).
    #[arg(long)]
    pub poses: PathBuf,
    /// Estimated twists (CSV t,vx,vy,vz,wx,wy,wz), same times as the poses.
    #[arg(long)]
    pub twists: Option<PathBuf>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &EvalArgs) -> Result<()> {
    let truth_poses = roitrack::formats::read_tum(args.truth.join(TRUTH_POSES_FILE))?;
    let estimated_poses = roitrack::formats::read_tum(&args.poses)?;
    let (truth_twists, estimated_twists) = match &args.twists {
        Some(path) => (
            Some(roitrack::formats::read_twists_csv(
                args.truth.join(TRUTH_TWISTS_FILE),
            )?),
            Some(roitrack::formats::read_twists_csv(path)?),
        ),
        None => (None, None),
    };
    let metrics = evaluate(
        &truth_poses,
        truth_twists.as_deref(),
        &estimated_poses,
        estimated_twists.as_deref(),
        &EvalOptions::default(),
    )?;
    if args.json {
        println!("{}", metrics.to_json());
    } else {
        print!("{}", metrics.to_table());
    }
    Ok(())
}
