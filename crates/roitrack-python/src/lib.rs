//! The `roitrack` Python package: the library's camera, target, tracker, simulator, photograph detection and metrics,
//! with numpy arrays in and out. This crate only translates: every job is a call into the `roitrack` library, the
//! same the command-line tool makes, so results and error messages are the command line's.
//!
//! Errors: a file that cannot be read raises `OSError` (`FileNotFoundError` when missing); a malformed file, an
//! invalid option or a refused measurement raises `roitrack.RoitrackError` (a `ValueError`) with the command line's
//! message (file, line and field for files); an array of the wrong shape raises `ValueError` and one of the wrong
//! dtype `TypeError`, both naming the argument.
#![deny(missing_docs)]

use std::path::PathBuf;
use std::sync::Mutex;

use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use roitrack::core::camera::PinholeIntrinsics;
use roitrack::detect::{PhotoError, PhotoOptions, PolarityChoice};
use roitrack::estimators::{TrackerOptions, UnknownName};
use roitrack::formats::FormatError;
use roitrack::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use roitrack::sim::{Scenario, ScenarioKind, SimulationOptions};
use roitrack::{
    CameraModel, Estimate as RustEstimate, Estimator, Frame, Measurement, PoseSample, Target,
    TargetPoint, TwistSample,
};

create_exception!(
    _roitrack,
    RoitrackError,
    PyValueError,
    "Bad input or options, refused by the roitrack library; the message is the command line's (a file's errors name \
     the file, the line and the field)."
);

/// A library error as a Python exception, with the message of the command line (`{error:#}`: the chain of causes).
fn library_error(error: &dyn std::error::Error) -> PyErr {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let text = cause.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        source = cause.source();
    }
    RoitrackError::new_err(message)
}

/// A file error: `OSError` (or `FileNotFoundError`) when the file could not be read, else `RoitrackError`.
fn format_error(error: FormatError) -> PyErr {
    match error.io_error().map(|e| e.kind()) {
        Some(std::io::ErrorKind::NotFound) => PyFileNotFoundError::new_err(error.to_string()),
        Some(_) => PyOSError::new_err(error.to_string()),
        None => RoitrackError::new_err(error.to_string()),
    }
}

fn name_error(error: UnknownName) -> PyErr {
    PyValueError::new_err(error.to_string())
}

/// `argument` as a 2-D float64 array with `columns` columns (`None`: any), copied out row by row. A numpy array of
/// another dtype raises `TypeError`; a sequence is converted by numpy first.
fn f64_rows(
    argument: &Bound<'_, PyAny>,
    name: &str,
    columns: Option<usize>,
) -> PyResult<(usize, usize, Vec<f64>)> {
    let py = argument.py();
    let array =
        if let Ok(array) = argument.cast::<PyUntypedArray>() {
            if !array.dtype().is_equiv_to(&numpy::dtype::<f64>(py)) {
                return Err(PyTypeError::new_err(format!(
                    "{name}: expected a float64 array, got dtype {}",
                    array.dtype()
                )));
            }
            array.clone()
        } else {
            let numpy = py.import("numpy")?;
            let converted = numpy
            .call_method1("asarray", (argument, "float64"))
            .map_err(|e| {
                PyTypeError::new_err(format!(
                    "{name}: expected a float64 array (or numbers numpy can convert), got {}: {e}",
                    argument.get_type().name().map_or("?".into(), |n| n.to_string())
                ))
            })?;
            converted.cast_into::<PyUntypedArray>()?
        };
    let shape = array.shape().to_vec();
    let wanted = columns.map_or("(N, M)".to_string(), |c| format!("(N, {c})"));
    if shape.len() != 2 || columns.is_some_and(|c| shape[1] != c) {
        return Err(PyValueError::new_err(format!(
            "{name}: expected an array of shape {wanted}, got shape {shape:?}"
        )));
    }
    let typed = array.cast::<PyArray2<f64>>()?;
    let readonly = typed.readonly();
    let view = readonly.as_array();
    Ok((shape[0], shape[1], view.iter().copied().collect()))
}

/// A camera: ROS camera_info intrinsics (pinhole with skew) and plumb_bob distortion `[k1, k2, p1, p2, k3]`.
///
/// >>> cam = roitrack.Camera(1024, 1024, 1500.0, 1500.0, 512.0, 512.0)
/// >>> cam = roitrack.Camera.from_yaml("camera.yaml")
#[pyclass(module = "roitrack", frozen)]
struct Camera {
    inner: CameraModel,
}

