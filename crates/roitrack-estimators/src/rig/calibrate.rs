//! Calibration of a rig from the target: each camera's pose in the rig and its clock, found from a recording in which
//! the moving target is seen by at least two cameras at a time.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x6, Matrix6, Rotation3, SMatrix, Vector3};
use thiserror::Error;

use super::{CameraMount, ClockModel, MAX_DRIFT_PPM, Rig, RigCamera, RigMeasurement};
use crate::{ConfigError, Estimator, TrackError, Tracker, TrackerConfig};
use roitrack_core::{MotionState, Target, so3};

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

/// The most estimates kept per camera: beyond, every other one is dropped (and from then on only every second,
/// fourth, ... is kept), so that memory stays bounded on long recordings while the whole of them is covered.
const MAX_TRACK_SAMPLES: usize = 1 << 18;

/// One vouched-for estimate of a camera's track.
#[derive(Debug, Clone, Copy)]
struct Sample {
    /// Its time on the camera's clock (s).
    t_s: f64,
    state: MotionState,
    /// The covariance of its pose error (translation, rotation on the left; camera frame).
    pose_covariance: Matrix6<f64>,
}

/// The pose covariance assumed for an estimate that states none: 1 mm and 1 mrad, so that such estimates still
/// weigh in, below any estimate of a target seen well.
const UNSTATED_POSE_VARIANCE: f64 = 1e-6;

/// A camera's track: its vouched-for estimates, thinned to a bounded number.
#[derive(Debug, Default)]
struct Track {
    samples: Vec<Sample>,
    stride: usize,
    seen: usize,
}

impl Track {
    fn push(&mut self, sample: Sample) {
        self.stride = self.stride.max(1);
        if self.seen.is_multiple_of(self.stride) {
            self.samples.push(sample);
            if self.samples.len() >= MAX_TRACK_SAMPLES {
                let mut keep = false;
                self.samples.retain(|_| {
                    keep = !keep;
                    keep
                });
                self.stride *= 2;
            }
        }
        self.seen += 1;
    }

    /// The state at camera time `t_s`, between the estimates around it (at most `max_gap_s` apart): both carried
    /// to `t_s` by their twists and blended by their distances in time; the pose covariance of the nearer.
    fn state_at(&self, t_s: f64, max_gap_s: f64) -> Option<(MotionState, Matrix6<f64>)> {
        let after = self.samples.partition_point(|s| s.t_s < t_s);
        let b = *self.samples.get(after)?;
        if b.t_s == t_s {
            return Some((b.state, b.pose_covariance));
        }
        let a = *self.samples.get(after.checked_sub(1)?)?;
        let (t_a, t_b) = (a.t_s, b.t_s);
        if t_b - t_a > max_gap_s {
            return None;
        }
        let alpha = (t_s - t_a) / (t_b - t_a);
        let covariance = if alpha < 0.5 {
            a.pose_covariance
        } else {
            b.pose_covariance
        };
        let (a, b) = (a.state.predicted(t_s - t_a), b.state.predicted(t_s - t_b));
        let turn = so3::log(&(b.cam_r_obj * a.cam_r_obj.inverse()));
        let state = MotionState {
            cam_r_obj: so3::exp(&(turn * alpha)) * a.cam_r_obj,
            cam_t_obj_m: a.cam_t_obj_m.lerp(&b.cam_t_obj_m, alpha),
            velocity_mps: a.velocity_mps.lerp(&b.velocity_mps, alpha),
            angular_velocity_radps: a
                .angular_velocity_radps
                .lerp(&b.angular_velocity_radps, alpha),
        };
        Some((state, covariance))
    }

    fn span_s(&self) -> Option<(f64, f64)> {
        Some((self.samples.first()?.t_s, self.samples.last()?.t_s))
    }
}

/// A camera placed: its mount and clock, and the covariance of (translation, rotation, offset) in the rig's terms,
/// which a camera placed against it inherits.
#[derive(Debug, Clone)]
struct Placed {
    mount: CameraMount,
    clock: ClockModel,
    /// Covariance of (translation (3), rotation (3), offset (1)): what a camera placed against it inherits.
    inherited: SMatrix<f64, 7, 7>,
}

