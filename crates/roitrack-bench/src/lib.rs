//! # roitrack-bench
//!
//! roitrack's benchmarks as library calls: the hot paths (this page), the real-time loop ([`loop_bench`]), tracking
//! from frames ([`frame_bench`]), the long soak run ([`soak`]) and the PnP comparison with OpenCV ([`pnp`]). `roitrack bench`, `roitrack soak` and
//! `roitrack pnp-bench` only print what these return.
//!
//! The inputs of roitrack's hot-path benchmarks, built on the built-in scene (docs/model.md) with the public APIs
//! only, and a batch timer. The criterion benches (`cargo bench -p roitrack-bench`, `benches/hot_paths.rs`) and the
//! quick `roitrack bench` command use the same inputs ([`HotPaths`]) and the same calls ([`time_all`] times the
//! [`HotPaths`] methods the criterion benches call).
//!
//! The scene ([`scene`]): camera [`CameraModel::canonical`], target [`Target::grid4x4`], the bench pose (origin at
//! (0.02, -0.01, 0.60) m, R = Rz(5°) Ry(-15°) Rx(10°), [`MotionState::bench`]) at the reference time,
//! moving with a moderate twist ([`TRUTH_VELOCITY_MPS`], [`TRUTH_ANGULAR_VELOCITY_RADPS`]) so that every path of a
//! moving target is timed (the time-dependent rotation `Exp(W d)`, a few milliradians over a window, as in tracking).
//! Measurements are taken [`ROI_PERIOD_S`] (250 µs) apart, visiting the points in the bit-reversed order, each the
//! projection of the true pose at its own time plus Gaussian noise of [`NOISE_PX`] (0.1 px), drawn from a seeded
//! generator: every run times the same problem. The static pose problem is the bench pose at rest, one noisy
//! measurement per point.
//!
//! The timed items ([`Item`]):
//! - `jacobian_residual_w16`: `JᵀJ`, `Jᵀe` of a 16-measurement window with the exact Jacobian
//!   ([`WindowProblem::normal_equations`]);
//! - `control_step_w16`, `control_step_w32`: one step of the virtual visual servoing loop, 1 iteration, exact Jacobian,
//!   gain 1, degeneracy gate 3e-3 (so it includes the conditioning figure) on 16 and 32 measurements
//!   ([`solver::solve`] with [`SolverOptions::servo`]), from a state off the truth by [`perturbation`];
//! - `gauss_newton_solve`: Levenberg-Marquardt (Gauss-Newton with damping) of the 12 parameters to convergence on 32
//!   measurements from the same perturbed state ([`SolverOptions::levenberg_marquardt`]);
//! - `static_pose`: the static pose from scratch, 16 points, no prior: closed form then Gauss-Newton to convergence,
//!   i.e. to the accuracy of a converged 6-dof VVS ([`roitrack_estimators::solve_static_pose`]);
//! - `centroid_24`: the blob centroid of a 24 x 24 8-bit ROI around a 6 mm blob, rendered once by the simulator with
//!   the default sensor ([`measure_blob`], default options, so with the symmetry check);
//! - `centroid_24_moments`: the same without the symmetry check (the first-order moments alone);
//! - `render_roi`: the simulator's rendering of that ROI (one blob, shot and read noise drawn)
//!   ([`RoiRenderer::render_roi_with_scratch`], scratch buffers reused);
//! - `kalman_update`: one measurement pushed into the default Kalman filter ([`KalmanEstimator`], default options but
//!   an estimate period so long that none is due) on a running track of the bench scene: the prediction, the update
//!   and the window's bookkeeping of one centroid, the per-measurement cost of tracking ([`KalmanStream`]);
//! - `kalman_update_constant_acceleration`: the same with [`MotionModel::ConstantAcceleration`] (18 states).
#![deny(missing_docs)]

pub mod frame_bench;
pub mod loop_bench;
pub mod pnp;
pub mod rig_bench;
pub mod soak;
pub mod track_bench;

use std::hint::black_box;
use std::time::{Duration, Instant};