#[pymethods]
impl Camera {
    /// A camera of `width` x `height` pixels, focal lengths `fx`, `fy` and principal point `cx`, `cy` (px), `skew`
    /// (px, camera_matrix[0][1]), and the lens `distortion` of `model` in ROS's and OpenCV's order: plumb_bob
    /// `[k1, k2, p1, p2(, k3)]`, rational_polynomial `[k1, k2, p1, p2, k3, k4, k5, k6]`, equidistant (OpenCV's
    /// fisheye) `[k1, k2, k3, k4]`; none or an empty list for a pinhole camera.
    #[new]
    #[pyo3(signature = (width, height, fx, fy, cx, cy, distortion = None, model = "plumb_bob", skew = 0.0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        distortion: Option<Vec<f64>>,
        model: &str,
        skew: f64,
    ) -> PyResult<Self> {
        let distortion =
            roitrack::formats::distortion_from(model, distortion.as_deref().unwrap_or(&[]))
                .map_err(|e| PyValueError::new_err(format!("distortion: {e}")))?;
        let intrinsics = PinholeIntrinsics {
            fx_px: fx,
            fy_px: fy,
            skew_px: skew,
            cx_px: cx,
            cy_px: cy,
        };
        CameraModel::new("camera", width, height, intrinsics, distortion)
            .map(|inner| Self { inner })
            .map_err(|e| library_error(&e))
    }

    /// Reads a camera calibration file as `roitrack track --camera` does: ROS camera_info YAML (and ROS topic
    /// echoes), OpenCV FileStorage YAML or XML, or a Kalibr camchain, recognised by content.
    #[staticmethod]
    fn from_yaml(path: PathBuf) -> PyResult<Self> {
        Self::from_file(path, None, None)
    }

    /// Reads any camera file `from_yaml` reads, with the command line's `--image-size` (width, height: for OpenCV
    /// files without one) and `--camera-name` (which camera of a Kalibr camchain).
    #[staticmethod]
    #[pyo3(signature = (path, image_size = None, camera_name = None))]
    fn from_file(
        path: PathBuf,
        image_size: Option<(u32, u32)>,
        camera_name: Option<String>,
    ) -> PyResult<Self> {
        let options = roitrack::formats::CameraFileOptions {
            image_size,
            camera_name,
        };
        roitrack::formats::read_camera_file(&path, &options)
            .map(|inner| Self { inner })
            .map_err(format_error)
    }

    /// Writes the camera as a ROS camera_info YAML file (atomically).
    fn to_yaml(&self, path: PathBuf) -> PyResult<()> {
        roitrack::formats::write_camera_yaml(&path, &self.inner).map_err(format_error)
    }

    /// Image width (px).
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width_px
    }
    /// Image height (px).
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height_px
    }
    /// Focal length along x (px).
    #[getter]
    fn fx(&self) -> f64 {
        self.inner.intrinsics.fx_px
    }
    /// Focal length along y (px).
    #[getter]
    fn fy(&self) -> f64 {
        self.inner.intrinsics.fy_px
    }
    /// Principal point x (px).
    #[getter]
    fn cx(&self) -> f64 {
        self.inner.intrinsics.cx_px
    }
    /// Principal point y (px).
    #[getter]
    fn cy(&self) -> f64 {
        self.inner.intrinsics.cy_px
    }
    /// Skew (px).
    #[getter]
    fn skew(&self) -> f64 {
        self.inner.intrinsics.skew_px
    }
    /// The distortion coefficients, in ROS's and OpenCV's order for the model.
    #[getter]
    fn distortion(&self) -> Vec<f64> {
        self.inner.distortion.coefficients()
    }
    /// The distortion model: none, plumb_bob, rational_polynomial or equidistant.
    #[getter]
    fn model(&self) -> &'static str {
        self.inner.distortion.model_name()
    }

    fn __repr__(&self) -> String {
        let i = &self.inner.intrinsics;
        format!(
            "Camera({}, {}, fx={}, fy={}, cx={}, cy={}, skew={}, distortion={:?}, model={:?})",
            self.inner.width_px,
            self.inner.height_px,
            i.fx_px,
            i.fy_px,
            i.cx_px,
            i.cy_px,
            i.skew_px,
            self.inner.distortion.coefficients(),
            self.inner.distortion.model_name()
        )
    }
}

/// A rigid target: model points (m) in the object frame, their ids (as in the measurements) and optional blob
/// diameters (m).
///
/// >>> tgt = roitrack.Target.from_csv("target.csv")
/// >>> tgt = roitrack.Target(np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]], dtype=float))
#[pyclass(module = "roitrack", name = "Target", frozen)]
struct Target_ {
    inner: Target,
}

#[pymethods]
impl Target_ {
    /// A target of `points_m` ((N, 3) float64, metres), with `ids` (N integers; default 0..N-1) and `diameters_m`
    /// (N blob diameters, metres; default unknown). At least 4 points, unique ids, not all on one line.
    #[new]
    #[pyo3(signature = (points_m, ids = None, diameters_m = None))]
    fn new(
        points_m: &Bound<'_, PyAny>,
        ids: Option<Vec<u32>>,
        diameters_m: Option<Vec<f64>>,
    ) -> PyResult<Self> {
        let (n, _, values) = f64_rows(points_m, "points_m", Some(3))?;
        if let Some(ids) = &ids
            && ids.len() != n
        {
            return Err(PyValueError::new_err(format!(
                "ids: expected {n} ids (one per row of points_m), got {}",
                ids.len()
            )));
        }
        if let Some(d) = &diameters_m
            && d.len() != n
        {
            return Err(PyValueError::new_err(format!(
                "diameters_m: expected {n} diameters (one per row of points_m), got {}",
                d.len()
            )));
        }
        let points = (0..n)
            .map(|k| TargetPoint {
                id: ids.as_ref().map_or(k as u32, |ids| ids[k]),
                point_in_obj_m: Vector3::new(values[3 * k], values[3 * k + 1], values[3 * k + 2]),
                diameter_m: diameters_m.as_ref().map(|d| d[k]),
            })
            .collect();
        Target::new(points)
            .map(|inner| Self { inner })
            .map_err(|e| library_error(&e))
    }