/// What is unknown about the camera being placed, as the columns of the least squares.
#[derive(Debug, Clone, Copy)]
struct Unknowns {
    mount: bool,
    offset: bool,
    drift: bool,
}

impl Unknowns {
    fn count(&self) -> usize {
        6 * self.mount as usize + self.offset as usize + self.drift as usize
    }
}

/// One estimate of the camera being placed, matched with the placed camera's track.
struct Pair {
    /// The camera's own time (s).
    s: f64,
    /// The rig time (s) by the current clock.
    rig_s: f64,
    /// The camera's state (camera_T_object and twist).
    camera: MotionState,
    /// The camera's pose covariance (translation, rotation; its frame).
    camera_covariance: Matrix6<f64>,
    /// The placed camera's state at the same rig time, carried into the rig's frame.
    rig: MotionState,
    /// The placed camera's pose covariance, carried into the rig's frame.
    rig_covariance: Matrix6<f64>,
    /// The placed camera's seconds per second of rig time, `1 + drift 1e-6`: its twist is per second of its clock.
    rig_per_s: f64,
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

    fn no_overlap(&self, placed: &[Option<Placed>], camera: &RigCamera) -> RigCalibrationError {
        let names: Vec<&str> = self
            .rig
            .cameras()
            .iter()
            .zip(placed)
            .filter(|(_, p)| p.is_some())
            .map(|(c, _)| c.name.as_str())
            .collect();
        RigCalibrationError::NoOverlap {
            camera: camera.name.clone(),
            placed: names.join(", "),
            needed: self.config.min_samples,
            max_offset_s: self.config.max_offset_s,
        }
    }

    /// The next camera to place and its placed partners, the most overlapping first: the pair of an unplaced and a
    /// placed camera whose tracks share the longest stretch of rig time (by the clocks as first given, widened by
    /// the offset search).
    fn next_to_place(&self, placed: &[Option<Placed>]) -> Option<(usize, Vec<usize>)> {
        let mut best: Option<(f64, usize)> = None;
        let mut candidates = Vec::new();
        for c in (0..placed.len()).filter(|&c| placed[c].is_none()) {
            let mut partners: Vec<(f64, usize)> = (0..placed.len())
                .filter_map(|p| {
                    let partner = placed[p].as_ref()?;
                    Some((self.shared_span_s(c, p, partner), p))
                })
                .collect();
            partners.sort_by(|a, b| b.0.total_cmp(&a.0));
            let top = partners.first().map_or(f64::NEG_INFINITY, |p| p.0);
            if best.is_none_or(|(b, _)| top > b) {
                best = Some((top, c));
            }
            candidates.push((c, partners.into_iter().map(|(_, p)| p).collect::<Vec<_>>()));
        }
        let (_, c) = best?;
        candidates.into_iter().find(|(k, _)| *k == c)
    }

    fn shared_span_s(&self, c: usize, p: usize, partner: &Placed) -> f64 {
        let (Some((a0, a1)), Some((b0, b1))) = (self.tracks[c].span_s(), self.tracks[p].span_s())
        else {
            return f64::NEG_INFINITY;
        };
        let clock = self.rig.cameras()[c].clock;
        let (a0, a1) = (clock.rig_time_s(a0), clock.rig_time_s(a1));
        let (b0, b1) = (partner.clock.rig_time_s(b0), partner.clock.rig_time_s(b1));
        a1.min(b1) - a0.max(b0) + 2.0 * self.config.max_offset_s
    }

    /// Camera `c`'s estimates matched with placed camera `p`'s track through `clock`, thinned to at most `most`.
    fn pairs(
        &self,
        c: usize,
        p: usize,
        partner: &Placed,
        clock: ClockModel,
        most: usize,
    ) -> Vec<Pair> {
        let samples = &self.tracks[c].samples;
        let stride = samples.len().div_ceil(most.max(1)).max(1);
        samples
            .iter()
            .step_by(stride)
            .filter_map(|sample| {
                let rig_s = clock.rig_time_s(sample.t_s);
                let (placed, covariance) = self.tracks[p]
                    .state_at(partner.clock.camera_time_s(rig_s), self.config.max_gap_s)?;
                let rig_r_camera = partner.mount.camera_r_rig.inverse();
                let mut turn = Matrix6::zeros();
                turn.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(rig_r_camera.matrix());
                turn.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(rig_r_camera.matrix());
                Some(Pair {
                    s: sample.t_s,
                    rig_s,
                    camera: sample.state,
                    camera_covariance: sample.pose_covariance,
                    rig: partner.mount.rig_state(&placed),
                    rig_covariance: turn * covariance * turn.transpose(),
                    rig_per_s: 1.0 + partner.clock.drift_ppm * 1e-6,
                })
            })
            .collect()
    }

