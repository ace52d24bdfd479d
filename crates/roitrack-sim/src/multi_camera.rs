//! Several ROI cameras around one scenario, none sharing a clock: each camera's centroids on its own clock, the truth
//! in the rig's frame (the scenario's camera frame) on the rig's clock.
//!
//! The rig's frame is the scenario's camera frame, so the scenario's motion is `rig_T_object`; the first camera of
//! [`CameraRigScene::random`] is the scenario's own camera (identity mount, the rig's clock), the others look at the
//! scene's centre (0, 0, 0.6) m from around it. A camera reads one ROI at a time at its own rate, ROI `k` at time
//! `k / rate_hz` of its clock (a random phase apart from the others), which is `clock.rig_time_s(t)` on the rig's;
//! its centroid is the projection of the true pose at that rig time, seen through its mount, plus noise. A blob of a
//! planar target seen from behind or within 10 degrees of edge-on is not measured, nor one outside the image.
//!
//! ```
//! use roitrack_sim::multi_camera::{CameraRigScene, simulate_rig};
//! use roitrack_sim::{Scenario, ScenarioKind};
//!
//! let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Random, 1).with_duration_s(0.5), 3, 7);
//! let run = simulate_rig(&scene, 4000.0, 0.1, 7).unwrap();
//! assert_eq!(run.measurements.len(), 3);
//! // Each camera's times are on its own clock.
//! let clock = scene.rig.cameras()[1].clock;
//! let t_rig = clock.rig_time_s(run.measurements[1][0].t_s);
//! assert!(t_rig >= 0.0 && t_rig < 0.5);
//! ```