use nalgebra::{Vector2, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use roitrack_core::roi_order::bit_reversed_indices;
use roitrack_core::solver::{self, NormalEquations, Solution, SolverOptions};
use roitrack_core::{
    CameraModel, Measurement, MotionState, SpatioTemporalModel, Target, Vector12, so3,
};
use roitrack_estimators::{
    Estimate, Estimator, InitError, KalmanEstimator, KalmanTuning, MotionModel, Observation,
    StaticPoses, TrackError, TrackerConfig, WindowProblem,
};
use roitrack_image::{BlobRejection, Centroid, CentroidOptions, Roi, measure_blob};
use roitrack_sim::{RenderScratch, RoiRenderer, SensorModel};

/// Time between two measurements (s): one ROI every 250 µs (4 kHz).
pub const ROI_PERIOD_S: f64 = 250e-6;
/// Standard deviation of the centroid noise added to the ideal projections (px).
pub const NOISE_PX: f64 = 0.1;
/// The degeneracy gate of the control step (reciprocal condition number), the tracker's default.
pub const MIN_INVERSE_CONDITION: f64 = 3e-3;
/// Gain of the control step.
pub const GAIN: f64 = 1.0;
/// Iteration cap of the full solves (never reached on the bench problems: they converge in a few iterations).
pub const MAX_ITERATIONS: usize = 50;
/// Velocity of the true motion at the reference time (m/s, camera frame).
pub const TRUTH_VELOCITY_MPS: [f64; 3] = [0.10, -0.05, 0.02];
/// Angular velocity of the true motion at the reference time (rad/s, camera frame).
pub const TRUTH_ANGULAR_VELOCITY_RADPS: [f64; 3] = [0.2, -0.1, 0.3];
/// Side of the ROI of the centroid and rendering items (px).
pub const ROI_SIZE_PX: u32 = 24;
/// Target point whose blob the ROI items image: id 5, a 6 mm blob near the target's centre.
pub const ROI_POINT_INDEX: usize = 5;
/// Seed of the noise of every bench problem.
pub const SEED: u64 = 2024;

/// The built-in scene (docs/model.md) with the true motion.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The camera: [`CameraModel::canonical`].
    pub camera: CameraModel,
    /// The target: [`Target::grid4x4`].
    pub target: Target,
    /// The spatio-temporal projection model of that camera and target.
    pub model: SpatioTemporalModel,
    /// The true state at the reference time: the bench pose, moving with the twist above.
    pub truth: MotionState,
}

/// The canonical scene: canonical camera, `grid4x4`, the bench pose moving with the bench twist.
pub fn scene() -> Scene {
    let camera = CameraModel::canonical();
    let model = SpatioTemporalModel::new(camera.intrinsics);
    let truth = MotionState {
        velocity_mps: Vector3::from(TRUTH_VELOCITY_MPS),
        angular_velocity_radps: Vector3::from(TRUTH_ANGULAR_VELOCITY_RADPS),
        ..MotionState::bench()
    };
    Scene {
        camera,
        target: Target::grid4x4(),
        model,
        truth,
    }
}

/// The correction (v, w, dV, dW) that takes the truth to the starting state of the control steps and solves: 1 mm of
/// position, 0.5° of rotation, 0.1 m/s of velocity and 0.1 rad/s of angular velocity, each along a fixed oblique
/// direction.
pub fn perturbation() -> Vector12 {
    let dir = |x: f64, y: f64, z: f64| Vector3::new(x, y, z).normalize();
    let mut delta = Vector12::zeros();
    delta
        .fixed_rows_mut::<3>(0)
        .copy_from(&(dir(1.0, -2.0, 2.0) * 1e-3));
    delta
        .fixed_rows_mut::<3>(3)
        .copy_from(&(dir(-2.0, 1.0, 2.0) * 0.5f64.to_radians()));
    delta
        .fixed_rows_mut::<3>(6)
        .copy_from(&(dir(2.0, 2.0, -1.0) * 0.1));
    delta
        .fixed_rows_mut::<3>(9)
        .copy_from(&(dir(1.0, 1.0, 1.0) * 0.1));
    delta
}

/// A window of measurements to fit the 12-dof state to.
#[derive(Debug, Clone)]
pub struct BenchWindow {
    /// Oldest first, [`ROI_PERIOD_S`] apart, in the bit-reversed order of the points.
    pub observations: Vec<Observation>,
    /// Reference time: that of the newest measurement (s).
    pub t_ref_s: f64,
    /// Starting state at `t_ref_s`: the truth corrected by [`perturbation`].
    pub initial: MotionState,
}

impl BenchWindow {
    /// The 12-dof least-squares problem of the window (exact Jacobian, plain least squares).
    pub fn problem<'a>(&'a self, scene: &'a Scene) -> WindowProblem<'a> {
        WindowProblem::new(
            &scene.model,
            scene.target.points(),
            &self.observations,
            self.t_ref_s,
        )
    }
}

impl Scene {
    /// `n` measurements 250 µs apart in the bit-reversed order, the newest at the truth's reference time, with
    /// noise of [`NOISE_PX`] drawn from `seed`.
    pub fn window(&self, n: usize, seed: u64) -> BenchWindow {
        let order = bit_reversed_indices(self.target.len());
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, NOISE_PX).expect("valid noise");
        let t_ref_s = (n.max(1) - 1) as f64 * ROI_PERIOD_S;
        let observations = (0..n)
            .map(|k| {
                let t_s = k as f64 * ROI_PERIOD_S;
                let point_index = order[k % order.len()];
                let p = &self.target.points()[point_index].point_in_obj_m;
                let ideal = self
                    .model
                    .project(&self.truth, p, t_s - t_ref_s)
                    .expect("bench points are in front of the camera");
                Observation {
                    t_s,
                    point_index,
                    ideal_px: ideal + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng)),
                }
            })
            .collect();
        BenchWindow {
            observations,
            t_ref_s,
            initial: self.truth.corrected(&perturbation()),
        }
    }

    /// One noisy measurement of each of the 16 points of the bench pose at rest (all at time 0): the static pose
    /// problem.
    pub fn static_observations(&self, seed: u64) -> Vec<Observation> {
        let at_rest = MotionState::bench();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, NOISE_PX).expect("valid noise");
        self.target
            .points()
            .iter()
            .enumerate()
            .map(|(point_index, p)| Observation {
                t_s: 0.0,
                point_index,
                ideal_px: self
                    .model
                    .project(&at_rest, &p.point_in_obj_m, 0.0)
                    .expect("bench points are in front of the camera")
                    + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng)),
            })
            .collect()
    }
}

