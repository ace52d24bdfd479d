//! `roitrack pnp-bench`: times the static pose solver on a stored PnP problem (see [`roitrack::bench::pnp`]).

use std::path::PathBuf;

use anyhow::{Context, Result, ensure};
use clap::Args;
use roitrack::bench::pnp::{self, PnpProblem};

/// Time the static pose solver on a stored PnP problem (the file the OpenCV comparison reads).
#[derive(Debug, Args)]
pub struct PnpBenchArgs {
    /// Problem file (JSON, format roitrack-pnp-problem/1, as written by bench/opencv_compare.py).
    #[arg(long)]
    pub problem: PathBuf,
    /// Timed solves of each instance (all instances are solved once per repetition, in turn).
    #[arg(long, default_value_t = 20)]
    pub repeats: usize,
    /// Print one JSON object (summary, the pose found for each instance, every solve's time) instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &PnpBenchArgs) -> Result<()> {
    ensure!(args.repeats >= 1, "--repeats must be at least 1");
    let path = &args.problem;
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the problem file {}", path.display()))?;
    let problem =
        PnpProblem::from_json(&text).with_context(|| format!("problem file {}", path.display()))?;
    let report = pnp::run(&problem, args.repeats);
    let name = path.display().to_string();
    if args.json {
        println!("{}", report.to_json(&name));
    } else {
        print!("{}", report.to_table(&name));
    }
    Ok(())
}