use nalgebra::{Rotation3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_core::{Measurement, MotionState, PoseSample, TwistSample};
use roitrack_estimators::rig::{CameraMount, ClockModel, Rig, RigCamera, RigMeasurement};

use crate::{RoiRenderer, Scenario, SensorError, SensorModel, SimError, SimulatedCamera};

/// A scenario seen by a rig of cameras (their true mounts and clocks).
#[derive(Debug, Clone)]
pub struct CameraRigScene {
    /// The target's motion: its camera frame is the rig's frame, its clock the rig's.
    pub scenario: Scenario,
    /// The cameras as they are: calibrations, mounts and clocks (every clock stated as known).
    pub rig: Rig,
}

/// The scene's centre in the rig's frame, which every camera looks at (m).
pub const SCENE_CENTRE_M: [f64; 3] = [0.0, 0.0, 0.6];

/// Offsets of the other cameras' clocks are drawn within ±this (s).
pub const MAX_SIMULATED_OFFSET_S: f64 = 0.05;
/// Drifts of the other cameras' clocks are drawn within ±this (ppm).
pub const MAX_SIMULATED_DRIFT_PPM: f64 = 100.0;

impl CameraRigScene {
    /// `cameras` cameras (at least 1) around `scenario`, drawn from `seed`: the first is the scenario's camera (the
    /// rig), each other the scenario's camera model looking at the scene's centre from 0.5 to 0.8 m away, turned 30 to
    /// 50 degrees from the first about the vertical, up to 20 degrees about the horizontal and rolled up to 30
    /// degrees, its clock offset within ±50 ms and drift within ±100 ppm. Cameras named `cam0`, `cam1`, ...
    ///
    /// # Panics
    ///
    /// If `cameras` is 0.
    pub fn random(scenario: Scenario, cameras: usize, seed: u64) -> Self {
        assert!(cameras > 0, "CameraRigScene::random: at least one camera");
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6d75_6c74_6963_616d);
        let centre = Vector3::from(SCENE_CENTRE_M);
        let mut list = vec![RigCamera::known(
            "cam0",
            scenario.camera.clone(),
            CameraMount::IDENTITY,
            ClockModel::REFERENCE,
        )];
        for k in 1..cameras {
            // Alternate sides, so that two cameras flank the first.
            let side = if k % 2 == 1 { 1.0 } else { -1.0 };
            let yaw = side * rng.random_range(30f64..50.0).to_radians();
            let pitch = rng.random_range(-20f64..20.0).to_radians();
            let roll = rng.random_range(-30f64..30.0).to_radians();
            let distance_m = rng.random_range(0.5..0.8);
            // rig_R_camera: the camera's axes in the rig; its optical axis through the centre.
            let rig_r_camera = Rotation3::from_axis_angle(&Vector3::y_axis(), yaw)
                * Rotation3::from_axis_angle(&Vector3::x_axis(), pitch)
                * Rotation3::from_axis_angle(&Vector3::z_axis(), roll);
            let position_m = centre - rig_r_camera * Vector3::new(0.0, 0.0, distance_m);
            let camera_r_rig = rig_r_camera.inverse();
            let mount = CameraMount::new(camera_r_rig, -(camera_r_rig * position_m));
            let clock = ClockModel {
                offset_s: rng.random_range(-MAX_SIMULATED_OFFSET_S..MAX_SIMULATED_OFFSET_S),
                drift_ppm: rng.random_range(-MAX_SIMULATED_DRIFT_PPM..MAX_SIMULATED_DRIFT_PPM),
            };
            list.push(RigCamera::known(
                format!("cam{k}"),
                scenario.camera.clone(),
                mount,
                clock,
            ));
        }
        let rig = Rig::new(list).expect("drawn cameras have unique names and finite poses");
        Self { scenario, rig }
    }

    /// The target's true pose and twist in camera `camera`'s frame at `t_camera_s` on that camera's clock: the
    /// scenario at the rig time its clock reads then, seen through its mount. What the camera images.
    ///
    /// ```
    /// use roitrack_sim::multi_camera::CameraRigScene;
    /// use roitrack_sim::{Scenario, ScenarioKind};
    ///
    /// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Orthoglide, 1), 2, 1);
    /// // The first camera is the rig: the scenario itself.
    /// assert_eq!(scene.camera_state_at(0, 0.7), scene.scenario.state_at(0.7));
    /// let camera = &scene.rig.cameras()[1];
    /// let seen = scene.camera_state_at(1, 0.7);
    /// let expected = camera.mount.camera_state(&scene.scenario.state_at(camera.clock.rig_time_s(0.7)));
    /// assert_eq!(seen, expected);
    /// ```
    ///
    /// # Panics
    ///
    /// If the rig has no camera `camera`.
    pub fn camera_state_at(&self, camera: usize, t_camera_s: f64) -> MotionState {
        let camera = &self.rig.cameras()[camera];
        camera
            .mount
            .camera_state(&self.scenario.state_at(camera.clock.rig_time_s(t_camera_s)))
    }

    /// Each camera's simulated ROI camera (the rig's order): its calibration and the scenario's target rendered with
    /// the default sensor at [`Self::camera_state_at`] of each ROI's exposure on its own clock, its noise drawn from
    /// `seed` and its place in the rig. Refuses a camera whose time model is invalid.
    ///
    /// ```
    /// use roitrack_image::{Frame, RoiCamera};
    /// use roitrack_sim::multi_camera::CameraRigScene;
    /// use roitrack_sim::{Scenario, ScenarioKind};
    ///
    /// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Orthoglide, 1), 3, 1);
    /// let mut cameras = scene.simulated_cameras(1).unwrap();
    /// let mut frame = Frame::default();
    /// cameras[2].grab_full_frame(0.1, &mut frame).unwrap();
    /// assert_eq!((frame.width, frame.t_s), (scene.rig.cameras()[2].camera.width_px, 0.1));
    /// ```
    pub fn simulated_cameras(
        &self,
        seed: u64,
    ) -> Result<Vec<SimulatedCamera<impl Fn(f64) -> MotionState + Send + 'static>>, SensorError>
    {
        (0..self.rig.len())
            .map(|c| {
                let renderer = RoiRenderer::new(
                    self.rig.cameras()[c].camera.clone(),
                    self.scenario.target.clone(),
                    SensorModel::default(),
                )?;
                let scene = self.clone();
                Ok(SimulatedCamera::new(
                    renderer,
                    move |t_s| scene.camera_state_at(c, t_s),
                    seed.wrapping_add(c as u64),
                ))
            })
            .collect()
    }

    /// The rig as a user tells the tracker of it who knows every camera's calibration and mount but no clock beyond
    /// the first camera's (the rig's own): every other camera's offset and drift left to be learnt.
    ///
    /// ```
    /// use roitrack_sim::multi_camera::CameraRigScene;
    /// use roitrack_sim::{Scenario, ScenarioKind};
    ///
    /// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Random, 1), 3, 1);
    /// let told = scene.rig_with_clocks_unknown();
    /// assert!(told.cameras()[0].offset_known && told.cameras()[0].drift_known);
    /// assert!(told.cameras()[1..].iter().all(|c| !c.offset_known && !c.drift_known && c.clock.offset_s == 0.0));
    /// ```
    pub fn rig_with_clocks_unknown(&self) -> Rig {
        let cameras = self.rig.cameras().iter().enumerate().map(|(c, camera)| {
            let known = c == 0;
            RigCamera {
                clock: if known {
                    camera.clock
                } else {
                    ClockModel::default()
                },
                offset_known: known,
                drift_known: known,
                ..camera.clone()
            }
        });
        Rig::new(cameras.collect())
            .expect("the scene's own cameras, their clocks reset, stay valid")
    }
}

