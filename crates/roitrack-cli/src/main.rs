//! `roitrack`: high-rate pose and velocity tracking from sequential ROI centroids.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod args;
mod commands;
mod ranges;
mod ros;

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
    Compare(commands::compare::CompareArgs),
    Soak(commands::soak::SoakArgs),
    // Boxed: its many options make it the largest variant by far.
    Simulate(Box<commands::simulate::SimulateArgs>),
    // Boxed: the largest arguments by far (the --mcap and --mcap-in options made the enum trip clippy's size check).
    Track(Box<commands::track::TrackArgs>),
    Eval(commands::eval::EvalArgs),
    Plot(commands::plot::PlotArgs),
    Detect(commands::detect::DetectArgs),
    Target(commands::target::TargetArgs),
    Tradeoff(commands::tradeoff::TradeoffArgs),
    PnpBench(commands::pnp_bench::PnpBenchArgs),
    Faults(commands::faults::FaultsArgs),
    FrameStudy(commands::frame_study::FrameStudyArgs),
    #[cfg(feature = "genicam")]
    Live(Box<commands::live::LiveArgs>),
    #[cfg(feature = "genicam")]
    Cameras(commands::live::CamerasArgs),
}

fn main() -> ExitCode {
    // Like other command-line tools, end quietly when the reader of our output goes away (`roitrack eval | head`)
    // instead of panicking on a broken pipe.
    #[cfg(unix)]
    // SAFETY: called first thing in main, before any other thread exists; restores the default signal action.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => commands::demo::run(&args),
        Command::Bench(args) => commands::bench::run(&args),
        Command::Compare(args) => commands::compare::run(&args),
        Command::Soak(args) => commands::soak::run(&args),
        Command::Simulate(args) => commands::simulate::run(&args),
        Command::Track(args) => commands::track::run(&args),
        Command::Eval(args) => commands::eval::run(&args),
        Command::Plot(args) => commands::plot::run(&args),
        Command::Detect(args) => commands::detect::run(&args),
        Command::Target(args) => commands::target::run(&args),
        Command::Tradeoff(args) => commands::tradeoff::run(&args),
        Command::PnpBench(args) => commands::pnp_bench::run(&args),
        Command::Faults(args) => commands::faults::run(&args),
        Command::FrameStudy(args) => commands::frame_study::run(&args),
        #[cfg(feature = "genicam")]
        Command::Live(args) => commands::live::run(&args),
        #[cfg(feature = "genicam")]
        Command::Cameras(args) => commands::live::cameras(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("roitrack: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