    /// Reads a target CSV file `id,x,y,z[,diameter]` as `roitrack track --target` does: in metres, refusing a target
    /// that looks like millimetres or centimetres, unless `units` ("m", "cm" or "mm", the command line's
    /// `--target-units`) says the file's unit.
    #[staticmethod]
    #[pyo3(signature = (path, units = None))]
    fn from_csv(path: PathBuf, units: Option<&str>) -> PyResult<Self> {
        use roitrack::formats::LengthUnit;
        let units = match units {
            None => None,
            Some("m") => Some(LengthUnit::M),
            Some("cm") => Some(LengthUnit::Cm),
            Some("mm") => Some(LengthUnit::Mm),
            Some(other) => {
                return Err(PyValueError::new_err(format!(
                    "units: unknown value '{other}' (expected one of m, cm, mm)"
                )));
            }
        };
        roitrack::formats::read_target_csv_in(&path, units)
            .map(|inner| Self { inner })
            .map_err(format_error)
    }

    /// Writes the target as a CSV file (atomically).
    fn to_csv(&self, path: PathBuf) -> PyResult<()> {
        roitrack::formats::write_target_csv(&path, &self.inner).map_err(format_error)
    }

    /// The model points, (N, 3) float64, metres, object frame.
    #[getter]
    fn points_m<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let points = self.inner.points();
        Array2::from_shape_fn((points.len(), 3), |(k, j)| points[k].point_in_obj_m[j])
            .into_pyarray(py)
    }

    /// The point ids, (N,) uint32.
    #[getter]
    fn ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        let ids: Vec<u32> = self.inner.points().iter().map(|p| p.id).collect();
        ids.into_pyarray(py)
    }

    /// The blob diameters (m), (N,) float64, NaN where unknown.
    #[getter]
    fn diameters_m<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let d: Vec<f64> = self
            .inner
            .points()
            .iter()
            .map(|p| p.diameter_m.unwrap_or(f64::NAN))
            .collect();
        d.into_pyarray(py)
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    fn __repr__(&self) -> String {
        format!("Target({} points)", self.inner.len())
    }
}

/// One output of a tracker: the pose (camera_T_object) and the twist (camera frame) at `t_s`, with status, residual,
/// conditioning and the 12 x 12 covariance.
#[pyclass(module = "roitrack", frozen)]
struct Estimate {
    inner: RustEstimate,
}

fn quaternion_xyzw(e: &RustEstimate) -> [f64; 4] {
    let q = PoseSample::from_state(e.t_ref_s, &e.state)
        .cam_from_obj
        .rotation;
    [q.i, q.j, q.k, q.w]
}

/// The covariance row by row, as the covariance file has it (`track --covariance`): the symmetric part of the
/// estimator's matrix (which rounding may leave slightly asymmetric), from the file's upper triangle; NaN without one.
fn covariance_entries(e: &RustEstimate) -> [f64; 144] {
    let mut out = [f64::NAN; 144];
    if let Some(c) = &e.covariance {
        let upper = roitrack::formats::covariance_upper_triangle(c);
        let mut k = 0;
        for i in 0..12 {
            for j in i..12 {
                out[12 * i + j] = upper[k];
                out[12 * j + i] = upper[k];
                k += 1;
            }
        }
    }
    out
}

#[pymethods]
impl Estimate {
    /// Time of the estimate (s): that of the newest measurement it used (the t of the TUM file).
    #[getter]
    fn t_s(&self) -> f64 {
        self.inner.t_ref_s
    }
    /// Position of the object's origin in the camera frame (m), (3,).
    #[getter]
    fn position_m<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.state.cam_t_obj_m.as_slice())
    }
    /// Orientation camera_R_object as a unit quaternion [x, y, z, w], (4,).
    #[getter]
    fn quaternion_xyzw<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &quaternion_xyzw(&self.inner))
    }
    /// Velocity of the object's origin, camera frame (m/s), (3,).
    #[getter]
    fn velocity_mps<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.state.velocity_mps.as_slice())
    }
    /// Angular velocity, camera frame (rad/s), (3,).
    #[getter]
    fn angular_velocity_radps<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.state.angular_velocity_radps.as_slice())
    }
    /// The 12 x 12 covariance in the order position, rotation, velocity, angular velocity (as `track --covariance`);
    /// NaN everywhere when the estimate has none.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        PyArray1::from_slice(py, &covariance_entries(&self.inner)).reshape([12, 12])
    }
    /// converging, tracking, degenerate, disputed or lost (as in the diagnostics file).
    #[getter]
    fn status(&self) -> &'static str {
        self.inner.status.name()
    }
    /// RMS reprojection residual (px).
    #[getter]
    fn residual_px(&self) -> f64 {
        self.inner.residual_rms_px
    }
    /// Reciprocal condition number of the window's column-scaled Jacobian (1 perfect, 0 singular).
    #[getter]
    fn conditioning(&self) -> f64 {
        self.inner.inverse_condition
    }
    /// Measurements in the window.
    #[getter]
    fn measurements_used(&self) -> usize {
        self.inner.measurements_used
    }
    /// The centroid noise (px) the estimate was computed with.
    #[getter]
    fn noise_px(&self) -> f64 {
        self.inner.noise_px
    }

    fn __repr__(&self) -> String {
        let p = &self.inner.state.cam_t_obj_m;
        format!(
            "Estimate(t_s={}, position_m=[{}, {}, {}], status={:?})",
            self.inner.t_ref_s,
            p.x,
            p.y,
            p.z,
            self.inner.status.name()
        )
    }
}

