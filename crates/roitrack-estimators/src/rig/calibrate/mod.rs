//! Calibration of a rig from the target: each camera's pose in the rig and its clock, found from a recording in which
//! the moving target is seen by at least two cameras at a time.

use nalgebra::{DMatrix, Matrix6, SMatrix, Vector3};
use thiserror::Error;

use super::{CameraMount, ClockModel, Rig, RigCamera, RigMeasurement};
use crate::{ConfigError, Estimator, TrackError, Tracker, TrackerConfig};
use roitrack_core::Target;

mod fit;
mod placing;
mod track;

use placing::Placed;
use track::{Sample, Track, UNSTATED_POSE_VARIANCE};

/// Options of a [`RigCalibrator`].
///
/// ```
/// use roitrack_estimators::rig::RigCalibrationConfig;
/// assert_eq!(RigCalibrationConfig::default().max_offset_s, 0.1);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigCalibrationConfig {
    /// The options of every camera's own tracker.
    pub tracker: TrackerConfig,
    /// An unknown clock offset is searched within `±max_offset_s` (s) of its starting value.
    pub max_offset_s: f64,
    /// A placed camera's track is interpolated only between two of its estimates at most this far apart (s).
    pub max_gap_s: f64,
    /// The target must move at least this far (m) while both cameras see it for a clock to be found: a still target
    /// tells no time.
    pub min_motion_m: f64,
    /// The length (rig time, s) of the contiguous batches of the sandwich covariance: longer than the time over which
    /// a tracker's errors are correlated.
    pub batch_s: f64,
    /// The fewest estimates of a camera seen at the same time as a placed camera's track to place it.
    pub min_samples: usize,
}

impl Default for RigCalibrationConfig {
    fn default() -> Self {
        Self {
            tracker: TrackerConfig::default(),
            max_offset_s: 0.1,
            max_gap_s: 0.02,
            min_motion_m: 0.01,
            batch_s: 0.1,
            min_samples: 50,
        }
    }
}

/// Why a rig could not be calibrated.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RigCalibrationError {
    /// The tracker options are invalid.
    #[error("invalid tracker options: {0}")]
    Config(#[from] ConfigError),
    /// A measurement names a camera the rig does not have.
    #[error("a measurement of camera number {camera}, but the rig has {cameras} cameras")]
    UnknownCamera {
        /// The camera number given.
        camera: usize,
        /// How many cameras the rig has.
        cameras: usize,
    },
    /// A camera's own tracker refused a measurement.
    #[error("camera '{camera}': {source}")]
    Measurement {
        /// The camera's name.
        camera: String,
        /// The tracker's error.
        #[source]
        source: TrackError,
    },
    /// A camera to be placed has too few estimates of its own.
    #[error(
        "camera '{camera}': its own track gave {estimates} estimates vouched for from {measurements} measurements, \
         fewer than the {needed} needed to place it: it must see the whole target while it moves"
    )]
    NoTrack {
        /// The camera's name.
        camera: String,
        /// Its measurements.
        measurements: usize,
        /// Its estimates vouched for.
        estimates: usize,
        /// The fewest needed.
        needed: usize,
    },
    /// A camera is never seen at the same time as any camera already placed.
    #[error(
        "camera '{camera}': never sees the target at the same time as a camera already placed ({placed}); at least \
         {needed} of its estimates must fall within one of their tracks (clock offsets searched within ±{max_offset_s} s)"
    )]
    NoOverlap {
        /// The camera's name.
        camera: String,
        /// The names of the cameras placed.
        placed: String,
        /// The fewest estimates needed.
        needed: usize,
        /// The offset search's half-width (s).
        max_offset_s: f64,
    },
    /// The target did not move enough while both cameras saw it.
    #[error(
        "camera '{camera}': the target moved {moved_mm:.1} mm while it and '{partner}' saw it: a still target tells \
         no time; move it by at least {needed_mm:.0} mm, or give the camera's clock_offset_s"
    )]
    StillTarget {
        /// The camera's name.
        camera: String,
        /// The camera it was placed against.
        partner: String,
        /// How far the target moved (mm).
        moved_mm: f64,
        /// How far it must move (mm).
        needed_mm: f64,
    },
    /// The best clock offset lies at the edge of the search.
    #[error(
        "camera '{camera}': its track never matches '{partner}''s within the clock offset search of ±{max_offset_s} s \
         (best match at the search's edge): check its clock and that it sees the same target"
    )]
    ClockBeyondSearch {
        /// The camera's name.
        camera: String,
        /// The camera it was placed against.
        partner: String,
        /// The offset search's half-width (s).
        max_offset_s: f64,
    },
}

