//! `roitrack lab compare`: every estimator and baseline on one scenario at the measurement level (see
//! [`roitrack::experiments::compare`]); with `--sweep`, the default Kalman filter against hand-tuned ones on every
//! case of the adaptive-estimation study (see [`roitrack::experiments::adaptive`]).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use anyhow::{Result, bail};
use clap::Args;
use roitrack::experiments::adaptive::{SweepOptions, sweep};
use roitrack::experiments::compare;

use crate::args::ScenarioArg;

/// Track one simulated scenario with every estimator and baseline and print their accuracy; or, with `--sweep`,
/// the default (adaptive) Kalman filter against hand-tuned filters searched over a grid, on every case of the sweep,
/// with the calibration of its covariance: the table of docs/results.md in markdown.
#[derive(Debug, Args)]
pub struct CompareArgs {
    #[arg(
        long,
        value_enum,
        default_value = "orthoglide",
        conflicts_with = "sweep"
    )]
    pub scenario: ScenarioArg,
    #[arg(long, default_value_t = 1, conflicts_with = "sweep")]
    pub seed: u64,
    /// Centroid noise (px, per axis).
    #[arg(long, default_value_t = 0.1, conflicts_with = "sweep", value_parser = crate::ranges::within(0.0..=roitrack::estimators::MAX_NOISE_PX, " px", "more than a ROI's half-width is no centroid"))]
    pub noise_px: f64,
    /// The scenario on your own rig (not with --sweep, whose cases are fixed).
    #[command(flatten)]
    pub rig: crate::args::RigArgs,
    /// Print one JSON object per estimator instead of a table (with --sweep: one JSON object with every case,
    /// check and grid point).
    #[arg(long)]
    pub json: bool,
    /// Run the adaptive-estimation sweep: every case, the hand-tuned grid, the targets checked.
    #[arg(long)]
    pub sweep: bool,
    /// With --sweep: a smoke run (a few cases cut to 0.6 s, a small grid), not the table of record.
    #[arg(long, requires = "sweep")]
    pub quick: bool,
    /// With --sweep: exit with a failure naming the targets that do not hold (after printing everything).
    #[arg(long, requires = "sweep")]
    pub check: bool,
    /// With --sweep: simulate every case with these seeds (comma-separated) and pool each case's figures over them.
    /// Default: each case's own seed (1), the table of record.
    #[arg(long, requires = "sweep", value_delimiter = ',', num_args = 1..)]
    pub seeds: Option<Vec<u64>>,
}

pub fn run(args: &CompareArgs) -> Result<()> {
    if args.sweep {
        if args.rig.is_given() {
            anyhow::bail!(
                "--sweep runs its own fixed cases: --camera, --target, --distance-m, --speed-scale and --duration-s \
                 are for a single comparison"
            );
        }
        return run_sweep(args);
    }
    let scenario = args.rig.scenario(roitrack::sim::Scenario::new(
        args.scenario.into(),
        args.seed,
    ))?;
    let rows = compare::compare_on(&scenario, args.seed, args.noise_px)?;
    if args.json {
        for row in &rows {
            println!("{}", compare::json(row));
        }
    } else {
        print!("{}", compare::table(&rows));
    }
    Ok(())
}

fn run_sweep(args: &CompareArgs) -> Result<()> {
    let mut options = if args.quick {
        SweepOptions::quick()
    } else {
        SweepOptions::full()
    };
    if let Some(seeds) = &args.seeds {
        options = options.with_seeds(seeds);
    }
    // Drawn on stderr, only when it is a terminal: the table on stdout stays clean.
    let bar = indicatif::ProgressBar::new(options.cases.len() as u64).with_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} cases ({elapsed})")
            .expect("valid progress template"),
    );
    let done = AtomicUsize::new(0);
    let finished = AtomicBool::new(false);
    let result = std::thread::scope(|scope| {
        scope.spawn(|| {
            while !finished.load(Ordering::Relaxed) {
                bar.set_position(done.load(Ordering::Relaxed) as u64);
                std::thread::sleep(Duration::from_millis(200));
            }
        });
        // Set on the way out, a panic of the sweep's included: the progress thread then ends, and the scope with it
        // (a panic used to leave the process waiting for that thread for ever).
        struct Finish<'a>(&'a AtomicBool);
        impl Drop for Finish<'_> {
            fn drop(&mut self) {
                self.0.store(true, Ordering::Relaxed);
            }
        }
        let _finish = Finish(&finished);
        sweep(&options, Some(&done))
    })?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", result.json());
    } else {
        print!("{}", result.markdown());
    }
    let failures = result.failures();
    if args.check && !failures.is_empty() {
        bail!(
            "{} target(s) do not hold:\n  {}",
            failures.len(),
            failures.join("\n  ")
        );
    }
    Ok(())
}