/// Checks options as the command line does (densities of the other motion model refused).
fn checked(options: TrackerOptions) -> PyResult<TrackerOptions> {
    options
        .check()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(options)
}

/// A table entry's Python type: a named value by its name (`str`).
macro_rules! py_type {
    (number $ty:ty) => { $ty };
    (named $ty:ty) => { &str };
    (optional_number $ty:ty) => { Option<$ty> };
    (optional_named $ty:ty) => { Option<&str> };
}

/// A table entry's value from its Python argument `$arg`: a name looked up (ValueError listing the names).
macro_rules! py_value {
    (number $ty:ty, $arg:ident) => {
        $arg
    };
    (named $ty:ty, $arg:ident) => {
        <$ty>::from_name($arg).map_err(name_error)?
    };
    (optional_number $ty:ty, $arg:ident) => {
        $arg
    };
    (optional_named $ty:ty, $arg:ident) => {
        $arg.map(<$ty>::from_name).transpose().map_err(name_error)?
    };
}

fn new_tracker(
    camera: &Camera,
    target: &Target_,
    options: &TrackerOptions,
) -> PyResult<roitrack::Tracker> {
    roitrack::Tracker::new(camera.inner.clone(), target.inner.clone(), options.config())
        .map_err(|e| RoitrackError::new_err(format!("invalid tracker options: {e}")))
}

/// A streaming tracker: push centroids one at a time, get an Estimate every `every` measurements once initialised.
/// The keywords are the tracker options of `roitrack track`, `_` for `-` (see `roitrack track --help` for what each
/// does and the names it takes: estimator kalman, exact, paper, static or batch, ...).
///
/// >>> tr = roitrack.Tracker(cam, tgt, estimator="kalman", every=10)
/// >>> est = tr.push(0.0, 3, 512.2, 498.7)   # None until an estimate is due
#[pyclass(module = "roitrack", frozen)]
struct Tracker {
    inner: Mutex<roitrack::Tracker>,
}

/// `Tracker(camera, target, ...)` and `track(camera, target, measurements, ...)` with one keyword argument per entry of
/// the library's table of tracker options ([`roitrack::estimators::tracker_options!`]), its default the table's, and
/// `_tracker_options()`, the table as the tests compare it with the signatures and the stubs.
macro_rules! tracker_api {
    ($($(#[doc = $doc:literal])* $name:ident : $shape:ident $ty:ty = $default:tt $(, $check:ident ($($arg:expr),*))?;)*) => {
        #[pymethods]
        impl Tracker {
            #[new]
            #[pyo3(signature = (camera, target, $($name = $default),*))]
            #[allow(clippy::too_many_arguments)]
            fn new(
                camera: PyRef<'_, Camera>,
                target: PyRef<'_, Target_>,
                $($name: py_type!($shape $ty),)*
            ) -> PyResult<Self> {
                let options = checked(TrackerOptions { $($name: py_value!($shape $ty, $name),)* })?;
                Ok(Self {
                    inner: Mutex::new(new_tracker(&camera, &target, &options)?),
                })
            }

    /// Takes one centroid: time (s, not decreasing), point id, raw pixel (u, v). Returns None, or an Estimate when
    /// one is due. A refused measurement raises RoitrackError and leaves the tracker as it was.
    fn push(&self, t_s: f64, point_id: u32, u_px: f64, v_px: f64) -> PyResult<Option<Estimate>> {
        let m = Measurement {
            t_s,
            id: point_id,
            u_px,
            v_px,
        };
        let mut tracker = self
            .inner
            .lock()
            .map_err(|_| RoitrackError::new_err("the tracker was poisoned by an earlier panic"))?;
        match tracker.push(&m) {
            Ok(estimate) => Ok(estimate.map(|inner| Estimate { inner })),
            Err(e) => Err(library_error(&e)),
        }
    }

    /// Drops the current track: the next measurements initialise a new one.
    fn reset(&self) {
        if let Ok(mut tracker) = self.inner.lock() {
            tracker.reset();
        }
    }

    /// Measurements accepted so far.
    #[getter]
    fn measurements(&self) -> usize {
        self.inner.lock().map_or(0, |t| t.report().measurements)
    }
        }

        /// Tracks a whole recording: `measurements` is an (N, 4) float64 array of rows t (s), id, u, v (raw px), in
        /// time order, as `roitrack track --measurements` reads them (rows sharing a time form one readout). The
        /// keywords are Tracker's. Returns a dict of arrays, one row per estimate: t_s (M,), position_m (M, 3),
        /// quaternion_xyzw (M, 4), velocity_mps (M, 3), angular_velocity_radps (M, 3), covariance (M, 12, 12),
        /// status (M,) str, residual_px (M,), conditioning (M,). Releases the GIL while tracking.
        #[pyfunction]
        #[pyo3(signature = (camera, target, measurements, $($name = $default),*))]
        #[allow(clippy::too_many_arguments)]
        fn track<'py>(
            py: Python<'py>,
            camera: PyRef<'py, Camera>,
            target: PyRef<'py, Target_>,
            measurements: &Bound<'py, PyAny>,
            $($name: py_type!($shape $ty),)*
        ) -> PyResult<Bound<'py, PyDict>> {
            let options = checked(TrackerOptions { $($name: py_value!($shape $ty, $name),)* })?;
            track_with(py, &camera, &target, measurements, &options)
        }

        /// The table of tracker options as (name, shape, default as Python writes it, Rust type), for the tests that
        /// compare it with the signatures of `Tracker` and `track` and with the stubs.
        #[pyfunction]
        fn _tracker_options() -> Vec<(&'static str, &'static str, &'static str, &'static str)> {
            vec![$((stringify!($name), stringify!($shape), stringify!($default), stringify!($ty))),*]
        }
    };
}

