//! `roitrack lab pnp-bench`: times the static pose solver on a stored PnP problem, or solves a suite of one-instance
//! problems (see [`roitrack::bench::pnp`]).

use std::path::PathBuf;

use anyhow::{Context, Result, ensure};
use clap::Args;
use roitrack::bench::pnp::{self, PnpProblem, PnpSuite};

/// Time the static pose solver on a stored PnP problem (the file the OpenCV comparison reads), or solve a suite of
/// problems (bench/pnp_families.py) and report each one's poses and time.
#[derive(Debug, Args)]
pub struct PnpBenchArgs {
    /// Problem file (JSON, format roitrack-pnp-problem/1, as written by bench/opencv_compare.py). Default: none;
    /// this or --suite is required.
    #[arg(long, required_unless_present = "suite", conflicts_with = "suite")]
    pub problem: Option<PathBuf>,
    /// Suite file (JSON, format roitrack-pnp-suite/1, as written by bench/pnp_families.py): per problem, its family,
    /// the poses found (best first), whether ambiguous, and the median solve time over --repeats. Default: none
    /// (then --problem).
    #[arg(long)]
    pub suite: Option<PathBuf>,
    /// Timed solves of each instance (all instances are solved once per repetition, in turn; a suite's problems are
    /// each timed this many times in a row).
    #[arg(long, default_value_t = 20, value_parser = crate::ranges::count(1..=100_000, "a median of a hundred thousand is steady"))]
    pub repeats: usize,
    /// Print one JSON object (summary, the pose found for each instance, every solve's time) instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &PnpBenchArgs) -> Result<()> {
    ensure!(args.repeats >= 1, "--repeats must be at least 1");
    if let Some(path) = &args.suite {
        // The library names the file, the problem and the field.
        let suite = PnpSuite::read(path)?;
        let report = pnp::run_suite(&suite, args.repeats);
        let name = path.display().to_string();
        if args.json {
            println!("{}", report.to_json(&name));
        } else {
            print!("{}", report.to_table(&name));
        }
        return Ok(());
    }
    // clap requires one of --problem and --suite.
    let Some(path) = &args.problem else {
        anyhow::bail!("give --problem FILE or --suite FILE");
    };
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
