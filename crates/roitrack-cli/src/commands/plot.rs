//! `roitrack plot`: the figures of one tracking run from its files (see [`roitrack::plot::run`]).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use roitrack::eval::{EvalOptions, TimeOffset, estimate_errors};
use roitrack::plot::RenderedFile;
use roitrack::plot::run::{RunFigureInputs, render_run_figures};

use super::eval::AlignArg;
use super::simulate::{TRUTH_POSES_FILE, TRUTH_TWISTS_FILE};

/// Plot a run: position, orientation (rotation vector), linear and angular velocity against time; with a truth, their
/// errors with ±3 sigma bands from the estimator's covariance; with diagnostics, the status and residual over time.
/// Writes motion, errors and status as PNG and SVG into --out.
#[derive(Debug, Args)]
pub struct PlotArgs {
    /// Estimated poses (TUM).
    #[arg(long)]
    pub poses: PathBuf,
    /// Estimated twists (CSV t,vx,vy,vz,wx,wy,wz), same times as the poses. Default: none (no velocity panels).
    #[arg(long)]
    pub twists: Option<PathBuf>,
    /// The diagnostics CSV of the same run (status, residual, position and velocity sigmas). Default: none.
    #[arg(long)]
    pub diagnostics: Option<PathBuf>,
    /// The covariance CSV of the same run: sigmas of all 12 components, for the rotation and angular-velocity bands
    /// too. Default: none (bands from --diagnostics, position and velocity only).
    #[arg(long)]
    pub covariance: Option<PathBuf>,
    /// Folder holding gt_poses.tum and gt_twists.csv (as written by `roitrack simulate`). Default: no truth.
    #[arg(long, conflicts_with_all = ["truth_poses", "truth_twists"])]
    pub truth: Option<PathBuf>,
    /// True poses (TUM), any file name; instead of --truth. Default: none (no error figure).
    #[arg(long)]
    pub truth_poses: Option<PathBuf>,
    /// True twists (CSV); with --truth-poses. Default: none (no velocity error panels).
    #[arg(long, requires = "truth_poses")]
    pub truth_twists: Option<PathBuf>,
    /// Alignment of the estimates onto the truth's frame before the errors are drawn, as in `roitrack eval`.
    #[arg(long, value_enum, default_value_t = AlignArg::None)]
    pub align: AlignArg,
    /// Seconds added to the estimates' times to put them on the truth's clock, as in `roitrack eval`.
    #[arg(long, default_value_t = 0.0, value_parser = crate::ranges::within(-1e9..=1e9, " s", "over 30 years"), allow_negative_numbers = true)]
    pub time_offset: f64,
    /// Folder for the figures (created if needed).
    #[arg(long)]
    pub out: PathBuf,
    /// The largest poses, twists, diagnostics or covariance file read (MiB; each is read whole). Default: 2048
    /// (about 15 million poses, an hour of ground truth at 4 kHz).
    #[arg(long, value_name = "MIB", default_value_t = 2048, value_parser = crate::ranges::count(1..=1 << 20, "up to a terabyte"))]
    pub max_file_mib: usize,
}

