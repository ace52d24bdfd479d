//! `roitrack track`: run an estimator over a measurements file or a ROI recording and write poses (TUM), twists and
//! diagnostics (CSV).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use roitrack::formats::{EstimateWriter, MeasurementReader, RoiRecordingReader};
use roitrack::image::CentroidOptions;
use roitrack::{EstimatorReport, TrackStatus, Tracker};

use crate::args::EstimatorArgs;

/// Track pose and velocity from a measurements file (t,id,u,v) or a ROI recording: one pose and one twist per
/// control step.
#[derive(Debug, Args)]
pub struct TrackArgs {
    /// Camera calibration (ROS camera_info YAML).
    #[arg(long)]
    pub camera: PathBuf,
    /// Target model (CSV id,x,y,z[,diameter], metres).
    #[arg(long)]
    pub target: PathBuf,
    /// Measured centroids (CSV t,id,u,v; raw pixels; time order).
    #[arg(long, required_unless_present = "rois", conflicts_with = "rois")]
    pub measurements: Option<PathBuf>,
    /// Instead of centroids: a recording of ROI images (see roitrack_formats::RoiRecordingReader), centroided here.
    #[arg(long)]
    pub rois: Option<PathBuf>,
    /// With --rois: keep blobs that are not centrally symmetric (by default they are rejected: a reflection or an
    /// occluder merged with a blob biases its centroid by up to half a pixel). For blobs that are not images of disks.
    #[arg(long, requires = "rois")]
    pub no_symmetry_check: bool,
    /// Output poses (TUM: t tx ty tz qx qy qz qw, camera_T_object).
    #[arg(long)]
    pub poses: PathBuf,
    /// Output twists (CSV t,vx,vy,vz,wx,wy,wz).
    #[arg(long)]
    pub twists: PathBuf,
    /// Output diagnostics per estimate (CSV: t, status, residual, conditioning, measurements used, 1-sigma).
    #[arg(long)]
    pub diagnostics: Option<PathBuf>,
    #[command(flatten)]
    pub estimator: EstimatorArgs,
}

pub fn run(args: &TrackArgs) -> Result<()> {
    let camera = roitrack::formats::read_camera_yaml(&args.camera)?;
    let target = roitrack::formats::read_target_csv(&args.target)?;
    let known_ids: Vec<u32> = target.points().iter().map(|p| p.id).collect();
    let mut tracker = Tracker::new(camera.clone(), target, args.estimator.config())
        .context("invalid tracker options")?;
    let mut writer =
        EstimateWriter::create(&args.poses, &args.twists, args.diagnostics.as_deref())?;
    // Progress on stderr for long files (drawn only when stderr is a terminal).
    let progress = indicatif::ProgressBar::new_spinner().with_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} {human_pos} inputs tracked ({per_sec}) {elapsed}",
        )
        .expect("valid progress template"),
    );
    let tick = |count: usize| {
        if count.is_multiple_of(4096) {
            progress.set_position(count as u64);
        }
    };
    let start = Instant::now();
    let mut sink = |e: &roitrack::Estimate| writer.write(e);
    let (path, report, rois) = match (&args.measurements, &args.rois) {
        (Some(path), _) => {
            let reader = MeasurementReader::open(path)?.with_known_ids(known_ids);
            let measurements = reader.enumerate().map(|(k, m)| {
                tick(k);
                m
            });
            let report = roitrack::track(&mut tracker, measurements, &mut sink)
                .with_context(|| format!("tracking {} failed", path.display()))?;
            (path, report, None)
        }
        (None, Some(path)) => {
            let reader = RoiRecordingReader::open(path)?.with_known_ids(known_ids);
            let mut options = CentroidOptions::default();
            if args.no_symmetry_check {
                options.symmetry = None;
            }
            let images = reader.enumerate().map(|(k, image)| {
                tick(k);
                image
            });
            let report = roitrack::pipeline::track_rois(
                &mut tracker,
                &options,
                &camera.time,
                images,
                &mut sink,
            )
            .with_context(|| format!("tracking {} failed", path.display()))?;
            (path, report.estimator, Some(report))
        }
        (None, None) => bail!("give --measurements or --rois"),
    };
    let seconds = start.elapsed().as_secs_f64();
    progress.finish_and_clear();
    let EstimatorReport {
        measurements,
        estimates,
        ..
    } = report;
    if estimates.total() == 0 {
        bail!(
            "{}: no estimate from {measurements} measurements: the tracker could not initialise (it needs two cycles \
             over every target point with a consistent static pose)",
            path.display()
        );
    }
    writer.finish()?;
    if let Some(rois) = rois {
        eprintln!(
            "roitrack: {} ROIs centroided; rejected: {}",
            rois.rois, rois.rejections
        );
    }
    eprintln!(
        "roitrack: {measurements} measurements -> {} estimates ({} degenerate, {} lost) in {seconds:.3} s ({:.2} us \
         per measurement)",
        estimates.total(),
        estimates.get(TrackStatus::Degenerate),
        estimates.get(TrackStatus::Lost),
        1e6 * seconds / measurements.max(1) as f64
    );
    Ok(())
}