/// The rig with every clock offset and drift it leaves unknown drawn from `seed` (offsets within ±50 ms, drifts
/// within ±100 ppm) and every clock then known: the truth of a simulation of a rig file.
///
/// ```
/// use roitrack_estimators::rig::{CameraMount, ClockModel, Rig, RigCamera};
/// use roitrack_core::CameraModel;
/// use roitrack_sim::multi_camera::draw_clocks;
///
/// let cam = |name: &str| RigCamera::known(name, CameraModel::canonical(), CameraMount::IDENTITY, ClockModel::REFERENCE);
/// let mut right = cam("right");
/// right.offset_known = false;
/// let truth = draw_clocks(&Rig::new(vec![cam("left"), right]).unwrap(), 1);
/// let clock = truth.cameras()[1].clock;
/// assert!(clock.offset_s.abs() <= 0.05 && clock.drift_ppm == 0.0 && truth.cameras()[1].offset_known);
/// ```
pub fn draw_clocks(rig: &Rig, seed: u64) -> Rig {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0c10_c45e_ed00);
    let cameras = rig
        .cameras()
        .iter()
        .map(|camera| {
            let mut clock = camera.clock;
            let offset_s = rng.random_range(-MAX_SIMULATED_OFFSET_S..MAX_SIMULATED_OFFSET_S);
            let drift_ppm = rng.random_range(-MAX_SIMULATED_DRIFT_PPM..MAX_SIMULATED_DRIFT_PPM);
            if !camera.offset_known {
                clock.offset_s = offset_s;
            }
            if !camera.drift_known {
                clock.drift_ppm = drift_ppm;
            }
            RigCamera::known(
                camera.name.clone(),
                camera.camera.clone(),
                camera.mount,
                clock,
            )
        })
        .collect();
    Rig::new(cameras).expect("the same cameras, every clock known")
}

/// What the rig measured, and what happened.
#[derive(Debug, Clone)]
pub struct RigRun {
    /// Per camera (the rig's order), its centroids in time order, their times on its own clock.
    pub measurements: Vec<Vec<Measurement>>,
    /// The truth in the rig's frame on the rig's clock, at `truth_rate_hz` (the ROI rate) over the scenario.
    pub truth_poses: Vec<PoseSample>,
    /// The true twists at the same times as [`Self::truth_poses`], rig frame.
    pub truth_twists: Vec<TwistSample>,
}