roitrack::estimators::tracker_options!(tracker_api);

/// Estimates as arrays, filled as they come (no per-estimate Python object).
struct EstimateColumns {
    t_s: Vec<f64>,
    position_m: Vec<f64>,
    quaternion_xyzw: Vec<f64>,
    velocity_mps: Vec<f64>,
    angular_velocity_radps: Vec<f64>,
    covariance: Vec<f64>,
    status: Vec<&'static str>,
    residual_px: Vec<f64>,
    conditioning: Vec<f64>,
}

impl EstimateColumns {
    /// Room for `estimates` estimates, so that the columns are not copied as they grow.
    fn with_capacity(estimates: usize) -> Self {
        Self {
            t_s: Vec::with_capacity(estimates),
            position_m: Vec::with_capacity(3 * estimates),
            quaternion_xyzw: Vec::with_capacity(4 * estimates),
            velocity_mps: Vec::with_capacity(3 * estimates),
            angular_velocity_radps: Vec::with_capacity(3 * estimates),
            covariance: Vec::with_capacity(144 * estimates),
            status: Vec::with_capacity(estimates),
            residual_px: Vec::with_capacity(estimates),
            conditioning: Vec::with_capacity(estimates),
        }
    }

    fn push(&mut self, e: &RustEstimate) {
        self.t_s.push(e.t_ref_s);
        self.position_m
            .extend_from_slice(e.state.cam_t_obj_m.as_slice());
        self.quaternion_xyzw.extend_from_slice(&quaternion_xyzw(e));
        self.velocity_mps
            .extend_from_slice(e.state.velocity_mps.as_slice());
        self.angular_velocity_radps
            .extend_from_slice(e.state.angular_velocity_radps.as_slice());
        self.covariance.extend_from_slice(&covariance_entries(e));
        self.status.push(e.status.name());
        self.residual_px.push(e.residual_rms_px);
        self.conditioning.push(e.inverse_condition);
    }

    fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let m = self.t_s.len();
        let dict = PyDict::new(py);
        dict.set_item("t_s", self.t_s.into_pyarray(py))?;
        dict.set_item(
            "position_m",
            self.position_m.into_pyarray(py).reshape([m, 3])?,
        )?;
        dict.set_item(
            "quaternion_xyzw",
            self.quaternion_xyzw.into_pyarray(py).reshape([m, 4])?,
        )?;
        dict.set_item(
            "velocity_mps",
            self.velocity_mps.into_pyarray(py).reshape([m, 3])?,
        )?;
        dict.set_item(
            "angular_velocity_radps",
            self.angular_velocity_radps
                .into_pyarray(py)
                .reshape([m, 3])?,
        )?;
        let covariance: Bound<'_, PyArray3<f64>> =
            self.covariance.into_pyarray(py).reshape([m, 12, 12])?;
        dict.set_item("covariance", covariance)?;
        let numpy = py.import("numpy")?;
        let status = numpy.call_method1("array", (PyList::new(py, self.status)?, "U10"))?;
        dict.set_item("status", status)?;
        dict.set_item("residual_px", self.residual_px.into_pyarray(py))?;
        dict.set_item("conditioning", self.conditioning.into_pyarray(py))?;
        Ok(dict)
    }
}

/// The rows of an (N, 4) float64 array t, id, u, v as measurements; an id that is not a non-negative integer raises
/// ValueError naming its row.
fn measurements_of(argument: &Bound<'_, PyAny>) -> PyResult<Vec<Measurement>> {
    let (n, _, values) = f64_rows(argument, "measurements", Some(4))?;
    (0..n)
        .map(|k| {
            let row = &values[4 * k..4 * k + 4];
            let id = row[1];
            if !(id >= 0.0 && id <= f64::from(u32::MAX) && id.fract() == 0.0) {
                return Err(PyValueError::new_err(format!(
                    "measurements: row {k}, column 1 (id): {id} is not a point id (an integer from 0 to {})",
                    u32::MAX
                )));
            }
            Ok(Measurement {
                t_s: row[0],
                id: id as u32,
                u_px: row[2],
                v_px: row[3],
            })
        })
        .collect()
}