/// The ROI items' inputs: the simulator, a 24 x 24 ROI around a 6 mm blob and its rendered 8-bit pixels.
#[derive(Debug, Clone)]
pub struct RoiProblem {
    /// The simulated camera that renders the ROI (default sensor).
    pub renderer: RoiRenderer,
    /// The ROI: [`ROI_SIZE_PX`] square around the blob of point [`ROI_POINT_INDEX`].
    pub roi: Roi,
    /// The state the ROI is rendered at (its reference time is the exposure midpoint, 0).
    pub state: MotionState,
    /// The ROI rendered once (default sensor: 8 bits, shot and read noise).
    pub pixels: Vec<u16>,
    /// The centroid options of `centroid_24` (defaults: with the symmetry check).
    pub options: CentroidOptions,
    rng: ChaCha8Rng,
    scratch: RenderScratch,
    out: Vec<u16>,
}

impl RoiProblem {
    /// The ROI of [`ROI_SIZE_PX`] centred on the projection of point [`ROI_POINT_INDEX`] at the scene's true state,
    /// rendered with the default sensor.
    pub fn new(scene: &Scene, seed: u64) -> Self {
        let renderer = RoiRenderer::new(
            scene.camera.clone(),
            scene.target.clone(),
            SensorModel::default(),
        )
        .expect("the default sensor is valid");
        let state = scene.truth;
        let centre = scene
            .camera
            .raw_pixel_from_cam(
                &state.point_in_cam_at(&scene.target.points()[ROI_POINT_INDEX].point_in_obj_m, 0.0),
            )
            .expect("the blob is in front of the camera");
        let roi = Roi::centred(
            centre.x,
            centre.y,
            ROI_SIZE_PX,
            scene.camera.width_px,
            scene.camera.height_px,
        )
        .expect("the blob is inside the sensor");
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut scratch = RenderScratch::new();
        let mut pixels = vec![0u16; roi.len()];
        renderer.render_roi_with_scratch(
            &|t| state.predicted(t),
            &roi,
            0.0,
            &mut rng,
            &mut scratch,
            &mut pixels,
        );
        let out = pixels.clone();
        Self {
            renderer,
            roi,
            state,
            pixels,
            options: CentroidOptions::default(),
            rng,
            scratch,
            out,
        }
    }
}

/// Period of the bench scene's oscillation in the Kalman stream (s): 4,000 measurements at 4 kHz.
pub const KALMAN_STREAM_PERIOD_S: f64 = 1.0;
/// Measurements the Kalman stream's filter takes after its initialisation before it is timed (10 cycles of the 16
/// points).
pub const KALMAN_WARM_UP_MEASUREMENTS: usize = 160;

/// An endless stream of measurements of the bench scene and a default Kalman filter tracking it: the input of the
/// `kalman_update` item.
///
/// The target oscillates about the bench pose with period [`KALMAN_STREAM_PERIOD_S`]: with `s(t) = P / (2π) sin(2π t /
/// P)`, the pose at time `t` is `R = Exp(W s) R₀`, `p = p₀ + V s` for the bench pose `(R₀, p₀)` and the bench twist
/// `(V, W)` (the twist at `t = 0`; ±16 mm and ±3.4° about the bench pose). Measurement `k` is at `k` x
/// [`ROI_PERIOD_S`], of the points in the bit-reversed order, the raw pixel of the true pose plus Gaussian noise of
/// [`NOISE_PX`]; one period of measurements is generated once and replayed with later times, so the stream never ends
/// and the timed calls allocate nothing.
///
/// ```
/// use roitrack_bench::{KalmanStream, SEED, scene};
/// use roitrack_estimators::Estimator;
///
/// let mut stream = KalmanStream::new(&scene(), SEED, usize::MAX);
/// // Initialised and warmed up: every push is one predict and update, no estimate due.
/// assert!(stream.estimator().state().is_some());
/// assert_eq!(stream.push(), Ok(None));
/// // ... and the filter follows the oscillation.
/// let (t_s, state) = stream.estimator().state().unwrap();
/// assert!((state.cam_t_obj_m - stream.truth_at(t_s).cam_t_obj_m).norm() < 1e-3);
/// assert_eq!(stream.next_measurement().t_s, stream.pushed() as f64 * roitrack_bench::ROI_PERIOD_S);
/// ```
#[derive(Debug, Clone)]
pub struct KalmanStream {
    estimator: KalmanEstimator,
    /// One period of measurements, times from 0.
    period: Vec<Measurement>,
    /// Index of the next measurement in the endless stream.
    next: u64,
    origin: MotionState,
}