impl RigRun {
    /// Every camera's centroids in one stream, in the order of their times on their own clocks: what a user who does
    /// not know the offsets can merge them by (the rig tracker's reorder buffer takes what comes out of order on the
    /// rig's clock).
    ///
    /// ```
    /// use roitrack_sim::multi_camera::{CameraRigScene, simulate_rig};
    /// use roitrack_sim::{Scenario, ScenarioKind};
    ///
    /// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Random, 1).with_duration_s(0.2), 2, 1);
    /// let run = simulate_rig(&scene, 4000.0, 0.1, 1).unwrap();
    /// let merged = run.merged_by_own_clocks();
    /// assert_eq!(merged.len(), run.measurements.iter().map(Vec::len).sum::<usize>());
    /// assert!(merged.windows(2).all(|w| w[0].measurement.t_s <= w[1].measurement.t_s));
    /// ```
    pub fn merged_by_own_clocks(&self) -> Vec<RigMeasurement> {
        let mut all: Vec<RigMeasurement> = self
            .measurements
            .iter()
            .enumerate()
            .flat_map(|(camera, list)| {
                list.iter().map(move |m| RigMeasurement {
                    camera,
                    measurement: *m,
                })
            })
            .collect();
        all.sort_by(|a, b| a.measurement.t_s.total_cmp(&b.measurement.t_s));
        all
    }
}

/// The most ROIs a simulated rig may take, all cameras together.
pub const MAX_RIG_ROIS: f64 = 1e8;

/// Samples `scene`: every camera reads one ROI every `1 / rate_hz` seconds of its own clock (in the bit-reversed
/// order of the target's points), its centroids with Gaussian noise of `noise_px` per axis; the truth at `rate_hz` on
/// the rig's clock. Seeded by `seed`.
pub fn simulate_rig(
    scene: &CameraRigScene,
    rate_hz: f64,
    noise_px: f64,
    seed: u64,
) -> Result<RigRun, SimError> {
    sample_rig(scene, rate_hz, noise_px, seed, false)
}

/// Samples `scene` as global-shutter cameras do: every camera reads every point of the target at once, `fps` times a
/// second of its own clock (at a random phase, the cameras not triggered together), each centroid with Gaussian noise
/// of `noise_px` per axis; the truth at `fps` on the rig's clock. Seeded by `seed`.
///
/// ```
/// use roitrack_sim::multi_camera::{CameraRigScene, simulate_rig_frames};
/// use roitrack_sim::{Scenario, ScenarioKind};
///
/// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Random, 1), 2, 1);
/// let run = simulate_rig_frames(&scene, 30.0, 0.05, 1).unwrap();
/// // The first camera's first frame: all 16 points at one time.
/// let first = &run.measurements[0];
/// assert!(first[..16].iter().all(|m| m.t_s == first[0].t_s) && first[16].t_s > first[0].t_s);
/// ```
pub fn simulate_rig_frames(
    scene: &CameraRigScene,
    fps: f64,
    noise_px: f64,
    seed: u64,
) -> Result<RigRun, SimError> {
    sample_rig(scene, fps, noise_px, seed, true)
}

