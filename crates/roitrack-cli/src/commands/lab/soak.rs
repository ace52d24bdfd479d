//! `roitrack lab soak`: a long run at full speed, to show that nothing drifts or grows (see [`roitrack::bench::soak`]).

use anyhow::Result;
use clap::Args;

/// Track a long simulated stream at full speed and report, per simulated minute, accuracy, time and memory.
#[derive(Debug, Args)]
pub struct SoakArgs {
    /// Length of the simulated stream (minutes at 4 kHz), at most a day.
    #[arg(long, default_value_t = 10.0, value_parser = crate::ranges::positive_up_to(1440.0, " min", "a day"))]
    pub minutes: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &SoakArgs) -> Result<()> {
    let report = roitrack::bench::soak::run(args.minutes)?;
    if args.json {
        println!("{}", report.to_json());
    } else {
        print!("{}", report.to_table());
    }
    Ok(())
}