impl KalmanStream {
    /// The stream of `scene` with noise drawn from `seed`, and a default Kalman filter ([`KalmanTuning::default`],
    /// [`TrackerConfig::default`] but an estimate every `every` measurements) fed until it is initialised, then
    /// [`KALMAN_WARM_UP_MEASUREMENTS`] more. `usize::MAX` for `every`: no estimate after the initialisation.
    pub fn new(scene: &Scene, seed: u64, every: usize) -> Self {
        Self::with_tuning(scene, seed, every, KalmanTuning::default())
    }

    /// [`Self::new`] with the filter's `tuning` instead of the default (the constant-acceleration model, say).
    ///
    /// ```
    /// use roitrack_bench::{KalmanStream, SEED, scene};
    /// use roitrack_estimators::{KalmanTuning, MotionModel};
    ///
    /// let tuning = KalmanTuning { motion_model: MotionModel::constant_acceleration(), ..KalmanTuning::default() };
    /// let mut stream = KalmanStream::with_tuning(&scene(), SEED, usize::MAX, tuning);
    /// assert_eq!(stream.push(), Ok(None));
    /// ```
    pub fn with_tuning(scene: &Scene, seed: u64, every: usize, tuning: KalmanTuning) -> Self {
        let origin = scene.truth;
        let n = (KALMAN_STREAM_PERIOD_S / ROI_PERIOD_S).round() as usize;
        let order = bit_reversed_indices(scene.target.len());
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, NOISE_PX).expect("valid noise");
        let period = (0..n)
            .map(|k| {
                let t_s = k as f64 * ROI_PERIOD_S;
                let point = &scene.target.points()[order[k % order.len()]];
                let state = Self::oscillation(&origin, t_s);
                let px = scene
                    .camera
                    .raw_pixel_from_cam(&state.point_in_cam_at(&point.point_in_obj_m, 0.0))
                    .expect("bench points are in front of the camera");
                Measurement {
                    t_s,
                    id: point.id,
                    u_px: px.x + noise.sample(&mut rng),
                    v_px: px.y + noise.sample(&mut rng),
                }
            })
            .collect();
        let config = TrackerConfig {
            every,
            ..TrackerConfig::default()
        };
        let estimator =
            KalmanEstimator::new(scene.camera.clone(), scene.target.clone(), config, tuning)
                .expect("the bench's Kalman options are valid");
        let mut stream = Self {
            estimator,
            period,
            next: 0,
            origin,
        };
        while stream.estimator.state().is_none() {
            assert!(
                stream.next < n as u64,
                "the Kalman filter did not initialise on the bench stream"
            );
            stream.push().expect("bench measurements are valid");
        }
        for _ in 0..KALMAN_WARM_UP_MEASUREMENTS {
            stream.push().expect("bench measurements are valid");
        }
        stream
    }

    /// The oscillating motion's state at time `t_s` (see the type's documentation).
    fn oscillation(origin: &MotionState, t_s: f64) -> MotionState {
        let phase = std::f64::consts::TAU * t_s / KALMAN_STREAM_PERIOD_S;
        let s = KALMAN_STREAM_PERIOD_S / std::f64::consts::TAU * phase.sin();
        let rate = phase.cos();
        MotionState {
            cam_r_obj: so3::exp(&(origin.angular_velocity_radps * s)) * origin.cam_r_obj,
            cam_t_obj_m: origin.cam_t_obj_m + origin.velocity_mps * s,
            velocity_mps: origin.velocity_mps * rate,
            angular_velocity_radps: origin.angular_velocity_radps * rate,
        }
    }

    /// The true state at time `t_s`.
    pub fn truth_at(&self, t_s: f64) -> MotionState {
        Self::oscillation(&self.origin, t_s)
    }

    /// The next measurement of the stream (without pushing it).
    pub fn next_measurement(&self) -> Measurement {
        let n = self.period.len() as u64;
        let m = self.period[(self.next % n) as usize];
        Measurement {
            t_s: self.next as f64 * ROI_PERIOD_S,
            ..m
        }
    }

    /// Pushes the next measurement into the filter; returns what the filter returns.
    #[inline(never)]
    pub fn push(&mut self) -> Result<Option<Estimate>, TrackError> {
        let m = self.next_measurement();
        self.next += 1;
        self.estimator.push(black_box(&m))
    }

    /// The filter.
    pub fn estimator(&self) -> &KalmanEstimator {
        &self.estimator
    }

    /// Measurements pushed so far.
    pub fn pushed(&self) -> u64 {
        self.next
    }
}