/// [`simulate_rig`] (one point per reading) or [`simulate_rig_frames`] (every point per reading).
fn sample_rig(
    scene: &CameraRigScene,
    rate_hz: f64,
    noise_px: f64,
    seed: u64,
    whole_frames: bool,
) -> Result<RigRun, SimError> {
    let bad = |field, expected, value| SimError::BadOption {
        field,
        expected,
        value,
    };
    if !(noise_px.is_finite() && noise_px >= 0.0) {
        return Err(bad("noise_px", "finite and >= 0", noise_px));
    }
    if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= crate::MAX_ROI_RATE_HZ) {
        return Err(bad(
            "rate_hz",
            "positive, at most 1e6 (a million ROIs a second)",
            rate_hz,
        ));
    }
    let scenario = &scene.scenario;
    let duration_s = scenario.duration_s;
    if duration_s * rate_hz * scene.rig.len() as f64 > MAX_RIG_ROIS {
        return Err(SimError::TooManyRois {
            duration_s,
            rate_hz,
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_px).expect("noise_px checked");
    let target = &scenario.target;
    // A planar target's face: its plane's normal, turned towards the first camera at the start.
    let face_in_obj = target.plane().map(|plane| {
        let normal = plane.obj_r_plane.column(2).into_owned();
        let start = scenario.state_at(0.0);
        let towards =
            (start.cam_r_obj * normal).dot(&(start.cam_r_obj * plane.centre_m + start.cam_t_obj_m));
        if towards > 0.0 { normal } else { -normal }
    });
    let order = bit_reversed_indices(target.len());
    let min_cos = 10f64.to_radians().sin();
    let mut measurements = Vec::with_capacity(scene.rig.len());
    for (c, camera) in scene.rig.cameras().iter().enumerate() {
        let clock = camera.clock;
        // ROIs of this camera whose rig times fall within the scenario; the first camera starts at 0, the others at
        // a random phase of their own ROI period.
        let phase_s = if c == 0 {
            0.0
        } else {
            rng.random_range(0.0..1.0 / rate_hz)
        };
        let first_k = ((clock.camera_time_s(0.0) - phase_s) * rate_hz).ceil() as i64;
        let last_k = ((clock.camera_time_s(duration_s) - phase_s) * rate_hz).floor() as i64;
        let mut list = Vec::with_capacity((last_k - first_k + 1).max(0) as usize);
        for k in first_k..=last_k {
            let t_camera_s = k as f64 / rate_hz + phase_s;
            let t_rig_s = clock.rig_time_s(t_camera_s).clamp(0.0, duration_s);
            let state = camera.mount.camera_state(&scenario.state_at(t_rig_s));
            let read = if whole_frames {
                0..target.len()
            } else {
                let i = order[k.rem_euclid(target.len() as i64) as usize];
                i..i + 1
            };
            for point in &target.points()[read] {
                let noise_px = Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng));
                let p = state.point_in_cam_at(&point.point_in_obj_m, 0.0);
                if let Some(face) = face_in_obj {
                    let normal = state.cam_r_obj * face;
                    if normal.dot(&p) < min_cos * p.norm() {
                        continue;
                    }
                }
                let Some(raw) = camera
                    .camera
                    .raw_pixel_from_cam(&p)
                    .filter(|px| camera.camera.contains_raw_pixel(px))
                else {
                    continue;
                };
                let measured = raw + noise_px;
                list.push(Measurement {
                    t_s: t_camera_s,
                    id: point.id,
                    u_px: measured.x,
                    v_px: measured.y,
                });
            }
        }
        measurements.push(list);
    }
    let samples = (duration_s * rate_hz + 1e-9).floor() as usize + 1;
    let (mut truth_poses, mut truth_twists) =
        (Vec::with_capacity(samples), Vec::with_capacity(samples));
    for k in 0..samples {
        let t_s = k as f64 / rate_hz;
        let state = scenario.state_at(t_s);
        truth_poses.push(PoseSample::from_state(t_s, &state));
        truth_twists.push(TwistSample::from_state(t_s, &state));
    }
    Ok(RigRun {
        measurements,
        truth_poses,
        truth_twists,
    })
}

/// The full frames every camera of a rig takes of its scene
/// ([`FrameSequence::seen_by`](crate::frames::FrameSequence::seen_by)), each on its own clock, and the truth in the
/// rig's frame on the rig's clock over every frame's exposure.
///
/// Every camera takes frame `k` at `start_s + k / fps_hz` of its own clock (so cameras whose clocks differ are not
/// triggered together); by default each takes the frames whose rows are all exposed by the scenario's end on the
/// rig's clock. The first camera's sensor noise is that of `options.seed`, the others' independent streams of it.
///
/// ```
/// use roitrack_sim::multi_camera::{CameraRigScene, RigFrames};
/// use roitrack_sim::{FrameOptions, Scenario, ScenarioKind};
///
/// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Random, 1), 2, 1);
/// let options = FrameOptions { frame_count: Some(3), ..FrameOptions::default() };
/// let rig = RigFrames::new(&scene, &options).unwrap();
/// assert_eq!(rig.cameras().len(), 2);
/// // Camera 1's frame 0 is at 0 s of its own clock: the rig's time of its clock offset.
/// let (start, _) = rig.span_s();
/// assert_eq!(start, scene.rig.cameras()[1].clock.offset_s.min(0.0));
/// ```
#[derive(Debug, Clone)]
pub struct RigFrames {
    scene: CameraRigScene,
    cameras: Vec<crate::FrameSequence>,
}