pub fn run(args: &PlotArgs) -> Result<()> {
    check_plot_paths(args)?;
    let max_bytes = (args.max_file_mib as u64) << 20;
    let read_tum = |path: &PathBuf| roitrack::formats::read_tum_limited(path, max_bytes);
    let read_twists = |path: &PathBuf| roitrack::formats::read_twists_csv_limited(path, max_bytes);
    let poses = read_tum(&args.poses)?;
    let twists = args.twists.as_ref().map(read_twists).transpose()?;
    let times: Vec<f64> = poses.iter().map(|p| p.t_s).collect();
    // Side files must be of the same run: one row per estimate, at its time.
    let run = SameRun {
        times: &times,
        poses_path: &args.poses,
    };
    if let (Some(path), Some(twists)) = (&args.twists, &twists) {
        run.check(
            "twist",
            path,
            &twists.iter().map(|t| t.t_s).collect::<Vec<_>>(),
        )?;
    }
    let diagnostics = read_side_file(args.diagnostics.as_ref(), "diagnostics", &run, |path| {
        roitrack::formats::read_diagnostics_csv_limited(path, max_bytes)
    })?;
    let covariance = read_side_file(args.covariance.as_ref(), "covariance", &run, |path| {
        roitrack::formats::read_covariance_csv_limited(path, max_bytes)
    })?;
    let sigmas = band_sigmas(covariance.as_deref(), diagnostics.as_deref());
    let (truth_poses_path, truth_twists_path) = truth_paths(args);
    let truth_poses = truth_poses_path.as_ref().map(read_tum).transpose()?;
    let truth_twists = match (&truth_twists_path, &twists) {
        // With --truth DIR the twists are read only when the estimates have twists to compare.
        (Some(path), Some(_)) if args.truth.is_none() || path.is_file() => Some(read_twists(path)?),
        _ => None,
    };
    let errors = match &truth_poses {
        Some(truth) => Some(errors_against_truth(
            args,
            (truth, truth_twists.as_deref()),
            (&poses, twists.as_deref()),
            truth_poses_path.as_deref(),
        )?),
        None => None,
    };
    let inputs = RunFigureInputs {
        title: args
            .poses
            .file_name()
            .map_or_else(|| "run".to_string(), |n| n.to_string_lossy().into_owned()),
        poses,
        twists,
        truth_poses,
        truth_twists,
        errors,
        sigmas,
        status: diagnostics.map(|rows| {
            rows.iter()
                .map(|r| (r.t_s, r.status, r.residual_rms_px))
                .collect()
        }),
    };
    let paths = write_figure_files(&args.out, &render_run_figures(&inputs)?)?;
    for path in paths {
        println!("{}", path.display());
    }
    Ok(())
}

/// Refuses figures that would overwrite an input.
fn check_plot_paths(args: &PlotArgs) -> Result<()> {
    let inputs: Vec<(&str, &std::path::Path)> = [
        ("--poses", Some(args.poses.as_path())),
        ("--twists", args.twists.as_deref()),
        ("--diagnostics", args.diagnostics.as_deref()),
        ("--covariance", args.covariance.as_deref()),
        ("--truth-poses", args.truth_poses.as_deref()),
        ("--truth-twists", args.truth_twists.as_deref()),
    ]
    .into_iter()
    .filter_map(|(name, path)| path.map(|p| (name, p)))
    .collect();
    let figures: Vec<(String, PathBuf)> = ["motion", "errors", "status"]
        .iter()
        .flat_map(|stem| ["png", "svg"].map(|ext| format!("{stem}.{ext}")))
        .map(|name| (format!("--out's {name}"), args.out.join(&name)))
        .collect();
    let outputs: Vec<(&str, &std::path::Path)> = figures
        .iter()
        .map(|(n, p)| (n.as_str(), p.as_path()))
        .collect();
    roitrack::formats::check_output_paths(&inputs, &outputs)?;
    Ok(())
}

/// The run the side files must be of: the times of the poses read from `poses_path`.
struct SameRun<'a> {
    times: &'a [f64],
    poses_path: &'a std::path::Path,
}

impl SameRun<'_> {
    /// Refuses a side file (`what`: twist, diagnostics, covariance) at `path` that is not of this run: its rows'
    /// times `side` must be the poses' times, one row per estimate.
    fn check(&self, what: &str, path: &std::path::Path, side: &[f64]) -> Result<()> {
        let times = self.times;
        if side.len() != times.len() {
            bail!(
                "{}: {} rows for {} poses in {}: not the same run",
                path.display(),
                side.len(),
                times.len(),
                self.poses_path.display()
            );
        }
        if let Some(k) = (0..side.len()).find(|&k| (side[k] - times[k]).abs() > 1e-6) {
            bail!(
                "{}: {what} row {} is at t = {} s but pose {} is at t = {} s: not the same run",
                path.display(),
                k + 1,
                side[k],
                k + 1,
                times[k]
            );
        }
        Ok(())
    }
}

/// A side file's rows (`what`: diagnostics, covariance), read by `read` when given and checked to be of `run`.
fn read_side_file<R: TimedRow>(
    path: Option<&PathBuf>,
    what: &str,
    run: &SameRun<'_>,
    read: impl Fn(&PathBuf) -> Result<Vec<R>, roitrack::formats::FormatError>,
) -> Result<Option<Vec<R>>> {
    path.map(|path| -> Result<_> {
        let rows = read(path)?;
        run.check(
            what,
            path,
            &rows.iter().map(|r| r.t_s()).collect::<Vec<_>>(),
        )?;
        Ok(rows)
    })
    .transpose()
}