/// Every hot path's inputs, built once.
#[derive(Debug, Clone)]
pub struct HotPaths {
    /// The scene every input is drawn from.
    pub scene: Scene,
    /// The 16-measurement window of `jacobian_residual_w16` and `control_step_w16`.
    pub w16: BenchWindow,
    /// The 32-measurement window of `control_step_w32` and `gauss_newton_solve`.
    pub w32: BenchWindow,
    /// The static pose problem of `static_pose`: one noisy measurement per point, the target at rest.
    pub static_observations: Vec<Observation>,
    /// The ROI of `centroid_24`, `centroid_24_moments` and `render_roi`.
    pub roi: RoiProblem,
    /// The running Kalman filter of `kalman_update`, no estimate due.
    pub kalman: KalmanStream,
    /// The same with the constant-acceleration model (`kalman_update_constant_acceleration`).
    pub kalman_constant_acceleration: KalmanStream,
}

impl Default for HotPaths {
    fn default() -> Self {
        Self::new()
    }
}

impl HotPaths {
    /// Every input built from the scene, each with its own seed from [`SEED`].
    pub fn new() -> Self {
        let scene = scene();
        Self {
            w16: scene.window(16, SEED),
            w32: scene.window(32, SEED),
            static_observations: scene.static_observations(SEED + 1),
            roi: RoiProblem::new(&scene, SEED + 2),
            kalman: KalmanStream::new(&scene, SEED + 3, usize::MAX),
            kalman_constant_acceleration: KalmanStream::with_tuning(
                &scene,
                SEED + 3,
                usize::MAX,
                KalmanTuning {
                    motion_model: MotionModel::constant_acceleration(),
                    ..KalmanTuning::default()
                },
            ),
            scene,
        }
    }

    /// The window of `n` (16 or 32) measurements.
    pub fn window(&self, n: usize) -> &BenchWindow {
        match n {
            16 => &self.w16,
            32 => &self.w32,
            _ => panic!("bench windows are 16 or 32 measurements, not {n}"),
        }
    }

    /// Exact Jacobian and residual of the window, accumulated as normal equations.
    #[inline(never)]
    pub fn jacobian_residual(&self, n: usize) -> NormalEquations<12> {
        let w = self.window(n);
        black_box(w.problem(black_box(&self.scene))).normal_equations(black_box(&w.initial))
    }

    /// One control step: 1 iteration, exact Jacobian, gain 1, with the conditioning figure.
    #[inline(never)]
    pub fn control_step(&self, n: usize) -> Solution<MotionState, 12> {
        let w = self.window(n);
        let mut problem = black_box(w.problem(black_box(&self.scene)));
        solver::solve(
            &mut problem,
            black_box(w.initial),
            &SolverOptions::servo(1, GAIN, MIN_INVERSE_CONDITION),
        )
    }

    /// Levenberg-Marquardt of the 12 parameters to convergence on the window.
    #[inline(never)]
    pub fn gauss_newton_solve(&self, n: usize) -> Solution<MotionState, 12> {
        let w = self.window(n);
        let mut problem = black_box(w.problem(black_box(&self.scene)));
        solver::solve(
            &mut problem,
            black_box(w.initial),
            &SolverOptions::levenberg_marquardt(MAX_ITERATIONS),
        )
    }

    /// The static pose from scratch (16 points, no prior), refined to convergence.
    #[inline(never)]
    pub fn static_pose(&self) -> Result<StaticPoses, InitError> {
        roitrack_estimators::solve_static_pose(
            black_box(&self.scene.model),
            black_box(&self.scene.target),
            black_box(&self.static_observations),
            black_box(NOISE_PX),
        )
    }

    /// The centroid of the pre-rendered 24 x 24 ROI.
    #[inline(never)]
    pub fn centroid(&self) -> Result<Centroid, BlobRejection> {
        measure_blob(
            black_box(&self.roi.pixels),
            black_box(&self.roi.roi),
            black_box(&self.roi.options),
        )
    }

    /// The centroid of the pre-rendered 24 x 24 ROI without the symmetry check.
    #[inline(never)]
    pub fn centroid_moments(&self) -> Result<Centroid, BlobRejection> {
        let options = CentroidOptions {
            symmetry: None,
            ..self.roi.options
        };
        measure_blob(
            black_box(&self.roi.pixels),
            black_box(&self.roi.roi),
            black_box(&options),
        )
    }

    /// Renders the 24 x 24 ROI again (fresh noise each call, scratch buffers reused); returns its centre pixel.
    #[inline(never)]
    pub fn render_roi(&mut self) -> u16 {
        let r = &mut self.roi;
        let state = black_box(r.state);
        r.renderer.render_roi_with_scratch(
            &|t| state.predicted(t),
            black_box(&r.roi),
            0.0,
            &mut r.rng,
            &mut r.scratch,
            &mut r.out,
        );
        r.out[r.out.len() / 2 + ROI_SIZE_PX as usize / 2]
    }

    /// One measurement into the running Kalman filter (predict, update, window bookkeeping; no estimate due).
    #[inline(never)]
    pub fn kalman_update(&mut self) -> Result<Option<Estimate>, TrackError> {
        self.kalman.push()
    }

