//! `roitrack`: high-rate pose and velocity tracking from sequential ROI centroids.

use std::process::ExitCode;

#[cfg(feature = "ros2")]
use clap::CommandFactory;
use clap::{Parser, Subcommand};

mod args;
mod commands;
#[cfg(feature = "ros2")]
mod params_file;
mod ranges;
mod ros;
mod ros2_args;
mod signals;

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
    // Boxed: its many options make it the largest variant by far.
    Simulate(Box<commands::simulate::SimulateArgs>),
    // Boxed: the largest arguments by far (the --mcap and --mcap-in options made the enum trip clippy's size check).
    Track(Box<commands::track::TrackArgs>),
    CalibrateRig(commands::calibrate_rig::CalibrateRigArgs),
    Eval(commands::eval::EvalArgs),
    Plot(commands::plot::PlotArgs),
    Detect(commands::detect::DetectArgs),
    Target(commands::target::TargetArgs),
    Servo(commands::servo::ServoArgs),
    #[cfg(feature = "lab")]
    Lab(commands::lab::LabArgs),
    #[cfg(feature = "genicam")]
    Live(Box<commands::live::LiveArgs>),
    #[cfg(feature = "genicam")]
    Cameras(commands::live::CamerasArgs),
    #[cfg(feature = "ros2")]
    Ros2Node(Box<commands::ros2_node::Ros2NodeArgs>),
}

/// The error of a run whose outputs stand all the same: they are moved into place, then the error is reported and the
/// command fails (`detect` with some images failed keeps the others' overlays; `live` ended by its camera keeps the
/// estimates until then).
#[derive(Debug)]
pub struct OutputsStand(pub String);