    /// The model points the residuals are taken at: the target's points, thinned to at most 16 spread over it.
    fn points(&self) -> Vec<Vector3<f64>> {
        let all = self.target.points();
        let stride = all.len().div_ceil(16).max(1);
        all.iter()
            .step_by(stride)
            .map(|p| p.point_in_obj_m)
            .collect()
    }

    /// Places camera `c` against placed camera `p`.
    fn place(
        &self,
        c: usize,
        p: usize,
        partner: &Placed,
    ) -> Result<(CameraCalibration, SMatrix<f64, 7, 7>), RigCalibrationError> {
        let camera = &self.rig.cameras()[c];
        let unknowns = Unknowns {
            mount: !camera.mount_known,
            offset: !camera.offset_known,
            drift: !camera.drift_known,
        };
        let points = self.points();
        let mut clock = camera.clock;
        let mut mount = camera.mount;
        let needed = self.config.min_samples;
        if unknowns.offset {
            (clock.offset_s, mount) =
                self.search_offset((c, p), partner, unknowns, (mount, clock), &points)?;
        } else if unknowns.mount {
            let pairs = self.pairs(c, p, partner, clock, 400);
            if pairs.len() < needed {
                return Err(self.no_overlap_with(c, p));
            }
            mount = mean_mount(&pairs, &points);
        }
        let pairs = self.pairs(c, p, partner, clock, 4000);
        if pairs.len() < needed {
            return Err(self.no_overlap_with(c, p));
        }
        if unknowns.offset || unknowns.drift {
            let moved_m = largest_distance_m(&pairs);
            if moved_m < self.config.min_motion_m {
                let (camera, partner) = self.names(c, p);
                return Err(RigCalibrationError::StillTarget {
                    camera,
                    partner,
                    moved_mm: moved_m * 1e3,
                    needed_mm: self.config.min_motion_m * 1e3,
                });
            }
        }
        let fit = self.fit_mount_then_clock((c, p), partner, unknowns, (mount, clock), &points);
        let (mount, clock) = (fit.mount, fit.clock);
        let inherited_from_partner = carried_from_partner(&mount, partner);
        let index = columns_of_unknowns(unknowns);
        let mut own = SMatrix::<f64, 7, 7>::zeros();
        for i in 0..7 {
            for j in 0..7 {
                if let (Some(a), Some(b)) = (index[i], index[j]) {
                    own[(i, j)] = fit.covariance[(a, b)];
                }
            }
        }
        let total = own + inherited_from_partner;
        let sigma = |i: usize| total[(i, i)].max(0.0).sqrt();
        let drift_sigma_ppm = index[7].map_or(0.0, |a| fit.covariance[(a, a)].max(0.0).sqrt());
        let result = CameraCalibration {
            mount,
            mount_sigma_m: Vector3::new(sigma(0), sigma(1), sigma(2)),
            mount_sigma_rad: Vector3::new(sigma(3), sigma(4), sigma(5)),
            clock,
            offset_sigma_s: sigma(6),
            drift_sigma_ppm,
            placed_against: Some(p),
            samples: fit.samples,
            rms_residual_m: fit.rms_residual_m,
            covariance: fit.covariance,
        };
        Ok((result, total))
    }

    /// The names of camera `c` and of its partner `p`, for an error.
    fn names(&self, c: usize, p: usize) -> (String, String) {
        let cameras = self.rig.cameras();
        (cameras[c].name.clone(), cameras[p].name.clone())
    }

    /// Camera `c` and its partner `p` see the target together too rarely, at any clock offset searched.
    fn no_overlap_with(&self, c: usize, p: usize) -> RigCalibrationError {
        let (camera, placed) = self.names(c, p);
        RigCalibrationError::NoOverlap {
            camera,
            placed,
            needed: self.config.min_samples,
            max_offset_s: self.config.max_offset_s,
        }
    }