/// One camera's calibration: its pose and clock, their standard deviations, and how it was placed.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraCalibration {
    /// The camera's pose in the rig (`camera_T_rig`).
    pub mount: CameraMount,
    /// The standard deviations (m) of the mount's translation, along the camera's axes (0 when known).
    pub mount_sigma_m: Vector3<f64>,
    /// The standard deviations (rad) of the mount's rotation, as small rotations about the camera's axes (0 when
    /// known).
    pub mount_sigma_rad: Vector3<f64>,
    /// The camera's clock.
    pub clock: ClockModel,
    /// The standard deviation (s) of the clock's offset (0 when known).
    pub offset_sigma_s: f64,
    /// The standard deviation (ppm) of the clock's drift (0 when known).
    pub drift_sigma_ppm: f64,
    /// The camera it was placed against (its index in the rig); `None` when nothing about it was to be found.
    pub placed_against: Option<usize>,
    /// The estimates of this camera the placement used.
    pub samples: usize,
    /// The RMS distance (m) between the two cameras' model points after the placement.
    pub rms_residual_m: f64,
    /// Its full covariance in the order (translation, rotation, offset, drift) of what was unknown; units m, rad, s
    /// and ppm. Empty when nothing was to be found.
    pub covariance: DMatrix<f64>,
}

/// The rig with every pose and clock found, and each camera's [`CameraCalibration`].
#[derive(Debug, Clone, PartialEq)]
pub struct RigCalibration {
    /// The rig, every mount and clock known.
    pub rig: Rig,
    /// Per camera, in the rig's order.
    pub cameras: Vec<CameraCalibration>,
}

/// Finds the unknown poses and clocks of a rig's cameras from their measurements of the moving target.
///
/// The first camera's frame is the rig's when its pose is not given; its clock is the rig's. Poses and clocks the rig
/// gives are kept.
///
/// # How it works
///
/// Every camera runs the single-camera tracker of its own measurements ([`Tracker`]), which gives its track of the
/// target, `camera_T_object` and its twist, on its own clock. A camera whose pose or clock is unknown is then placed
/// against a camera already placed (the first camera, whose frame and clock are the rig's, to begin with): for each of
/// its estimates at camera time `s`, the rig time is `τ = offset + s / (1 + drift 1e-6)`, the placed camera's track is
/// interpolated at `τ` and carried into the rig's frame, and every model point `p` gives the residual
///
/// ```text
/// r = X (rig_T_object(τ) p) - camera_T_object(s) p        (metres, the camera's frame; X = camera_T_rig)
/// ```
///
/// An unknown offset is first searched on a grid (the shift whose best `X` lays the two tracks over each other most
/// closely); `X`, the offset and the drift are then refined by Gauss-Newton with Huber weights. A clock's columns are
/// the point's velocity, `X R (W × (R_c p) + V)` carried from the placed camera, times `dτ/d offset = 1` and
/// `dτ/d drift = -s 1e-6 / (1 + drift 1e-6)²`.
///
/// The mount is fitted with every point weighed alike; the clock is then fitted again, the mount held, with each
/// residual weighed by the covariance the two tracks state at its point. On simulated rigs, weighing the mount's fit
/// so (or by the residuals' own covariance) doubled its error, the tracks' well-determined directions carrying errors
/// that their covariances do not account for; the clock's error it cuts several times.
///
/// The standard deviations come from the spread of the residuals, not from a noise model of the tracks: consecutive
/// estimates of a tracker are correlated, so the covariance is the sandwich `H⁻¹ (Σ_b g_b g_bᵀ) H⁻¹` over contiguous
/// batches `b` of [`RigCalibrationConfig::batch_s`] (`g_b` the batch's gradient, `H` the Gauss-Newton matrix), with
/// the small-sample factor `B / (B - n)` for `B` batches and `n` parameters. A camera placed against another than the
/// first also carries that camera's uncertainty.
///
/// ```
/// use roitrack_estimators::rig::{CameraMount, ClockModel, Rig, RigCalibrator, RigCalibrationConfig, RigCamera};
/// use roitrack_core::{CameraModel, Target};
///
/// // The second camera's pose and clock are unknown.
/// let left = RigCamera::known("left", CameraModel::canonical(), CameraMount::IDENTITY, ClockModel::REFERENCE);
/// let right = RigCamera { name: "right".into(), mount_known: false, offset_known: false, drift_known: false, ..left.clone() };
/// let calibrator = RigCalibrator::new(Rig::new(vec![left, right]).unwrap(), Target::grid4x4(), RigCalibrationConfig::default());
/// // Without measurements, the second camera has no track to place.
/// let e = calibrator.unwrap().finish().unwrap_err();
/// assert!(e.to_string().contains("camera 'right'"), "{e}");
/// ```
#[derive(Debug)]
pub struct RigCalibrator {
    rig: Rig,
    target: Target,
    config: RigCalibrationConfig,
    trackers: Vec<Tracker>,
    tracks: Vec<Track>,
    measurements: Vec<usize>,
}