/// `track()` once its options are read: the measurements tracked with the GIL released, as columns.
fn track_with<'py>(
    py: Python<'py>,
    camera: &Camera,
    target: &Target_,
    measurements: &Bound<'py, PyAny>,
    options: &TrackerOptions,
) -> PyResult<Bound<'py, PyDict>> {
    let every = options.every;
    let measurements = measurements_of(measurements)?;
    let mut tracker = new_tracker(camera, target, options)?;
    // An estimate every `every` measurements, and one per readout at most: room for them all.
    let expected = measurements.len() / every.max(1) + 1;
    let (columns, report) = py.detach(move || {
        let mut columns = EstimateColumns::with_capacity(expected);
        let report = roitrack::track(
            &mut tracker,
            measurements
                .into_iter()
                .map(Ok::<_, std::convert::Infallible>),
            |e: &RustEstimate| {
                columns.push(e);
                Ok::<_, std::convert::Infallible>(())
            },
        );
        (columns, report)
    });
    let report = report.map_err(|e| RoitrackError::new_err(format!("tracking failed: {e}")))?;
    if report.estimates.total() == 0 {
        return Err(RoitrackError::new_err(format!(
            "no estimate from {} measurements: {}",
            report.measurements,
            report.why_no_start()
        )));
    }
    columns.into_dict(py)
}

/// The target in a photograph: `image` is an (H, W) uint8 or uint16 array of the camera's size; `polarity` auto,
/// bright or dark; `distance_m` an optional (near, far) range in metres. Returns a dict: ok (bool), error (str, when
/// not ok), polarity, ambiguous, ids (K,) uint32, uv_px (K, 2) raw pixels, position_m (3,), quaternion_xyzw (4,),
/// residual_rms_px, missing, blobs (as `roitrack detect --json`). Releases the GIL while detecting.
#[pyfunction]
#[pyo3(signature = (camera, target, image, polarity = "auto", distance_m = None))]
fn detect<'py>(
    py: Python<'py>,
    camera: PyRef<'py, Camera>,
    target: PyRef<'py, Target_>,
    image: &Bound<'py, PyAny>,
    polarity: &str,
    distance_m: Option<(f64, f64)>,
) -> PyResult<Bound<'py, PyDict>> {
    let polarity = match polarity {
        "auto" => PolarityChoice::Auto,
        "bright" => PolarityChoice::Bright,
        "dark" => PolarityChoice::Dark,
        other => {
            return Err(PyValueError::new_err(format!(
                "polarity: unknown value '{other}' (expected one of auto, bright, dark)"
            )));
        }
    };
    if let Some((near, far)) = distance_m
        && !(near > 0.0 && far >= near && far.is_finite())
    {
        return Err(PyValueError::new_err(format!(
            "distance_m: want (near, far) with 0 < near <= far, got ({near}, {far})"
        )));
    }
    let array = image.cast::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!(
            "image: expected a numpy array of uint8 or uint16, got {}",
            image
                .get_type()
                .name()
                .map_or("?".into(), |n| n.to_string())
        ))
    })?;
    if array.ndim() != 2 {
        return Err(PyValueError::new_err(format!(
            "image: expected an array of shape (H, W), got shape {:?}",
            array.shape()
        )));
    }
    let (height, width) = (array.shape()[0], array.shape()[1]);
    let (bit_depth, pixels): (u8, Vec<u16>) = if let Ok(a) = array.cast::<PyArray2<u8>>() {
        (
            8,
            a.readonly().as_array().iter().map(|&p| p.into()).collect(),
        )
    } else if let Ok(a) = array.cast::<PyArray2<u16>>() {
        (16, a.readonly().as_array().iter().copied().collect())
    } else {
        return Err(PyTypeError::new_err(format!(
            "image: expected dtype uint8 or uint16, got {}",
            array.dtype()
        )));
    };
    let frame = Frame {
        t_s: 0.0,
        width: width as u32,
        height: height as u32,
        bit_depth,
        pixels,
    };
    let options = PhotoOptions {
        polarity,
        distance_range_m: distance_m,
        ..PhotoOptions::default()
    };
    let (camera, target) = (&camera.inner, &target.inner);
    let outcome = py.detach(|| roitrack::detect::detect_target(camera, target, &frame, &options));
    let dict = PyDict::new(py);
    match outcome {
        Ok(found) => {
            let q = found.cam_q_obj();
            dict.set_item("ok", true)?;
            dict.set_item("polarity", found.polarity.name())?;
            dict.set_item("ambiguous", found.ambiguous)?;
            let ids: Vec<u32> = found.points.iter().map(|p| p.id).collect();
            let uv: Vec<f64> = found
                .points
                .iter()
                .flat_map(|p| [p.centre_px.x, p.centre_px.y])
                .collect();
            dict.set_item("ids", ids.into_pyarray(py))?;
            dict.set_item(
                "uv_px",
                uv.into_pyarray(py).reshape([found.points.len(), 2])?,
            )?;
            dict.set_item(
                "position_m",
                PyArray1::from_slice(py, found.state.cam_t_obj_m.as_slice()),
            )?;
            dict.set_item(
                "quaternion_xyzw",
                PyArray1::from_slice(py, &[q.i, q.j, q.k, q.w]),
            )?;
            dict.set_item("residual_rms_px", found.reprojection_rms_px)?;
            dict.set_item("missing", found.missing)?;
            dict.set_item("blobs", found.blobs.len())?;
        }
        Err(e @ PhotoError::ImageSize { .. }) => {
            return Err(PyValueError::new_err(format!("image: {e}")));
        }
        Err(e) => {
            dict.set_item("ok", false)?;
            dict.set_item("error", e.to_string())?;
            dict.set_item("polarity", py.None())?;
            dict.set_item("ambiguous", false)?;
            dict.set_item("ids", PyArray1::<u32>::zeros(py, [0], false))?;
            dict.set_item("uv_px", PyArray2::<f64>::zeros(py, [0, 2], false))?;
            dict.set_item("position_m", PyArray1::from_slice(py, &[f64::NAN; 3]))?;
            dict.set_item("quaternion_xyzw", PyArray1::from_slice(py, &[f64::NAN; 4]))?;
            dict.set_item("residual_rms_px", f64::NAN)?;
            dict.set_item("missing", 0)?;
            dict.set_item("blobs", 0)?;
        }
    }
    Ok(dict)
}

