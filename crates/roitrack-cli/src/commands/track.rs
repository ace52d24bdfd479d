//! `roitrack track`: run the tracker over a measurements file and write poses (TUM) and twists (CSV).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use roitrack_core::estimator::{
    Estimate, Estimator, EstimatorConfig, KalmanTuning, RobustLoss, TrackStatus, Tracker,
    TrackerConfig, VvsSettings, WindowMode,
};
use roitrack_core::{CameraModel, JacobianKind, Measurement, PoseSample, Target, TwistSample};
use roitrack_formats::{MeasurementReader, PoseWriter, TwistWriter};
use roitrack_pipeline::realtime::RejectionCounts;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EstimatorArg {
    /// Error-state Kalman filter, one update per centroid at its own time (default)
    Kalman,
    /// The paper's virtual visual servoing loop with the exact Jacobian
    Exact,
    /// The paper's virtual visual servoing loop with the paper's Jacobian (eqs. 17-24)
    Paper,
    /// Baseline: static PnP as if simultaneous, velocity by finite differences
    Static,
    /// Baseline: Levenberg-Marquardt of the 12 parameters on the window
    Batch,
}

impl EstimatorArg {
    /// The estimator, with the Kalman tuning and the VVS settings given.
    pub fn config(self, kalman: KalmanTuning, vvs: VvsSettings) -> EstimatorConfig {
        match self {
            Self::Kalman => EstimatorConfig::Kalman(kalman),
            Self::Exact => EstimatorConfig::Vvs(VvsSettings {
                jacobian: JacobianKind::Exact,
                ..vvs
            }),
            Self::Paper => EstimatorConfig::Vvs(VvsSettings {
                jacobian: JacobianKind::Paper,
                ..vvs
            }),
            Self::Static => EstimatorConfig::Static,
            Self::Batch => EstimatorConfig::Batch,
        }
    }

    /// The estimator with default settings, but for the VVS gain.
    pub fn with_gain(self, gain: f64) -> EstimatorConfig {
        self.config(
            KalmanTuning::default(),
            VvsSettings {
                gain,
                ..VvsSettings::default()
            },
        )
    }
}

/// Estimator options shared by `track` and the commands that run the tracker.
#[derive(Debug, Clone, Args)]
pub struct EstimatorArgs {
    /// Which estimator.
    #[arg(long, value_enum, default_value = "kalman")]
    pub estimator: EstimatorArg,
    /// Gain λ of the VVS update δ = -λ L⁺ e (exact, paper).
    #[arg(long, default_value_t = 1.0)]
    pub gain: f64,
    /// VVS iterations per control step (1 = the paper's scheme; more = Gauss-Newton).
    #[arg(long, default_value_t = 1)]
    pub iterations: usize,
    /// Window: 0 = the newest measurement of each point (the paper), N = the last N measurements.
    #[arg(long, default_value_t = 0)]
    pub window: usize,
    /// Control period k: one estimate every K measurements.
    #[arg(long, default_value_t = 10)]
    pub every: usize,
    /// Centroid noise standard deviation (px), used by the Kalman filter and the covariances.
    #[arg(long, default_value_t = 0.1)]
    pub noise_px: f64,
    /// Kalman: white linear acceleration spectral density ((m/s²)²/Hz); larger = less lag, more noise.
    #[arg(long)]
    pub accel_psd: Option<f64>,
    /// Kalman: white angular acceleration spectral density ((rad/s²)²/Hz).
    #[arg(long)]
    pub angular_accel_psd: Option<f64>,
    /// M-estimator against outliers: tukey (default), huber (window fits; the Kalman filter uses Huber either way)
    /// or none (plain least squares, and no Huber weighting in the Kalman filter).
    #[arg(long, value_enum, default_value = "tukey")]
    pub robust: RobustArg,
    /// Degeneracy gate: windows whose column-scaled Jacobian has a reciprocal condition number below this are not
    /// used for an update (the estimate is flagged degenerate and the window widened).
    #[arg(long)]
    pub min_conditioning: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RobustArg {
    None,
    Huber,
    Tukey,
}

impl EstimatorArgs {
    pub fn config(&self) -> TrackerConfig {
        let mut kalman = KalmanTuning::default();
        if let Some(q) = self.accel_psd {
            kalman.linear_accel_psd = q;
        }
        if let Some(q) = self.angular_accel_psd {
            kalman.angular_accel_psd = q;
        }
        if self.robust == RobustArg::None {
            kalman.huber_sigma = f64::INFINITY;
        }
        let vvs = VvsSettings {
            gain: self.gain,
            iterations: self.iterations,
            ..VvsSettings::default()
        };
        let mut config = TrackerConfig {
            estimator: self.estimator.config(kalman, vvs),
            window: if self.window == 0 {
                WindowMode::NewestPerPoint
            } else {
                WindowMode::Last(self.window)
            },
            every: self.every,
            noise_px: self.noise_px,
            ..TrackerConfig::default()
        };
        if let Some(c) = self.min_conditioning {
            config.min_inverse_condition = c;
        }
        config.robust = match self.robust {
            RobustArg::None => RobustLoss::None,
            RobustArg::Huber => RobustLoss::Huber,
            RobustArg::Tukey => RobustLoss::Tukey,
        };
        config
    }
}

/// Track pose and velocity from a measurements file (t,id,u,v): one pose and one twist per control step.
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

/// Counts of what a tracking run produced.
#[derive(Debug, Default, Clone, Copy)]
pub struct TrackSummary {
    pub measurements: usize,
    pub estimates: usize,
    pub degenerate: usize,
    pub lost: usize,
    pub seconds: f64,
}

impl TrackSummary {
    pub fn us_per_measurement(&self) -> f64 {
        1e6 * self.seconds / self.measurements.max(1) as f64
    }