    /// The same into the constant-acceleration filter.
    #[inline(never)]
    pub fn kalman_update_constant_acceleration(&mut self) -> Result<Option<Estimate>, TrackError> {
        self.kalman_constant_acceleration.push()
    }
}

/// A timed hot path. [`Item::key`] is the prefix of its `roitrack bench --json` keys and its criterion benchmark id.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    /// `JᵀJ` and `Jᵀe` of the 16-measurement window, exact Jacobian.
    JacobianResidualW16,
    /// One virtual visual servoing step on 16 measurements, conditioning figure included.
    ControlStepW16,
    /// One virtual visual servoing step on 32 measurements, conditioning figure included.
    ControlStepW32,
    /// Levenberg-Marquardt of the 12 parameters to convergence on 32 measurements.
    GaussNewtonSolve,
    /// The static pose of 16 points from scratch, no prior.
    StaticPose,
    /// The centroid of the 24 x 24 ROI, with the symmetry check.
    Centroid24,
    /// The centroid of the same ROI from the first-order moments alone.
    Centroid24Moments,
    /// The simulator's rendering of that ROI, noise drawn.
    RenderRoi,
    /// One measurement pushed into the default Kalman filter.
    KalmanUpdate,
    /// One measurement pushed into the constant-acceleration Kalman filter.
    KalmanUpdateConstantAcceleration,
}

impl Item {
    /// Every item, in the order they are timed and printed.
    pub const ALL: [Item; 10] = [
        Item::JacobianResidualW16,
        Item::ControlStepW16,
        Item::ControlStepW32,
        Item::GaussNewtonSolve,
        Item::StaticPose,
        Item::Centroid24,
        Item::Centroid24Moments,
        Item::RenderRoi,
        Item::KalmanUpdate,
        Item::KalmanUpdateConstantAcceleration,
    ];

    /// Stable name: `roitrack bench --json` reports `<key>_us_median` and `<key>_us_p99`.
    pub fn key(self) -> &'static str {
        match self {
            Item::JacobianResidualW16 => "jacobian_residual_w16",
            Item::ControlStepW16 => "control_step_w16",
            Item::ControlStepW32 => "control_step_w32",
            Item::GaussNewtonSolve => "gauss_newton_solve",
            Item::StaticPose => "static_pose",
            Item::Centroid24 => "centroid_24",
            Item::Centroid24Moments => "centroid_24_moments",
            Item::RenderRoi => "render_roi",
            Item::KalmanUpdate => "kalman_update",
            Item::KalmanUpdateConstantAcceleration => "kalman_update_constant_acceleration",
        }
    }

    /// What is timed, for tables.
    pub fn label(self) -> &'static str {
        match self {
            Item::JacobianResidualW16 => "exact Jacobian + residual, window 16",
            Item::ControlStepW16 => "control step, exact, 1 iteration, window 16",
            Item::ControlStepW32 => "control step, exact, 1 iteration, window 32",
            Item::GaussNewtonSolve => "Gauss-Newton (LM) to convergence, window 32",
            Item::StaticPose => "static pose from scratch, 16 points",
            Item::Centroid24 => "ROI centroid, 24x24 8-bit, symmetry checked",
            Item::Centroid24Moments => "ROI centroid, 24x24 8-bit, moments only",
            Item::RenderRoi => "ROI rendering (simulator), 24x24, one blob",
            Item::KalmanUpdate => "Kalman filter, one measurement, running track",
            Item::KalmanUpdateConstantAcceleration => {
                "Kalman filter, constant acceleration, one measurement, running track"
            }
        }
    }
}

/// Per-call time of an item.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Median over batches of the batch time divided by the batch size (µs).
    pub median_us: f64,
    /// 99th percentile of the same (µs). With batches of more than one call it is the p99 of a batch's mean, which
    /// smooths single-call outliers: per-call p99 only where `batch_size` is 1.
    pub p99_us: f64,
    /// Calls per timed batch.
    pub batch_size: usize,
    /// Batches timed.
    pub batches: usize,
}

/// Shortest batch the timer aims at (s): each batch runs at least this long, so the clock's own cost (about 20-40 ns a
/// reading) stays below about 1 % of it.
pub const BATCH_TARGET_S: f64 = 5e-6;
/// Fewest batches timed, whatever the budget.
pub const MIN_BATCHES: usize = 20;