/// Simulates a scenario one ROI at a time, as `roitrack simulate`: `scenario` static, orthoglide, spin, random or
/// sweep; the camera and target default to the scenario's. `order` bitrev, rowmajor or random; `drop` and `outliers`
/// fractions. Returns a dict: measurements (N, 4) float64 rows t, id, u, v; the ground truth at every ROI time gt_t_s
/// (T,), gt_position_m (T, 3), gt_quaternion_xyzw (T, 4), gt_velocity_mps (T, 3), gt_angular_velocity_radps (T, 3);
/// camera and target. Releases the GIL while simulating.
#[pyfunction]
#[pyo3(signature = (scenario, seed = 1, camera = None, target = None, noise_px = 0.1, rate_hz = 4000.0,
    order = "bitrev", drop = 0.0, outliers = 0.0))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    scenario: &str,
    seed: u64,
    camera: Option<PyRef<'py, Camera>>,
    target: Option<PyRef<'py, Target_>>,
    noise_px: f64,
    rate_hz: f64,
    order: &str,
    drop: f64,
    outliers: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let kind = ScenarioKind::from_name(scenario).ok_or_else(|| {
        PyValueError::new_err(format!(
            "scenario: unknown value '{scenario}' (expected one of static, orthoglide, spin, random, sweep)"
        ))
    })?;
    let order = match order {
        "bitrev" => roitrack::core::RoiOrder::BitReversed,
        "rowmajor" => roitrack::core::RoiOrder::RowMajor,
        "random" => roitrack::core::RoiOrder::Random,
        other => {
            return Err(PyValueError::new_err(format!(
                "order: unknown value '{other}' (expected one of bitrev, rowmajor, random)"
            )));
        }
    };
    let mut plan = Scenario::new(kind, seed);
    if let Some(camera) = camera {
        plan = plan.with_camera(camera.inner.clone());
    }
    if let Some(target) = target {
        plan = plan.with_target(target.inner.clone());
    }
    let options = SimulationOptions {
        seed,
        noise_px,
        rate_hz,
        order,
        drop_fraction: drop,
        outlier_fraction: outliers,
        ..SimulationOptions::default()
    };
    let run = py
        .detach(|| roitrack::sim::simulate(&plan, &options))
        .map_err(|e| RoitrackError::new_err(format!("simulation failed: {e}")))?;
    let dict = PyDict::new(py);
    let n = run.measurements.len();
    let rows: Vec<f64> = run
        .measurements
        .iter()
        .flat_map(|m| [m.t_s, f64::from(m.id), m.u_px, m.v_px])
        .collect();
    dict.set_item("measurements", rows.into_pyarray(py).reshape([n, 4])?)?;
    let t = run.truth_poses.len();
    let poses = &run.truth_poses;
    let twists = &run.truth_twists;
    let gt_t: Vec<f64> = poses.iter().map(|p| p.t_s).collect();
    let gt_p: Vec<f64> = poses
        .iter()
        .flat_map(|p| {
            let v = p.cam_from_obj.translation.vector;
            [v.x, v.y, v.z]
        })
        .collect();
    let gt_q: Vec<f64> = poses
        .iter()
        .flat_map(|p| {
            let q = p.cam_from_obj.rotation;
            [q.i, q.j, q.k, q.w]
        })
        .collect();
    let gt_v: Vec<f64> = twists
        .iter()
        .flat_map(|s| [s.velocity_mps.x, s.velocity_mps.y, s.velocity_mps.z])
        .collect();
    let gt_w: Vec<f64> = twists
        .iter()
        .flat_map(|s| {
            let w = s.angular_velocity_radps;
            [w.x, w.y, w.z]
        })
        .collect();
    dict.set_item("gt_t_s", gt_t.into_pyarray(py))?;
    dict.set_item("gt_position_m", gt_p.into_pyarray(py).reshape([t, 3])?)?;
    dict.set_item("gt_quaternion_xyzw", gt_q.into_pyarray(py).reshape([t, 4])?)?;
    dict.set_item(
        "gt_velocity_mps",
        gt_v.into_pyarray(py).reshape([twists.len(), 3])?,
    )?;
    dict.set_item(
        "gt_angular_velocity_radps",
        gt_w.into_pyarray(py).reshape([twists.len(), 3])?,
    )?;
    dict.set_item("camera", Camera { inner: run.camera })?;
    dict.set_item("target", Target_ { inner: run.target })?;
    Ok(dict)
}

/// A dict's entry `key` (KeyError naming the dict and key when missing).
fn entry<'py>(dict: &Bound<'py, PyDict>, name: &str, key: &str) -> PyResult<Bound<'py, PyAny>> {
    dict.get_item(key)?.ok_or_else(|| {
        pyo3::exceptions::PyKeyError::new_err(format!("{name}: missing key '{key}'"))
    })
}