    /// The clock offset (s) of camera `c`, and the mount found with it: a coarse grid (1 ms) over ± `max_offset_s`
    /// about `clock`'s, then a fine one (50 µs) about its best, each offset scored by how close its best mount (or
    /// `mount`, when known) lays the two tracks. Err when the tracks never overlap enough, or when the best lies at
    /// the search's edge (the offset is likely beyond it).
    fn search_offset(
        &self,
        (c, p): (usize, usize),
        partner: &Placed,
        unknowns: Unknowns,
        (mount, clock): (CameraMount, ClockModel),
        points: &[Vector3<f64>],
    ) -> Result<(f64, CameraMount), RigCalibrationError> {
        let needed = self.config.min_samples;
        let search = self.config.max_offset_s;
        let coarse_step_s = 1e-3;
        let steps = (search / coarse_step_s).ceil() as i64;
        let start = clock.offset_s;
        let score = |offset_s: f64| -> Option<(f64, CameraMount)> {
            let trial = ClockModel { offset_s, ..clock };
            let pairs = self.pairs(c, p, partner, trial, 400);
            if pairs.len() < needed {
                return None;
            }
            let m = if unknowns.mount {
                mean_mount(&pairs, points)
            } else {
                mount
            };
            Some((mean_square_residual(&pairs, points, &m), m))
        };
        // The offsets `centre_s + k step_s` for |k| <= reach, each kept in `best` if it scores lower (cost, offset,
        // mount).
        let scan =
            |best: &mut Option<(f64, f64, CameraMount)>, centre_s: f64, step_s: f64, reach: i64| {
                for k in -reach..=reach {
                    let offset_s = centre_s + k as f64 * step_s;
                    if let Some((cost, m)) = score(offset_s)
                        && best.is_none_or(|(b, _, _)| cost < b)
                    {
                        *best = Some((cost, offset_s, m));
                    }
                }
            };
        let mut best = None;
        scan(&mut best, start, coarse_step_s, steps);
        let (_, coarse_s, _) = best.ok_or_else(|| self.no_overlap_with(c, p))?;
        if (coarse_s - start).abs() > search - 1.5 * coarse_step_s {
            let (camera, partner) = self.names(c, p);
            return Err(RigCalibrationError::ClockBeyondSearch {
                camera,
                partner,
                max_offset_s: search,
            });
        }
        scan(&mut best, coarse_s, 5e-5, 20);
        let (_, offset_s, m) = best.expect("the coarse search found one");
        Ok((offset_s, m))
    }

    /// The mount with every point weighed alike; then the clock again, the mount held, each residual weighed by the
    /// covariance the two tracks state (see the module documentation for why the two differ). The covariance joins
    /// the first fit's of the mount to the second's of the clock.
    fn fit_mount_then_clock(
        &self,
        (c, p): (usize, usize),
        partner: &Placed,
        unknowns: Unknowns,
        (mount, clock): (CameraMount, ClockModel),
        points: &[Vector3<f64>],
    ) -> Fit {
        let joint = self.refine(
            (c, p),
            partner,
            unknowns,
            (mount, clock),
            points,
            &Weights::Common(Matrix3::identity()),
        );
        if !(unknowns.offset || unknowns.drift) {
            return joint;
        }
        let clock_only = Unknowns {
            mount: false,
            ..unknowns
        };
        let timed = self.refine(
            (c, p),
            partner,
            clock_only,
            (joint.mount, joint.clock),
            points,
            &Weights::Stated,
        );
        let n = unknowns.count();
        let m = 6 * unknowns.mount as usize;
        let mut covariance = DMatrix::zeros(n, n);
        covariance
            .view_mut((0, 0), (m, m))
            .copy_from(&joint.covariance.view((0, 0), (m, m)));
        covariance
            .view_mut((m, m), (n - m, n - m))
            .copy_from(&timed.covariance);
        Fit {
            covariance,
            ..timed
        }
    }

