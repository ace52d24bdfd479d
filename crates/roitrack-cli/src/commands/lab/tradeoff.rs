//! `roitrack lab tradeoff`: velocity noise against velocity lag (see [`roitrack::experiments::tradeoff`]); writes a CSV and
//! a plot (PNG and SVG).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use roitrack::experiments::tradeoff;

use crate::args::ScenarioArg;

/// Velocity RMSE against velocity lag: the paper's loop at gains 0.2-1.0 and the Kalman filter over its tuning range.
#[derive(Debug, Args)]
pub struct TradeoffArgs {
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder for tradeoff.csv, tradeoff.png and tradeoff.svg.
    #[arg(long, default_value = "out/tradeoff")]
    pub out: PathBuf,
    /// The scenario on your own rig.
    #[command(flatten)]
    pub rig: crate::args::RigArgs,
}

pub fn run(args: &TradeoffArgs) -> Result<()> {
    let scenario = args.rig.scenario(roitrack::sim::Scenario::new(
        args.scenario.into(),
        args.seed,
    ))?;
    args.rig
        .check_outputs(&args.out, &["tradeoff.csv", "tradeoff.png", "tradeoff.svg"])?;
    let points = tradeoff::sweep_on(&scenario, args.seed)?;
    roitrack::formats::create_output_dir(&args.out)?;
    let mut csv = roitrack::formats::AtomicFile::create(args.out.join("tradeoff.csv"))?;
    writeln!(csv, "{}", tradeoff::CSV_HEADER)?;
    println!("{}", tradeoff::table_header());
    for p in &points {
        writeln!(csv, "{}", tradeoff::csv_row(p))?;
        println!("{}", tradeoff::table_row(p));
    }
    csv.finish()?;
    let chart = tradeoff::chart(&points, args.scenario.into(), args.seed);
    let paths = crate::commands::plot::write_figure_files(
        &args.out,
        &roitrack::plot::render_chart("tradeoff", &chart)?,
    )?;
    let (png, svg) = (&paths[0], &paths[1]);
    eprintln!(
        "roitrack: wrote {}, {} and tradeoff.csv",
        png.display(),
        svg.display()
    );
    Ok(())
}