/// Poses (and twists, when the dict has them) from a dict's `{prefix}t_s`, `{prefix}position_m`,
/// `{prefix}quaternion_xyzw`, `{prefix}velocity_mps`, `{prefix}angular_velocity_radps`.
fn samples_from(
    dict: &Bound<'_, PyDict>,
    name: &str,
    prefix: &str,
) -> PyResult<(Vec<PoseSample>, Option<Vec<TwistSample>>)> {
    let key = |k: &str| format!("{prefix}{k}");
    let label = |k: &str| format!("{name}['{prefix}{k}']");
    let t = entry(dict, name, &key("t_s"))?;
    let (n, _, t) = {
        let t = f64_rows(
            &t.py()
                .import("numpy")?
                .call_method1("reshape", (t, (-1, 1)))?,
            &label("t_s"),
            Some(1),
        )?;
        (t.0, t.1, t.2)
    };
    let rows = |k: &str, cols: usize| -> PyResult<Vec<f64>> {
        let (rows, _, values) = f64_rows(&entry(dict, name, &key(k))?, &label(k), Some(cols))?;
        if rows != n {
            return Err(PyValueError::new_err(format!(
                "{}: expected {n} rows (as {}), got {rows}",
                label(k),
                label("t_s")
            )));
        }
        Ok(values)
    };
    let p = rows("position_m", 3)?;
    let q = rows("quaternion_xyzw", 4)?;
    let poses = (0..n)
        .map(|k| PoseSample {
            t_s: t[k],
            cam_from_obj: Isometry3::from_parts(
                Translation3::new(p[3 * k], p[3 * k + 1], p[3 * k + 2]),
                UnitQuaternion::from_quaternion(Quaternion::new(
                    q[4 * k + 3],
                    q[4 * k],
                    q[4 * k + 1],
                    q[4 * k + 2],
                )),
            ),
        })
        .collect();
    let twists =
        if dict.contains(key("velocity_mps"))? && dict.contains(key("angular_velocity_radps"))? {
            let v = rows("velocity_mps", 3)?;
            let w = rows("angular_velocity_radps", 3)?;
            Some(
                (0..n)
                    .map(|k| TwistSample {
                        t_s: t[k],
                        velocity_mps: Vector3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2]),
                        angular_velocity_radps: Vector3::new(w[3 * k], w[3 * k + 1], w[3 * k + 2]),
                    })
                    .collect(),
            )
        } else {
            None
        };
    Ok((poses, twists))
}

/// Scores tracked estimates against a simulation's ground truth, as `roitrack eval --json`: `sim` is simulate()'s
/// dict (gt_t_s, gt_position_m, gt_quaternion_xyzw and, for the velocity figures, gt_velocity_mps and
/// gt_angular_velocity_radps), `res` track()'s (t_s, position_m, quaternion_xyzw, velocity_mps,
/// angular_velocity_radps). Returns the metrics dict with the keys of `roitrack eval --json` (count, duration_s,
/// estimator_period_ms, position_rmse_mm, position_rmse_xyz_mm, max_position_error_mm, rotation_rmse_deg,
/// velocity_rmse_mm_s, velocity_rmse_xyz_mm_s, angular_velocity_rmse_deg_s, velocity_lag_samples,
/// velocity_lag_subsample, velocity_lag_ms; None where there are no twists).
#[pyfunction]
fn evaluate<'py>(
    py: Python<'py>,
    sim: &Bound<'py, PyDict>,
    res: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyAny>> {
    let (truth_poses, truth_twists) = samples_from(sim, "sim", "gt_")?;
    let (poses, twists) = samples_from(res, "res", "")?;
    // As `roitrack eval`: velocity figures when both sides have twists.
    let (truth_twists, twists) = match (truth_twists, twists) {
        (Some(a), Some(b)) => (Some(a), Some(b)),
        _ => (None, None),
    };
    let metrics = roitrack::eval::evaluate(
        &truth_poses,
        truth_twists.as_deref(),
        &poses,
        twists.as_deref(),
        &roitrack::eval::EvalOptions::default(),
    )
    .map_err(|e| library_error(&e))?;
    py.import("json")?
        .call_method1("loads", (metrics.to_json(),))
}

/// The Rust figure of `roitrack lab bench --json`'s `track_library_meas_per_s`, measured in this process (best of
/// `runs`): for bench/python_bench.py, which compares it with `track()` from Python in the same run. Only in a wheel
/// built with the feature `lab`.
#[cfg(feature = "lab")]
#[pyfunction]
#[pyo3(signature = (runs = 5))]
fn _bench_track_library(py: Python<'_>, runs: usize) -> PyResult<f64> {
    let bench = roitrack::bench::track_bench::TrackLibraryBench::orthoglide()
        .map_err(|e| library_error(&e))?;
    Ok(py.detach(|| bench.measure(runs).meas_per_s))
}

/// High-rate 3-D pose and velocity tracking of a rigid target from timestamped blob centroids.
#[pymodule]
fn _roitrack(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Camera>()?;
    m.add_class::<Target_>()?;
    m.add_class::<Tracker>()?;
    m.add_class::<Estimate>()?;
    m.add_function(wrap_pyfunction!(track, m)?)?;
    m.add_function(wrap_pyfunction!(detect, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(_tracker_options, m)?)?;
    #[cfg(feature = "lab")]
    m.add_function(wrap_pyfunction!(_bench_track_library, m)?)?;
    m.add("RoitrackError", m.py().get_type::<RoitrackError>())?;
    Ok(())
}
