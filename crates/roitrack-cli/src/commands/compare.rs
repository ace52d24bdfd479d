//! `roitrack compare`: every estimator and baseline on one scenario at the measurement level (see
//! [`roitrack::experiments::compare`]).

use anyhow::Result;
use clap::Args;
use roitrack::experiments::compare;

use crate::args::ScenarioArg;

/// Track one simulated scenario with every estimator and baseline and print their accuracy.
#[derive(Debug, Args)]
pub struct CompareArgs {
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Centroid noise (px, per axis).
    #[arg(long, default_value_t = 0.1)]
    pub noise_px: f64,
    /// Print one JSON object per estimator instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &CompareArgs) -> Result<()> {
    let rows = compare::compare(args.scenario.into(), args.seed, args.noise_px)?;
    if args.json {
        for row in &rows {
            println!("{}", compare::json(row));
        }
    } else {
        print!("{}", compare::table(&rows));
    }
    Ok(())
}