    /// Gauss-Newton with Huber weights on the unknown mount, offset and drift of camera `c`, from `mount` and `clock`.
    fn refine(
        &self,
        (c, p): (usize, usize),
        partner: &Placed,
        unknowns: Unknowns,
        (mut mount, mut clock): (CameraMount, ClockModel),
        points: &[Vector3<f64>],
        weights: &Weights,
    ) -> Fit {
        let n = unknowns.count();
        let mut pairs = self.pairs(c, p, partner, clock, 4000);
        let drift_prior = 1.0 / (MAX_DRIFT_PPM * MAX_DRIFT_PPM);
        for _ in 0..12 {
            let system = normal_equations(&pairs, points, &mount, &clock, unknowns, weights, None);
            let mut h = system.h.clone();
            let mut g = system.g.clone();
            if unknowns.drift {
                // A weak prior within the drifts a rig may have: only a track too short to tell a drift leans on it.
                let d = n - 1;
                h[(d, d)] += drift_prior * system.scale * system.scale;
                g[d] -= drift_prior * system.scale * system.scale * clock.drift_ppm;
            }
            let Some(step) = h.clone().cholesky().map(|ch| ch.solve(&g)) else {
                break;
            };
            let (new_mount, new_clock) = apply_step(&mount, &clock, &step, unknowns);
            mount = new_mount;
            clock = new_clock;
            pairs = self.pairs(c, p, partner, clock, 4000);
            let small = step
                .iter()
                .take(6 * unknowns.mount as usize)
                .all(|x| x.abs() < 1e-9)
                && (!unknowns.offset || step[6 * unknowns.mount as usize].abs() < 1e-9);
            if small {
                break;
            }
        }
        let system = normal_equations(
            &pairs,
            points,
            &mount,
            &clock,
            unknowns,
            weights,
            Some(self.config.batch_s),
        );
        let mut h = system.h.clone();
        if unknowns.drift {
            h[(n - 1, n - 1)] += drift_prior * system.scale * system.scale;
        }
        let covariance = match h.try_inverse() {
            Some(h_inv) => {
                let batches = system.batches as f64;
                let correction = if batches > n as f64 + 1.0 {
                    batches / (batches - n as f64)
                } else {
                    f64::INFINITY
                };
                &h_inv * &system.meat * &h_inv * correction
            }
            None => DMatrix::from_element(n, n, f64::INFINITY),
        };
        Fit {
            mount,
            clock,
            covariance,
            samples: pairs.len(),
            rms_residual_m: (mean_square_residual(&pairs, points, &mount) / 3.0).sqrt(),
        }
    }
}

/// The partner's own uncertainty (translation, rotation, offset) carried to a camera of mount `mount` placed against
/// it: the partner mount's error turns with the relative rotation (a left error of the partner's camera_T_rig is
/// R_rel of it on this camera's), its offset adds.
fn carried_from_partner(mount: &CameraMount, partner: &Placed) -> SMatrix<f64, 7, 7> {
    let relative = mount.camera_r_rig * partner.mount.camera_r_rig.inverse();
    let mut carry = SMatrix::<f64, 7, 7>::zeros();
    carry
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(relative.matrix());
    carry
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(relative.matrix());
    carry[(6, 6)] = 1.0;
    carry * partner.inherited * carry.transpose()
}

/// Where each of translation (3), rotation (3), offset and drift sits among the fit's columns, `None` when known.
fn columns_of_unknowns(unknowns: Unknowns) -> [Option<usize>; 8] {
    let mut k = 0;
    let mut index = [None; 8];
    for (slot, unknown) in [
        (0, unknowns.mount),
        (6, unknowns.offset),
        (7, unknowns.drift),
    ] {
        if unknown {
            let width = if slot == 0 { 6 } else { 1 };
            for j in 0..width {
                index[slot + j] = Some(k + j);
            }
            k += width;
        }
    }
    index
}

/// The result of [`RigCalibrator::refine`].
struct Fit {
    mount: CameraMount,
    clock: ClockModel,
    covariance: DMatrix<f64>,
    samples: usize,
    rms_residual_m: f64,
}

/// The weighted normal equations `H δ = g` of the residuals at the current mount and clock, the Huber scale (the residuals' spread in units of their stated covariance),
/// and, with `batch_s`, the sandwich's middle `Σ_b g_b g_bᵀ` over contiguous batches of that length.
struct System {
    h: DMatrix<f64>,
    g: DVector<f64>,
    meat: DMatrix<f64>,
    batches: usize,
    scale: f64,
}