/// Times `f` in about `budget`: a tenth of it warms up and estimates the per-call time, which sets the batch size (one
/// batch lasting at least [`BATCH_TARGET_S`]); then batches are timed until the budget is spent (at least
/// [`MIN_BATCHES`]), each giving batch time / batch size. Returns the median and p99 of those. The result of every
/// call goes through [`black_box`]; `f` should take its inputs through it too (the [`HotPaths`] methods do).
pub fn time_item<R>(mut f: impl FnMut() -> R, budget: Duration) -> Timing {
    // Warm-up and calibration: double the calls until a tenth of the budget is spent.
    let calibration = (budget / 10).max(Duration::from_micros(100));
    let start = Instant::now();
    let (mut calls, mut n) = (0u64, 1u64);
    loop {
        for _ in 0..n {
            black_box(f());
        }
        calls += n;
        if start.elapsed() >= calibration {
            break;
        }
        n = (n * 2).min(1 << 20);
    }
    let per_call_s = start.elapsed().as_secs_f64() / calls as f64;
    let batch_size = ((BATCH_TARGET_S / per_call_s).ceil() as usize).clamp(1, 1 << 20);
    let remaining = budget.saturating_sub(start.elapsed());
    let expected = (remaining.as_secs_f64() / (per_call_s * batch_size as f64)).ceil() as usize;
    let mut samples = Vec::with_capacity(expected.clamp(MIN_BATCHES, 10_000_000) + 16);
    let end = Instant::now() + remaining;
    loop {
        let t0 = Instant::now();
        for _ in 0..batch_size {
            black_box(f());
        }
        let dt = t0.elapsed();
        samples.push(dt.as_secs_f64() * 1e6 / batch_size as f64);
        if samples.len() >= MIN_BATCHES && Instant::now() >= end {
            break;
        }
    }
    samples.sort_by(f64::total_cmp);
    Timing {
        median_us: roitrack_core::stats::quantile(&samples, 0.5),
        p99_us: roitrack_core::stats::quantile(&samples, 0.99),
        batch_size,
        batches: samples.len(),
    }
}

/// Times every [`Item`] with `budget` each, in [`Item::ALL`]'s order.
pub fn time_all(hot: &mut HotPaths, budget: Duration) -> Vec<(Item, Timing)> {
    Item::ALL
        .iter()
        .map(|&item| {
            let timing = match item {
                Item::JacobianResidualW16 => time_item(|| hot.jacobian_residual(16), budget),
                Item::ControlStepW16 => time_item(|| hot.control_step(16), budget),
                Item::ControlStepW32 => time_item(|| hot.control_step(32), budget),
                Item::GaussNewtonSolve => time_item(|| hot.gauss_newton_solve(32), budget),
                Item::StaticPose => time_item(|| hot.static_pose(), budget),
                Item::Centroid24 => time_item(|| hot.centroid(), budget),
                Item::Centroid24Moments => time_item(|| hot.centroid_moments(), budget),
                Item::RenderRoi => time_item(|| hot.render_roi(), budget),
                Item::KalmanUpdate => time_item(|| hot.kalman_update(), budget),
                Item::KalmanUpdateConstantAcceleration => {
                    time_item(|| hot.kalman_update_constant_acceleration(), budget)
                }
            };
            (item, timing)
        })
        .collect()
}

/// The calling thread's time on a CPU so far (Linux: `/proc/thread-self/schedstat`, ns), if the system tells it:
/// what a thread pays for its own work, whatever else runs beside it.
///
/// ```
/// let before = roitrack_bench::thread_cpu_time();
/// let sum: u64 = (0..1_000_000u64).map(std::hint::black_box).sum();
/// if let (Some(a), Some(b)) = (before, roitrack_bench::thread_cpu_time()) {
///     assert!(b >= a && sum > 0);
/// }
/// ```
pub fn thread_cpu_time() -> Option<Duration> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: u64 = text.split_whitespace().next()?.parse().ok()?;
    Some(Duration::from_nanos(ns))
}

/// The calling thread's CPU time over `passes` runs of `pass` ([`thread_cpu_time`]), if the system tells it.
///
/// ```
/// let cpu = roitrack_bench::cpu_time_of(3, || {
///     std::hint::black_box((0..100_000u64).sum::<u64>());
/// });
/// if let Some(cpu) = cpu {
///     println!("{cpu:?} on a CPU");
/// }
/// ```
pub fn cpu_time_of(passes: usize, mut pass: impl FnMut()) -> Option<Duration> {
    let start = thread_cpu_time()?;
    for _ in 0..passes {
        pass();
    }
    Some(thread_cpu_time()? - start)
}

#[cfg(test)]
mod tests {
    use super::*;
    use roitrack_core::so3;

