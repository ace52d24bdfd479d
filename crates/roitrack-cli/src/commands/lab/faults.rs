//! `roitrack lab faults`: the default estimator under faults (see [`roitrack::experiments::faults`]).

use anyhow::Result;
use clap::Args;
use roitrack::experiments::faults;

/// Run the default estimator on clean and faulty simulated measurements (orthoglide and random scenarios, seed 1,
/// 0.1 px, 4 kHz, bit-reversed order) and print a fault table.
#[derive(Debug, Args)]
pub struct FaultsArgs {
    /// Print one JSON object per row instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Only the orthoglide scenario and three rows (for tests).
    #[arg(long, hide = true)]
    pub quick: bool,
}

pub fn run(args: &FaultsArgs) -> Result<()> {
    if !args.json {
        println!("{}", faults::header());
    }
    for &kind in faults::scenarios(args.quick) {
        for row in faults::scenario_rows(kind, args.quick)? {
            if args.json {
                println!("{}", row.to_json());
            } else {
                println!("{}", faults::line(&row));
            }
        }
    }
    if !args.json {
        println!("{}", faults::footnote());
    }
    Ok(())
}