fn normal_equations(
    pairs: &[Pair],
    points: &[Vector3<f64>],
    mount: &CameraMount,
    clock: &ClockModel,
    unknowns: Unknowns,
    weights: &Weights,
    batch_s: Option<f64>,
) -> System {
    let information = |pair: &Pair, point: &Vector3<f64>, r_x: &Rotation3<f64>| match weights {
        Weights::Stated => point_information(pair, point, r_x),
        Weights::Common(w) => *w,
    };
    let n = unknowns.count();
    let r_x = mount.camera_r_rig;
    let t_x = mount.camera_t_rig_m;
    // Per pair, the RMS over its points of the residual weighed by its covariance (both cameras' pose errors at
    // that point): the Huber scale is 1.48 times their median.
    let residual = |pair: &Pair, point: &Vector3<f64>| {
        let q = pair.rig.point_in_cam_at(point, 0.0);
        r_x * q + t_x - pair.camera.point_in_cam_at(point, 0.0)
    };
    let mut norms: Vec<f64> = pairs
        .iter()
        .map(|pair| {
            (points
                .iter()
                .map(|p| {
                    let r = residual(pair, p);
                    r.dot(&(information(pair, p, &r_x) * r))
                })
                .sum::<f64>()
                / points.len() as f64)
                .sqrt()
        })
        .collect();
    let norms_by_pair = norms.clone();
    norms.sort_by(f64::total_cmp);
    let median = norms.get(norms.len() / 2).copied().unwrap_or(0.0);
    let scale = (1.4826 * median).max(1e-12);
    let huber = 2.0 * scale;
    let mut h = DMatrix::zeros(n, n);
    let mut g = DVector::zeros(n);
    let mut meat = DMatrix::zeros(n, n);
    let mut batch_g = DVector::zeros(n);
    let mut batch_start: Option<f64> = None;
    let mut batches = 0usize;
    let mut row = nalgebra::Matrix3xX::<f64>::zeros(n);
    for (pair, norm) in pairs.iter().zip(&norms_by_pair) {
        if let Some(batch_s) = batch_s
            && batch_start.is_none_or(|s| pair.rig_s - s >= batch_s)
        {
            if batch_start.is_some() {
                meat += &batch_g * batch_g.transpose();
                batches += 1;
            }
            batch_g.fill(0.0);
            batch_start = Some(pair.rig_s);
        }
        let weight = if *norm <= huber { 1.0 } else { huber / norm };
        for point in points {
            let q = pair.rig.point_in_cam_at(point, 0.0);
            let r = r_x * q + t_x - pair.camera.point_in_cam_at(point, 0.0);
            let mut col = 0;
            if unknowns.mount {
                row.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&Matrix3::identity());
                row.fixed_view_mut::<3, 3>(0, 3)
                    .copy_from(&(-so3::hat(&(r_x * q))));
                col = 6;
            }
            if unknowns.offset || unknowns.drift {
                // The point's velocity in the rig's frame, per second of rig time, seen in this camera's frame.
                let rotated = pair.rig.cam_r_obj * point;
                let dq_dt = pair.rig.angular_velocity_radps.cross(&rotated) + pair.rig.velocity_mps;
                let dr_dt = r_x * dq_dt * pair.rig_per_s;
                if unknowns.offset {
                    row.set_column(col, &dr_dt);
                    col += 1;
                }
                if unknowns.drift {
                    let rate = 1.0 + clock.drift_ppm * 1e-6;
                    row.set_column(col, &(dr_dt * (-pair.s * 1e-6 / (rate * rate))));
                }
            }
            let information = information(pair, point, &r_x) * weight;
            h += row.transpose() * information * &row;
            let contribution = -(row.transpose() * (information * r));
            g += &contribution;
            batch_g += &contribution;
        }
    }
    if batch_start.is_some() {
        meat += &batch_g * batch_g.transpose();
        batches += 1;
    }
    System {
        h,
        g,
        meat,
        batches,
        scale,
    }
}