/// Mixed into the seed of every camera but the first.
const RIG_FRAME_SEED_SALT: u64 = 0x9e37_79b9_7f4a_7c15;

impl RigFrames {
    /// The frames of `options` of every camera of `scene` (see [`RigFrames`]); refuses what
    /// [`FrameSequence::new`](crate::FrameSequence::new) refuses, for any camera.
    pub fn new(
        scene: &CameraRigScene,
        options: &crate::FrameOptions,
    ) -> Result<Self, crate::FrameSequenceError> {
        let cameras = scene
            .rig
            .cameras()
            .iter()
            .enumerate()
            .map(|(c, camera)| {
                let seed = if c == 0 {
                    options.seed
                } else {
                    options.seed ^ RIG_FRAME_SEED_SALT.wrapping_mul(c as u64)
                };
                let options = crate::FrameOptions { seed, ..*options };
                crate::FrameSequence::seen_by(&scene.scenario, camera, &options)
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            scene: scene.clone(),
            cameras,
        })
    }

    /// Every camera's frames, in the rig's order.
    pub fn cameras(&self) -> &[crate::FrameSequence] {
        &self.cameras
    }

    /// The scene.
    pub fn scene(&self) -> &CameraRigScene {
        &self.scene
    }

    /// The interval of the rig's clock (s) holding every blob time of every camera: from the earliest first frame to
    /// the latest last row.
    pub fn span_s(&self) -> (f64, f64) {
        self.cameras
            .iter()
            .zip(self.scene.rig.cameras())
            .map(|(frames, camera)| {
                let (start, end) = frames.span_s();
                (camera.clock.rig_time_s(start), camera.clock.rig_time_s(end))
            })
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (s, e)| {
                (a.min(s), b.max(e))
            })
    }

    /// The true poses (`rig_T_object`) and twists (rig frame) on the rig's clock over [`Self::span_s`], at `rate_hz`
    /// from the span's start and at its end, so that linear (slerp) interpolation gives the truth at any time of the
    /// span; use [`DEFAULT_TRUTH_RATE_HZ`](crate::DEFAULT_TRUTH_RATE_HZ). One at a time, in constant memory. Refuses
    /// a rate that is not finite and positive.
    ///
    /// ```
    /// use roitrack_sim::multi_camera::{CameraRigScene, RigFrames};
    /// use roitrack_sim::{FrameOptions, Scenario, ScenarioKind};
    ///
    /// let scene = CameraRigScene::random(Scenario::new(ScenarioKind::Random, 1), 3, 2);
    /// let rig = RigFrames::new(&scene, &FrameOptions { frame_count: Some(4), ..FrameOptions::default() }).unwrap();
    /// let truth: Vec<_> = rig.truth_iter(2000.0).unwrap().collect();
    /// let (start, end) = rig.span_s();
    /// assert_eq!((truth[0].0.t_s, truth.last().unwrap().0.t_s), (start, end));
    /// ```
    pub fn truth_iter(
        &self,
        rate_hz: f64,
    ) -> Result<impl Iterator<Item = (PoseSample, TwistSample)> + '_, crate::FrameSequenceError>
    {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(crate::FrameSequenceError::TruthRate { rate_hz });
        }
        let (start_s, end_s) = self.span_s();
        let regular = ((end_s - start_s) * rate_hz).floor() as usize;
        let times = (0..=regular)
            .map(move |i| start_s + i as f64 / rate_hz)
            // The end itself is the last sample, never a near-duplicate of the grid's.
            .filter(move |t| *t < end_s - 1e-9)
            .chain(std::iter::once(end_s));
        Ok(times.map(|t_s| {
            let state = self.scene.scenario.state_at(t_s);
            (
                PoseSample::from_state(t_s, &state),
                TwistSample::from_state(t_s, &state),
            )
        }))
    }
}