/// A row of a side file, at the time of its estimate.
trait TimedRow {
    fn t_s(&self) -> f64;
}

impl TimedRow for roitrack::formats::DiagnosticsRow {
    fn t_s(&self) -> f64 {
        self.t_s
    }
}

impl TimedRow for roitrack::formats::CovarianceRow {
    fn t_s(&self) -> f64 {
        self.t_s
    }
}

/// The sigmas of the error bands per estimate, in the 12 components of the covariance: all of them from the
/// covariance file, else position and velocity from the diagnostics (NaN for the others); none without either.
fn band_sigmas(
    covariance: Option<&[roitrack::formats::CovarianceRow]>,
    diagnostics: Option<&[roitrack::formats::DiagnosticsRow]>,
) -> Option<Vec<[f64; 12]>> {
    match (covariance, diagnostics) {
        (Some(rows), _) => Some(
            rows.iter()
                .map(|r| {
                    r.covariance
                        .as_ref()
                        .map_or([f64::NAN; 12], roitrack::estimators::standard_deviations)
                })
                .collect(),
        ),
        (None, Some(rows)) => Some(
            rows.iter()
                .map(|r| {
                    let mut s = [f64::NAN; 12];
                    s[..3].copy_from_slice(&r.sigma_position_m);
                    s[6..9].copy_from_slice(&r.sigma_velocity_mps);
                    s
                })
                .collect(),
        ),
        (None, None) => None,
    }
}

/// The truth's poses and twists files: in --truth's folder, or --truth-poses and --truth-twists.
fn truth_paths(args: &PlotArgs) -> (Option<PathBuf>, Option<PathBuf>) {
    match (&args.truth, &args.truth_poses) {
        (Some(dir), _) => (
            Some(dir.join(TRUTH_POSES_FILE)),
            Some(dir.join(TRUTH_TWISTS_FILE)),
        ),
        (None, Some(poses)) => (Some(poses.clone()), args.truth_twists.clone()),
        (None, None) => (None, None),
    }
}

/// The estimates' errors against the truth, aligned and offset in time as --align and --time-offset say (as `roitrack
/// eval` does), estimates outside the truth's time left out; the twists compared only when both have them.
fn errors_against_truth(
    args: &PlotArgs,
    (truth, truth_twists): (
        &[roitrack::core::PoseSample],
        Option<&[roitrack::core::TwistSample]>,
    ),
    (poses, twists): (
        &[roitrack::core::PoseSample],
        Option<&[roitrack::core::TwistSample]>,
    ),
    truth_poses_path: Option<&std::path::Path>,
) -> Result<roitrack::eval::EstimateErrors> {
    estimate_errors(
        truth,
        truth_twists,
        poses,
        twists.filter(|_| truth_twists.is_some()),
        &EvalOptions {
            alignment: super::eval::alignment(args.align),
            time_offset: TimeOffset::Fixed(args.time_offset),
            skip_outside_truth: true,
            ..EvalOptions::default()
        },
    )
    .with_context(|| {
        format!(
            "comparing {} with the truth {}",
            args.poses.display(),
            truth_poses_path.map_or(String::new(), |p| p.display().to_string())
        )
    })
}

/// Writes figures rendered in memory into `dir` (created if needed, and removed again if the run fails), each through
/// a temporary moved into place with the run's other outputs; returns their paths.
pub fn write_figure_files(dir: &std::path::Path, files: &[RenderedFile]) -> Result<Vec<PathBuf>> {
    use std::io::Write as _;
    roitrack::formats::create_output_dir(dir)?;
    files
        .iter()
        .map(|figure| {
            let path = dir.join(&figure.name);
            let mut file = roitrack::formats::AtomicFile::create(&path)?;
            file.write_all(&figure.bytes)
                .with_context(|| format!("cannot write {}", path.display()))?;
            file.finish()?;
            Ok(path)
        })
        .collect()
}
