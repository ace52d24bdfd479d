//! `roitrack lab ...` (feature `lab`): the studies behind the tables of docs/results.md and the benchmarks, apart
//! from the commands a user runs.

use anyhow::Result;
use clap::{Args, Subcommand};

pub mod bench;
pub mod compare;
pub mod faults;
pub mod frame_study;
pub mod pnp_bench;
pub mod soak;
pub mod tradeoff;

/// The lab: the studies behind docs/results.md (estimator comparison and adaptive sweep, faults, velocity-lag
/// trade-off, frame cameras) and the benchmarks (hot paths and the real-time loop, a long run, the PnP solver).
#[derive(Debug, Args)]
pub struct LabArgs {
    #[command(subcommand)]
    command: LabCommand,
}

#[derive(Debug, Subcommand)]
enum LabCommand {
    Bench(bench::BenchArgs),
    Compare(compare::CompareArgs),
    Faults(faults::FaultsArgs),
    FrameStudy(frame_study::FrameStudyArgs),
    PnpBench(pnp_bench::PnpBenchArgs),
    Soak(soak::SoakArgs),
    Tradeoff(tradeoff::TradeoffArgs),
}

pub fn run(args: &LabArgs) -> Result<()> {
    match &args.command {
        LabCommand::Bench(args) => bench::run(args),
        LabCommand::Compare(args) => compare::run(args),
        LabCommand::Faults(args) => faults::run(args),
        LabCommand::FrameStudy(args) => frame_study::run(args),
        LabCommand::PnpBench(args) => pnp_bench::run(args),
        LabCommand::Soak(args) => soak::run(args),
        LabCommand::Tradeoff(args) => tradeoff::run(args),
    }
}