    #[test]
    fn the_bench_problems_are_the_intended_ones() {
        let mut hot = HotPaths::new();
        assert_eq!(hot.w16.observations.len(), 16);
        assert_eq!(hot.w32.observations.len(), 32);
        // Bit-reversed order, 250 µs apart.
        let ids: Vec<usize> = hot.w16.observations.iter().map(|o| o.point_index).collect();
        assert_eq!(ids, bit_reversed_indices(16));
        assert!((hot.w32.t_ref_s - 31.0 * ROI_PERIOD_S).abs() < 1e-15);

        // The control steps are applied (the windows pass the degeneracy gate) and reduce the error.
        for n in [16, 32] {
            let step = hot.control_step(n);
            assert_eq!(
                step.report.steps_applied, 1,
                "window {n}: {:?}",
                step.report
            );
            assert!(step.report.inverse_condition.unwrap() >= MIN_INVERSE_CONDITION);
            let before = (hot.window(n).initial.cam_t_obj_m - hot.scene.truth.cam_t_obj_m).norm();
            let after = (step.params.cam_t_obj_m - hot.scene.truth.cam_t_obj_m).norm();
            assert!(after < before, "window {n}: {after} >= {before}");
            assert_eq!(hot.jacobian_residual(n).count(), n);
        }

        // The full solve converges well before the cap, near the truth (Cramer-Rao: 0.4 mm in depth for 32).
        let fit = hot.gauss_newton_solve(32);
        assert!(fit.report.converged, "{:?}", fit.report);
        assert!(fit.report.iterations < MAX_ITERATIONS, "{:?}", fit.report);
        assert!(fit.normal_equations.residual_rms_px() < 3.0 * NOISE_PX);
        assert!((fit.params.cam_t_obj_m - hot.scene.truth.cam_t_obj_m).norm() < 3e-3);

        // The static pose from scratch is the converged 6-dof VVS from the truth.
        let poses = hot.static_pose().unwrap();
        assert!(!poses.is_ambiguous());
        let fit = poses.best();
        assert!(fit.converged);
        let vvs = roitrack_estimators::refine_static_pose(
            &hot.scene.model,
            &hot.scene.target,
            &hot.static_observations,
            &MotionState::bench(),
            MAX_ITERATIONS,
        );
        assert!(vvs.converged);
        assert!((fit.state.cam_t_obj_m - vvs.state.cam_t_obj_m).norm() < 1e-9);
        assert!(so3::angle_between(&fit.state.cam_r_obj, &vvs.state.cam_r_obj) < 1e-9);

        // The ROI holds the whole blob: a centroid near the projected centre.
        let c = hot.centroid().unwrap();
        let p = hot.scene.truth.point_in_cam_at(
            &hot.scene.target.points()[ROI_POINT_INDEX].point_in_obj_m,
            0.0,
        );
        let truth = hot.scene.camera.raw_pixel_from_cam(&p).unwrap();
        assert!((c.u_px - truth.x).abs() < 0.1 && (c.v_px - truth.y).abs() < 0.1);
        assert_eq!(hot.roi.pixels.len(), 24 * 24);
        assert!(hot.roi.pixels.iter().all(|&v| v <= 255));
        // Rendering again draws fresh noise but the same blob.
        hot.render_roi();
        let again = measure_blob(&hot.roi.out, &hot.roi.roi, &hot.roi.options).unwrap();
        assert!((again.u_px - c.u_px).abs() < 0.05);

        // The Kalman stream is tracked: no estimate due, the filter's state near the truth, a full period later too.
        let start = hot.kalman.pushed();
        for _ in 0..4000 {
            assert_eq!(hot.kalman_update(), Ok(None));
        }
        let report = hot.kalman.estimator().report();
        assert_eq!(report.initialisations, 1, "{report:?}");
        assert_eq!(report.measurements as u64, hot.kalman.pushed());
        assert!(hot.kalman.pushed() >= start + 4000);
        let (t_s, state) = hot.kalman.estimator().state().unwrap();
        let truth = hot.kalman.truth_at(t_s);
        assert!(
            (state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-3,
            "{state:?} {truth:?}"
        );
        assert!(so3::angle_between(&state.cam_r_obj, &truth.cam_r_obj) < 0.2f64.to_radians());
        assert!(
            (state.velocity_mps - truth.velocity_mps).norm() < 0.05,
            "{state:?} {truth:?}"
        );
    }

    #[test]
    fn the_kalman_stream_is_periodic_and_continuous() {
        let stream = KalmanStream::new(&scene(), SEED, usize::MAX);
        let n = stream.period.len();
        assert_eq!(n, 4000);
        // The motion after one period is where it started, and the true twist at 0 is the bench twist.
        let (a, b) = (stream.truth_at(0.1), stream.truth_at(1.1));
        assert!(MotionState::difference(&a, &b).norm() < 1e-12);
        let truth = stream.truth_at(0.0);
        assert!(MotionState::difference(&truth, &scene().truth).norm() < 1e-15);
        // The replayed measurements keep going in time, 250 µs apart, in the same point order.
        let m = stream.next_measurement();
        assert!((m.t_s - stream.pushed() as f64 * ROI_PERIOD_S).abs() < 1e-12);
        let k = stream.pushed() as usize % n;
        assert_eq!(m.id, stream.period[k].id);
        assert_eq!(stream.period[0].id, stream.period[16].id);
    }

    #[test]
    fn the_timer_reports_batches() {
        let t = time_item(|| black_box(3u64).pow(2), Duration::from_millis(5));
        assert!(t.batch_size > 1, "{t:?}");
        assert!(t.batches >= MIN_BATCHES);
        assert!(t.median_us > 0.0 && t.median_us <= t.p99_us);
        let slow = time_item(
            || std::thread::sleep(Duration::from_micros(50)),
            Duration::from_millis(1),
        );
        assert_eq!(slow.batch_size, 1);
        assert!(slow.batches >= MIN_BATCHES);
        assert!(slow.median_us >= 50.0);
    }
}