impl std::fmt::Display for OutputsStand {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for OutputsStand {}

/// The studies and benchmarks, once top-level commands, now under `roitrack lab` (feature `lab`).
const LAB_COMMANDS: [&str; 7] = [
    "bench",
    "compare",
    "faults",
    "frame-study",
    "pnp-bench",
    "soak",
    "tradeoff",
];

/// How to build a binary with the lab.
const LAB_BUILD: &str = "cargo build --release -p roitrack-cli --features lab";

/// The error for a command that moved to the lab (`roitrack compare`), or for the lab in a binary built without it.
fn moved_to_the_lab(command: Option<std::ffi::OsString>) -> Option<String> {
    let command = command?;
    let command = command.to_str()?;
    let build = if cfg!(feature = "lab") {
        String::new()
    } else {
        format!(", in a binary built with the cargo feature lab ({LAB_BUILD})")
    };
    if LAB_COMMANDS.contains(&command) {
        return Some(format!(
            "`{command}` is a study or benchmark: it is `roitrack lab {command}` now{build}"
        ));
    }
    (command == "lab" && !cfg!(feature = "lab")).then(|| {
        format!(
            "`roitrack lab` (the studies and benchmarks: {}) is not in this binary: build it with the cargo feature \
             lab ({LAB_BUILD})",
            LAB_COMMANDS.join(", ")
        )
    })
}

/// The command line, parsed; `ros2-node --params-file FILE` first puts the file's parameters before the node's own
/// options (src/params_file.rs). A command line that clap refuses, or a parameters file that is wrong, ends the
/// process with its code.
fn parse() -> Result<Cli, ExitCode> {
    #[cfg(feature = "ros2")]
    if std::env::args_os().nth(1).is_some_and(|c| c == "ros2-node") {
        let given: Vec<std::ffi::OsString> = std::env::args_os().collect();
        let argv = match params_file::expand(given.clone(), &Cli::command()) {
            Ok(argv) => argv,
            Err(e) => {
                eprintln!("roitrack: error: {e:#}");
                return Err(ExitCode::from(2));
            }
        };
        let from_file = argv.len() != given.len();
        return Cli::try_parse_from(argv).map_err(|e| {
            let _ = e.print();
            if from_file && e.use_stderr() {
                eprintln!("roitrack: note: some of these options came from the --params-file");
            }
            ExitCode::from(e.exit_code().clamp(0, 255) as u8)
        });
    }
    Ok(Cli::parse())
}

fn main() -> ExitCode {
    // SIGINT, SIGTERM, SIGHUP and SIGPIPE alike (src/signals.rs). A reader of our output that goes away
    // (`roitrack eval | head`) still ends the process quietly, by SIGPIPE, as the default action did.
    signals::install();
    if let Some(message) = moved_to_the_lab(std::env::args_os().nth(1)) {
        eprintln!("roitrack: error: {message}");
        return ExitCode::from(2);
    }
    let cli = match parse() {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    // The commands that track or render stop at their next estimate at the first signal, keeping what they promise;
    // the others end at once.
    if matches!(
        cli.command,
        Command::Demo(_)
            | Command::Simulate(_)
            | Command::Track(_)
            | Command::CalibrateRig(_)
            | Command::Detect(_)
    ) {
        signals::stop_at_next_estimate();
    }
    #[cfg(feature = "genicam")]
    if matches!(cli.command, Command::Live(_)) {
        signals::stop_at_next_estimate();
    }
    // A node runs until the first signal, then writes its outputs.
    #[cfg(feature = "ros2")]
    if matches!(cli.command, Command::Ros2Node(_)) {
        signals::stop_at_next_estimate();
    }
    // Every output of the run (files, bags, figures, folders) is written to a temporary and moved into place only
    // when the whole run has succeeded: a failed or interrupted run leaves every previous output as it was.
    let outputs = roitrack::formats::OutputSet::begin();
    let result = match cli.command {
        Command::Demo(args) => commands::demo::run(&args),
        Command::Simulate(args) => commands::simulate::run(&args),
        Command::Track(args) => commands::track::run(&args),
        Command::CalibrateRig(args) => commands::calibrate_rig::run(&args),
        Command::Eval(args) => commands::eval::run(&args),
        Command::Plot(args) => commands::plot::run(&args),
        Command::Detect(args) => commands::detect::run(&args),
        Command::Target(args) => commands::target::run(&args),
        Command::Servo(args) => commands::servo::run(&args),
        #[cfg(feature = "lab")]
        Command::Lab(args) => commands::lab::run(&args),
        #[cfg(feature = "genicam")]
        Command::Live(args) => commands::live::run(&args),
        #[cfg(feature = "genicam")]
        Command::Cameras(args) => commands::live::cameras(&args),
        #[cfg(feature = "ros2")]
        Command::Ros2Node(args) => commands::ros2_node::run(&args),
    };
    let signal = signals::received();
    // An error after which the outputs stand (`detect` with some images failed, `live` ended by its camera).
    let stands = matches!(&result, Err(e) if e.downcast_ref::<OutputsStand>().is_some());
    if signal.is_none() && stands {
        let committed = outputs.commit();
        if let Err(error) = result.and(committed.map_err(anyhow::Error::new)) {
            eprintln!("roitrack: error: {error:#}");
        }
        return ExitCode::FAILURE;
    }
    if let (Ok(()), None) = (&result, signal) {
        return match outputs.commit() {
            Ok(()) => ExitCode::SUCCESS,
            Err(error) => {
                eprintln!(
                    "roitrack: error: the run succeeded, but its outputs could not all be moved into place: {error}"
                );
                ExitCode::FAILURE
            }
        };
    }
    // Failed or interrupted: no output is moved into place; a partial result that was promised is kept under its
    // own name.
    let kept = outputs.abandon();
    // A reader that went away (SIGPIPE) wants no message.
    if signal != Some(signals::SIGPIPE) {
        match &result {
            Err(error) => eprintln!("roitrack: error: {error:#}"),
            Ok(()) => eprintln!(
                "roitrack: interrupted ({}) before the outputs were moved into place",
                signals::name(signal.unwrap_or_default())
            ),
        }
    }
    for path in &kept {
        eprintln!(
            "roitrack: the outputs are as they were; kept {}, the partial result up to the run's last estimate",
            path.display()
        );
    }
    match signal {
        Some(signal) => signals::end_by(signal),
        None => ExitCode::FAILURE,
    }
}