/// How the residuals of a point are weighed.
enum Weights {
    /// By the covariance the two tracks state.
    Stated,
    /// By one information matrix (m⁻²) for every point.
    Common(Matrix3<f64>),
}

/// The inverse of the covariance (m⁻²) of a pair's residual at model point `point`, in the camera's frame: the
/// camera's pose error at the point plus the placed camera's, turned by the mount's rotation `camera_r_rig`.
fn point_information(
    pair: &Pair,
    point: &Vector3<f64>,
    camera_r_rig: &Rotation3<f64>,
) -> Matrix3<f64> {
    let at = |rotated: Vector3<f64>| {
        let mut j = Matrix3x6::zeros();
        j.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        j.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-so3::hat(&rotated)));
        j
    };
    let j_camera = at(pair.camera.cam_r_obj * point);
    let j_rig = at(pair.rig.cam_r_obj * point);
    let r = camera_r_rig.matrix();
    let covariance = j_camera * pair.camera_covariance * j_camera.transpose()
        + r * (j_rig * pair.rig_covariance * j_rig.transpose()) * r.transpose();
    covariance
        .try_inverse()
        .unwrap_or_else(|| Matrix3::identity() / UNSTATED_POSE_VARIANCE)
}

/// The mount and clock after a Gauss-Newton step (translation, rotation on the left, offset, drift).
fn apply_step(
    mount: &CameraMount,
    clock: &ClockModel,
    step: &DVector<f64>,
    unknowns: Unknowns,
) -> (CameraMount, ClockModel) {
    let mut mount = *mount;
    let mut clock = *clock;
    let mut k = 0;
    if unknowns.mount {
        let v = Vector3::new(step[0], step[1], step[2]);
        let w = Vector3::new(step[3], step[4], step[5]);
        mount = CameraMount::new(
            so3::orthonormalized(&(so3::exp(&w) * mount.camera_r_rig)),
            mount.camera_t_rig_m + v,
        );
        k = 6;
    }
    if unknowns.offset {
        clock.offset_s += step[k];
        k += 1;
    }
    if unknowns.drift {
        clock.drift_ppm = (clock.drift_ppm + step[k]).clamp(-MAX_DRIFT_PPM, MAX_DRIFT_PPM);
    }
    (mount, clock)
}

/// The mount that lays the pairs' rig-frame poses over the camera's: the chordal mean of the relative rotations, then
/// the translation that is best for it.
fn mean_mount(pairs: &[Pair], points: &[Vector3<f64>]) -> CameraMount {
    let mut sum = Matrix3::zeros();
    for pair in pairs {
        sum += (pair.camera.cam_r_obj * pair.rig.cam_r_obj.inverse()).matrix();
    }
    let svd = sum.svd(true, true);
    let (u, v_t) = (svd.u.expect("asked for"), svd.v_t.expect("asked for"));
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rotation = Rotation3::from_matrix_unchecked(u * d * v_t);
    let mut t = Vector3::zeros();
    let mut count = 0.0f64;
    for pair in pairs {
        for point in points {
            t += pair.camera.point_in_cam_at(point, 0.0)
                - rotation * pair.rig.point_in_cam_at(point, 0.0);
            count += 1.0;
        }
    }
    CameraMount::new(rotation, t / count.max(1.0))
}

/// The mean over pairs and points of the squared residual (m²).
fn mean_square_residual(pairs: &[Pair], points: &[Vector3<f64>], mount: &CameraMount) -> f64 {
    let mut sum = 0.0;
    for pair in pairs {
        for point in points {
            let q = pair.rig.point_in_cam_at(point, 0.0);
            sum += (mount.camera_from_rig(&q) - pair.camera.point_in_cam_at(point, 0.0))
                .norm_squared();
        }
    }
    sum / (pairs.len() * points.len()).max(1) as f64
}

/// The largest distance (m) between the target's positions (rig frame) over the pairs: how far it moved.
fn largest_distance_m(pairs: &[Pair]) -> f64 {
    let positions: Vec<Vector3<f64>> = pairs.iter().map(|p| p.rig.cam_t_obj_m).collect();
    let mean = positions.iter().sum::<Vector3<f64>>() / positions.len().max(1) as f64;
    2.0 * positions
        .iter()
        .map(|p| (p - mean).norm())
        .fold(0.0, f64::max)
}