    /// Wall time per control step, including the handling of the `k` measurements that lead to it (µs).
    pub fn us_per_estimate(&self) -> f64 {
        1e6 * self.seconds / self.estimates.max(1) as f64
    }
}

/// Runs a tracker over measurements, handing each estimate to `sink`.
pub fn track_stream(
    camera: &CameraModel,
    target: &Target,
    config: TrackerConfig,
    measurements: impl Iterator<Item = Result<Measurement>>,
    mut sink: impl FnMut(&Estimate) -> Result<()>,
) -> Result<TrackSummary> {
    let mut tracker =
        Tracker::new(camera.clone(), target.clone(), config).context("invalid tracker options")?;
    let mut summary = TrackSummary::default();
    let start = Instant::now();
    for m in measurements {
        let m = m?;
        summary.measurements += 1;
        if let Some(estimate) = tracker.push(&m)? {
            summary.estimates += 1;
            match estimate.status {
                TrackStatus::Degenerate => summary.degenerate += 1,
                TrackStatus::Lost => summary.lost += 1,
                _ => {}
            }
            sink(&estimate)?;
        }
    }
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

/// Writes estimates as TUM poses, twists CSV and optional diagnostics CSV, each atomically.
pub struct EstimateWriter {
    poses: PoseWriter,
    twists: TwistWriter,
    diagnostics: Option<roitrack_formats::AtomicFile>,
}

impl EstimateWriter {
    pub fn create(poses: &Path, twists: &Path, diagnostics: Option<&Path>) -> Result<Self> {
        let mut diagnostics = diagnostics
            .map(roitrack_formats::AtomicFile::create)
            .transpose()?;
        if let Some(file) = diagnostics.as_mut() {
            use std::io::Write;
            writeln!(
                file,
                "t,status,residual_rms_px,inverse_condition,measurements_used,iterations,\
                 sigma_x_m,sigma_y_m,sigma_z_m,sigma_vx_mps,sigma_vy_mps,sigma_vz_mps"
            )?;
        }
        Ok(Self {
            poses: PoseWriter::create(poses)?,
            twists: TwistWriter::create(twists)?,
            diagnostics,
        })
    }

    pub fn write(&mut self, e: &Estimate) -> Result<()> {
        self.poses
            .write(&PoseSample::from_state(e.t_ref_s, &e.state))?;
        self.twists
            .write(&TwistSample::from_state(e.t_ref_s, &e.state))?;
        if let Some(file) = self.diagnostics.as_mut() {
            use std::io::Write;
            let sigma = e
                .covariance
                .map(|c| roitrack_core::estimator::standard_deviations(&c))
                .unwrap_or([f64::NAN; 12]);
            writeln!(
                file,
                "{},{},{},{},{},{},{},{},{},{},{},{}",
                e.t_ref_s,
                e.status.name(),
                e.residual_rms_px,
                e.inverse_condition,
                e.measurements_used,
                e.iterations,
                sigma[0],
                sigma[1],
                sigma[2],
                sigma[6],
                sigma[7],
                sigma[8]
            )?;
        }
        Ok(())
    }

    pub fn finish(self) -> Result<()> {
        self.poses.finish()?;
        self.twists.finish()?;
        if let Some(file) = self.diagnostics {
            file.finish()?;
        }
        Ok(())
    }
}

pub fn run(args: &TrackArgs) -> Result<()> {
    let camera = roitrack_formats::read_camera_yaml(&args.camera)?;
    let target = roitrack_formats::read_target_csv(&args.target)?;
    let known_ids = target.points().iter().map(|p| p.id);
    // One stream of measurements, from centroids or from ROI images centroided on the fly.
    let mut rejected = RejectionTally::default();
    let (path, measurements): (String, Box<dyn Iterator<Item = Result<Measurement>>>) =
        match (&args.measurements, &args.rois) {
            (Some(path), _) => (
                path.display().to_string(),
                Box::new(
                    MeasurementReader::open(path)?
                        .with_known_ids(known_ids)
                        .map(|r| r.map_err(anyhow::Error::from)),
                ),
            ),
            (None, Some(path)) => (
                path.display().to_string(),
                Box::new(centroided_rois(
                    path,
                    &target,
                    !args.no_symmetry_check,
                    &mut rejected,
                )?),
            ),
            (None, None) => bail!("give --measurements or --rois"),
        };
    let mut writer =
        EstimateWriter::create(&args.poses, &args.twists, args.diagnostics.as_deref())?;
    // Progress on stderr for long files (drawn only when stderr is a terminal).
    let progress = indicatif::ProgressBar::new_spinner().with_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} {human_pos} measurements tracked ({per_sec}) {elapsed}",
        )
        .expect("valid progress template"),
    );
    const PROGRESS_EVERY: u64 = 4096;
    let mut count = 0u64;
    let summary = track_stream(
        &camera,
        &target,
        args.estimator.config(),
        measurements.inspect(|_| {
            count += 1;
            if count.is_multiple_of(PROGRESS_EVERY) {
                progress.inc(PROGRESS_EVERY);
            }
        }),
        |e| writer.write(e),
    )
    .with_context(|| format!("tracking {path} failed"))?;
    progress.finish_and_clear();
    if summary.estimates == 0 {
        bail!(
            "{path}: no estimate from {} measurements: the tracker could not initialise (it needs two cycles \
             over every target point with a consistent static pose)",
            summary.measurements
        );
    }
    writer.finish()?;
    if args.rois.is_some() {
        eprintln!("roitrack: {}", rejected.summary());
    }
    eprintln!(
        "roitrack: {} measurements -> {} estimates ({} degenerate, {} lost) in {:.3} s ({:.2} us per measurement)",
        summary.measurements,
        summary.estimates,
        summary.degenerate,
        summary.lost,
        summary.seconds,
        summary.us_per_measurement()
    );
    Ok(())
}

