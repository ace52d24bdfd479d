//! `roitrack`: high-rate pose and velocity tracking from sequential ROI centroids.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;

#[derive(Debug, Parser)]
#[command(name = "roitrack", version, about, long_about = None)]
/// Track the 3-D pose and velocity of a rigid target from timestamped blob centroids (one ROI at a time).
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    Demo(commands::demo::DemoArgs),
    Bench(commands::bench::BenchArgs),
    Simulate(commands::simulate::SimulateArgs),
    Track(commands::track::TrackArgs),
    Eval(commands::eval::EvalArgs),
    Target(commands::target::TargetArgs),
    Tradeoff(commands::tradeoff::TradeoffArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => commands::demo::run(&args),
        Command::Bench(args) => commands::bench::run(&args),
        Command::Simulate(args) => commands::simulate::run(&args),
        Command::Track(args) => commands::track::run(&args),
        Command::Eval(args) => commands::eval::run(&args),
        Command::Target(args) => commands::target::run(&args),
        Command::Tradeoff(args) => commands::tradeoff::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("roitrack: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