impl RigCalibrator {
    /// A calibrator for `rig` (whose unknown mounts and clocks it finds) and `target`.
    pub fn new(
        rig: Rig,
        target: Target,
        config: RigCalibrationConfig,
    ) -> Result<Self, RigCalibrationError> {
        let trackers = rig
            .cameras()
            .iter()
            .map(|c| Tracker::new(c.camera.clone(), target.clone(), config.tracker))
            .collect::<Result<Vec<_>, _>>()?;
        let n = rig.len();
        Ok(Self {
            rig,
            target,
            config,
            trackers,
            tracks: (0..n).map(|_| Track::default()).collect(),
            measurements: vec![0; n],
        })
    }

    /// Takes one measurement of one camera (each camera's in the order of its own time).
    pub fn push(&mut self, m: &RigMeasurement) -> Result<(), RigCalibrationError> {
        let cameras = self.rig.len();
        let tracker =
            self.trackers
                .get_mut(m.camera)
                .ok_or(RigCalibrationError::UnknownCamera {
                    camera: m.camera,
                    cameras,
                })?;
        self.measurements[m.camera] += 1;
        let estimate =
            tracker
                .push(&m.measurement)
                .map_err(|source| RigCalibrationError::Measurement {
                    camera: self.rig.cameras()[m.camera].name.clone(),
                    source,
                })?;
        if let Some(e) = estimate.filter(|e| e.status.is_vouched_for()) {
            let pose_covariance = e
                .covariance
                .map(|p| p.fixed_view::<6, 6>(0, 0).into_owned())
                .filter(|p| p.iter().all(|x| x.is_finite()))
                .unwrap_or_else(|| Matrix6::identity() * UNSTATED_POSE_VARIANCE);
            self.tracks[m.camera].push(Sample {
                t_s: e.t_ref_s,
                state: e.state,
                pose_covariance,
            });
        }
        Ok(())
    }

    /// Places every camera whose pose or clock is unknown, each against the placed camera whose track it overlaps
    /// most, and returns the rig with all of them known.
    pub fn finish(self) -> Result<RigCalibration, RigCalibrationError> {
        let n = self.rig.len();
        let mut placed: Vec<Option<Placed>> = vec![None; n];
        let mut results: Vec<Option<CameraCalibration>> = vec![None; n];
        for (c, camera) in self.rig.cameras().iter().enumerate() {
            let first = c == 0;
            if camera.clock_known() && (camera.mount_known || first) {
                let mount = if camera.mount_known {
                    camera.mount
                } else {
                    CameraMount::IDENTITY
                };
                placed[c] = Some(Placed {
                    mount,
                    clock: camera.clock,
                    inherited: SMatrix::zeros(),
                });
                results[c] = Some(CameraCalibration {
                    mount,
                    mount_sigma_m: Vector3::zeros(),
                    mount_sigma_rad: Vector3::zeros(),
                    clock: camera.clock,
                    offset_sigma_s: 0.0,
                    drift_sigma_ppm: 0.0,
                    placed_against: None,
                    samples: 0,
                    rms_residual_m: 0.0,
                    covariance: DMatrix::zeros(0, 0),
                });
            }
        }
        let needed = self.config.min_samples;
        for (c, camera) in self.rig.cameras().iter().enumerate() {
            if placed[c].is_none() && self.tracks[c].samples.len() < needed {
                return Err(RigCalibrationError::NoTrack {
                    camera: camera.name.clone(),
                    measurements: self.measurements[c],
                    estimates: self.tracks[c].samples.len(),
                    needed,
                });
            }
        }
        while let Some((c, partners)) = self.next_to_place(&placed) {
            let camera = &self.rig.cameras()[c];
            let mut last_error = None;
            let mut done = false;
            for p in partners {
                let partner = placed[p].clone().expect("a partner is placed");
                match self.place(c, p, &partner) {
                    Ok((result, inherited)) => {
                        placed[c] = Some(Placed {
                            mount: result.mount,
                            clock: result.clock,
                            inherited,
                        });
                        results[c] = Some(result);
                        done = true;
                        break;
                    }
                    Err(e @ RigCalibrationError::NoOverlap { .. }) => {
                        last_error.get_or_insert(e);
                    }
                    Err(e) => return Err(e),
                }
            }
            if !done {
                return Err(last_error.unwrap_or_else(|| self.no_overlap(&placed, camera)));
            }
        }
        let cameras: Vec<CameraCalibration> = results
            .into_iter()
            .map(|r| r.expect("every camera is placed"))
            .collect();
        let rig = Rig::new(
            self.rig
                .cameras()
                .iter()
                .zip(&cameras)
                .map(|(camera, result)| RigCamera {
                    mount: result.mount,
                    mount_known: true,
                    clock: result.clock,
                    offset_known: true,
                    drift_known: true,
                    ..camera.clone()
                })
                .collect(),
        )
        .expect("the rig was valid and its clocks are finite");
        Ok(RigCalibration { rig, cameras })
    }
}