/// ROIs centroided from a recording, and the blobs rejected, by reason.
#[derive(Debug, Default)]
struct RejectionTally {
    rois: std::rc::Rc<std::cell::Cell<(usize, RejectionCounts)>>,
}

impl RejectionTally {
    fn summary(&self) -> String {
        let (rois, rejected) = self.rois.get();
        format!("{rois} ROIs centroided; rejected: {rejected}")
    }
}

/// Measurements from a ROI recording: each ROI's blob centroid (rejected blobs are skipped and counted).
fn centroided_rois(
    path: &Path,
    target: &Target,
    symmetry_check: bool,
    tally: &mut RejectionTally,
) -> Result<impl Iterator<Item = Result<Measurement>> + use<>> {
    use roitrack_image::{BlobRejection, CentroidOptions, Roi, measure_blob};
    let reader = roitrack_formats::RoiRecordingReader::open(path)?;
    let counts = tally.rois.clone();
    let ids: std::collections::HashSet<u32> = target.points().iter().map(|p| p.id).collect();
    let path = path.to_path_buf();
    let mut options = CentroidOptions::default();
    if !symmetry_check {
        options.symmetry = None;
    }
    Ok(reader.enumerate().filter_map(move |(index, record)| {
        let record = match record {
            Ok(r) => r,
            Err(e) => return Some(Err(e.into())),
        };
        if !ids.contains(&record.id) {
            return Some(Err(anyhow::anyhow!(
                "{}:{}: field 'id': point id {} is not in the target",
                path.display(),
                index + 1,
                record.id
            )));
        }
        let roi = Roi::new(record.x0, record.y0, record.width, record.height);
        let (mut rois, mut rejected) = counts.get();
        rois += 1;
        let result = if record.width > roitrack_image::centroid::MAX_ROI_WIDTH
            || record.height > roitrack_image::centroid::MAX_ROI_HEIGHT
        {
            Err(BlobRejection::TooLarge {
                area_px: record.width * record.height,
            })
        } else {
            measure_blob(&record.pixels, &roi, &options)
        };
        let out = match result {
            Ok(centroid) => Some(Ok(Measurement {
                t_s: record.t_s,
                id: record.id,
                u_px: centroid.u_px,
                v_px: centroid.v_px,
            })),
            Err(r) => {
                rejected.count(&r);
                None
            }
        };
        counts.set((rois, rejected));
        out
    }))
}
