//! Aravis' fake GigE Vision camera, started in this process on 127.0.0.1 (or another loopback address), serving images
//! of a simulated target.
//!
//! The fake camera speaks the real protocol (GVCP registers, GVSP packets) on the loopback interface; roitrack only
//! replaces its test pattern: at each buffer it renders the scenario's target ([`RoiRenderer`]) in the window its
//! registers say (`OffsetX`, `OffsetY`, `Width`, `Height`), in its pixel format (Mono8 or Mono16, the two its
//! GenICam description offers), at the scene time the host set ([`SceneClock`]), and stamps the buffer with its
//! device clock: a real clock, started [`FAKE_DEVICE_CLOCK_START_S`] before the camera, so that the host estimates
//! its offset as with a real camera. The scene time of each buffer is recorded under its timestamp. Only one fake
//! camera can own an address's GVCP port at a time: a rig's second fake camera listens on another loopback address
//! ([`FakeGigeCamera::start_rendering_at`]).

use std::collections::VecDeque;
use std::ffi::c_void;
use std::sync::atomic::{AtomicPtr, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use aravis::GvFakeCamera;
use aravis::glib::translate::ToGlibPtr;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::Roi;
use roitrack_sim::{RenderScratch, RoiRenderer, Scenario, SensorModel};

use crate::GenicamError;

/// The address of the fake camera.
///
/// ```
/// assert_eq!(roitrack_genicam::FAKE_ADDRESS, "127.0.0.1");
/// ```
pub const FAKE_ADDRESS: &str = "127.0.0.1";

/// The fake camera's scene time (s, the scenario's): the host sets it to each ROI's time before triggering the ROI,
/// and the fake camera renders the scenario at that time; it records the scene time of each buffer under the
/// buffer's device timestamp, for the host to read back ([`SceneClock::scene_time_of`]).
///
/// ```
/// let clock = roitrack_genicam::SceneClock::default();
/// clock.set(1.25);
/// assert_eq!(clock.get(), 1.25);
/// clock.record(5_000, 1.25);
/// assert_eq!((clock.scene_time_of(5_000), clock.scene_time_of(5_001)), (Some(1.25), None));
/// ```
#[derive(Debug, Default)]
pub struct SceneClock {
    t_s: AtomicU64,
    /// (device timestamp (ns), scene time (s)) of the latest buffers rendered.
    rendered: Mutex<VecDeque<(u64, f64)>>,
}

/// Buffers whose scene time is kept: far more than the stream's buffers in flight.
const RENDERED_KEPT: usize = 256;

impl SceneClock {
    /// Sets the scene time (s) the fake camera renders its next frame at.
    pub fn set(&self, t_s: f64) {
        self.t_s.store(t_s.to_bits(), Ordering::SeqCst);
    }

    /// The scene time (s) last set (0 before any).
    pub fn get(&self) -> f64 {
        f64::from_bits(self.t_s.load(Ordering::SeqCst))
    }

    /// Records that the buffer stamped `device_ns` shows the scene at `t_s`.
    pub fn record(&self, device_ns: u64, t_s: f64) {
        if let Ok(mut rendered) = self.rendered.lock() {
            if rendered.len() >= RENDERED_KEPT {
                rendered.pop_front();
            }
            rendered.push_back((device_ns, t_s));
        }
    }

    /// The scene time of the buffer stamped `device_ns`, if it is among the latest rendered.
    pub fn scene_time_of(&self, device_ns: u64) -> Option<f64> {
        let rendered = self.rendered.lock().ok()?;
        rendered
            .iter()
            .rev()
            .find(|(ns, _)| *ns == device_ns)
            .map(|&(_, t_s)| t_s)
    }
}

/// The fake camera's fastest free run (Hz): its `AcquisitionFramePeriod` is at least 1 ms.
///
/// ```
/// assert_eq!(1.0 / roitrack_genicam::FAKE_MAX_FRAME_RATE_HZ, 1e-3);
/// ```
pub const FAKE_MAX_FRAME_RATE_HZ: f64 = 1000.0;

/// Where the fake camera's device clock starts (s): as if it had been powered on that long before the run, so that
/// the offset between its clock and the host's is not zero.
///
/// ```
/// assert_eq!(roitrack_genicam::FAKE_DEVICE_CLOCK_START_S, 1000.0);
/// ```
pub const FAKE_DEVICE_CLOCK_START_S: f64 = 1000.0;

/// The target's motion a fake camera renders: its state (camera frame) at each scene time.
type Truth = Box<dyn Fn(f64) -> MotionState + Send + Sync>;

/// What the fake camera's thread renders from.
struct Scene {
    renderer: RoiRenderer,
    truth: Truth,
    clock: Arc<SceneClock>,
    /// Noise generator, rendering scratch and a pixel buffer, used by the fake camera's thread only.
    state: Mutex<(ChaCha8Rng, RenderScratch, Vec<u16>)>,
    rendered: AtomicUsize,
    refused: AtomicUsize,
    /// The device clock: nanoseconds since `origin`, plus [`FAKE_DEVICE_CLOCK_START_S`]; `last_ns` keeps the
    /// timestamps strictly increasing (they key the scene times).
    origin: Instant,
    last_ns: AtomicU64,
    /// The fake camera itself, for its payload size (set once it is created; it outlives the fill callback).
    fake: AtomicPtr<aravis_sys::ArvFakeCamera>,
}

impl Scene {
    /// The device clock now (ns), later than every timestamp given before.
    fn device_now_ns(&self) -> u64 {
        let now =
            (FAKE_DEVICE_CLOCK_START_S * 1e9) as u64 + self.origin.elapsed().as_nanos() as u64;
        let previous = self.last_ns.fetch_max(now, Ordering::SeqCst);
        if previous >= now {
            self.last_ns.fetch_add(1, Ordering::SeqCst) + 1
        } else {
            now
        }
    }
}

/// The fill callback of the fake camera: renders the scene into the buffer, on the fake camera's thread.
unsafe extern "C" fn fill_scene(
    buffer: *mut aravis_sys::ArvBuffer,
    data: *mut c_void,
    _exposure_time_us: u32,
    _gain: u32,
    pixel_format: aravis_sys::ArvPixelFormat,
) {
    if buffer.is_null() || data.is_null() {
        return;
    }
    // SAFETY: `data` is the `Scene` that FakeGigeCamera keeps alive until it has removed this callback.
    let scene = unsafe { &*(data as *const Scene) };
    // The exposure begins: the device clock's time, and the scene's.
    let device_ns = scene.device_now_ns();
    let t_s = scene.clock.get();
    let (mut x, mut y, mut w, mut h) = (0, 0, 0, 0);
    let fake = scene.fake.load(Ordering::SeqCst);
    if fake.is_null() {
        return;
    }
    // SAFETY: the buffer is the fake camera's, valid during this call; so is the fake camera, which calls this.
    let (pixels, payload) = unsafe {
        aravis_sys::arv_buffer_get_image_region(buffer, &mut x, &mut y, &mut w, &mut h);
        (
            aravis_sys::arv_buffer_get_data(buffer, std::ptr::null_mut()),
            aravis_sys::arv_fake_camera_get_payload(fake),
        )
    };
    let bytes = match pixel_format {
        aravis_sys::ARV_PIXEL_FORMAT_MONO_8 => 1,
        aravis_sys::ARV_PIXEL_FORMAT_MONO_16 => 2,
        _ => 0,
    };
    let camera = scene.renderer.camera();
    let fits = x >= 0 && y >= 0 && w > 0 && h > 0;
    let roi = Roi::new(
        x.max(0) as u32,
        y.max(0) as u32,
        w.max(0) as u32,
        h.max(0) as u32,
    );
    let n = roi.len();
    // The fake camera calls this only with a buffer of at least its payload (it marks a smaller one SIZE_MISMATCH
    // and returns before), and sends that payload: the image must fit in it (some Aravis releases size the payload
    // as one byte a pixel whatever the format).
    if bytes == 0
        || !fits
        || !roi.fits_in(camera.width_px, camera.height_px)
        || pixels.is_null()
        || payload < n * bytes
    {
        scene.refused.fetch_add(1, Ordering::Relaxed);
        return;
    }
    let Ok(mut state) = scene.state.lock() else {
        return;
    };
    let (rng, scratch, out) = &mut *state;
    out.resize(n, 0);
    let truth = |t: f64| (scene.truth)(t);
    scene
        .renderer
        .render_readout(&truth, &roi, t_s, rng, scratch, out);
    // SAFETY: the buffer holds at least `payload >= n * bytes` bytes at `pixels`.
    let target = unsafe { std::slice::from_raw_parts_mut(pixels, n * bytes) };
    let depth = scene.renderer.sensor().bit_depth;
    if bytes == 1 {
        let shift = depth.saturating_sub(8);
        for (t, &v) in target.iter_mut().zip(out.iter()) {
            *t = (v >> shift).min(255) as u8;
        }
    } else {
        // Mono16: the sensor's values scaled to 16 bits (most significant bits first, as cameras with a 10- or
        // 12-bit converter do), little-endian.
        let shift = 16u32.saturating_sub(depth);
        for (t, &v) in target.chunks_exact_mut(2).zip(out.iter()) {
            let value = (u32::from(v) << shift).min(u32::from(u16::MAX)) as u16;
            t.copy_from_slice(&value.to_le_bytes());
        }
    }
    // SAFETY: as above.
    unsafe { aravis_sys::arv_buffer_set_timestamp(buffer, device_ns) };
    scene.clock.record(device_ns, t_s);
    scene.rendered.fetch_add(1, Ordering::Relaxed);
}

/// Aravis' fake GigE Vision camera on 127.0.0.1, serving the rendered scenario.
///
/// ```no_run
/// use roitrack_genicam::FakeGigeCamera;
/// use roitrack_sim::{Scenario, ScenarioKind};
/// let fake = FakeGigeCamera::start(&Scenario::new(ScenarioKind::Orthoglide, 1), Default::default(), 1).unwrap();
/// assert_eq!(fake.address(), "127.0.0.1");
/// ```
pub struct FakeGigeCamera {
    gv: Mutex<Option<GvFakeCamera>>,
    scene: Arc<Scene>,
    serial: String,
    address: String,
}

// SAFETY: the GObject is reference counted atomically and the fake camera serialises its own work on its thread;
// this handle only starts it and, under its mutex, stops it.
unsafe impl Send for FakeGigeCamera {}
unsafe impl Sync for FakeGigeCamera {}

impl FakeGigeCamera {
    /// Starts the fake camera on 127.0.0.1, rendering `scenario` with `sensor` (served as Mono8, the sensor's values
    /// shifted down to 8 bits, or Mono16, scaled up to 16 bits), noise
    /// seeded with `seed`. Refused if 127.0.0.1's GVCP port is taken (another fake camera).
    pub fn start(
        scenario: &Scenario,
        sensor: SensorModel,
        seed: u64,
    ) -> Result<Self, GenicamError> {
        let motion = scenario.clone();
        Self::start_rendering(
            &scenario.camera,
            &scenario.target,
            move |t_s| motion.state_at(t_s),
            sensor,
            seed,
        )
    }

    /// Starts the fake camera on 127.0.0.1 rendering `target` seen by `camera` at the state `truth` gives for each
    /// buffer's scene time (the time the host set, [`SceneClock`]): a motion computed as the run goes, such as a
    /// simulated robot's (`roitrack servo --live --fake`). `truth` is called on the fake camera's thread, a few
    /// times per buffer (the exposure's motion blur): it must be quick and must not block. Otherwise as
    /// [`Self::start`].
    ///
    /// ```no_run
    /// use roitrack_core::{CameraModel, MotionState, Target};
    /// use roitrack_genicam::FakeGigeCamera;
    /// let still = MotionState::at_rest(Default::default(), [0.0, 0.0, 0.6].into());
    /// let fake = FakeGigeCamera::start_rendering(&CameraModel::canonical(), &Target::grid4x4(), move |_t| still,
    ///     Default::default(), 1).unwrap();
    /// assert_eq!(fake.address(), "127.0.0.1");
    /// ```
    pub fn start_rendering(
        camera: &CameraModel,
        target: &Target,
        truth: impl Fn(f64) -> MotionState + Send + Sync + 'static,
        sensor: SensorModel,
        seed: u64,
    ) -> Result<Self, GenicamError> {
        Self::start_rendering_at(FAKE_ADDRESS, camera, target, truth, sensor, seed)
    }

    /// As [`Self::start_rendering`], on `address`, an IPv4 address of one of this host's interfaces (Aravis binds
    /// the camera's GVCP port there): a second fake camera needs an address of its own, such as 127.0.0.2 added to
    /// the loopback (`ip addr add 127.0.0.2/8 dev lo`, as root, in a network namespace of its own in the tests).
    /// Refused if no interface has the address or its GVCP port is taken.
    ///
    /// ```no_run
    /// use roitrack_core::{CameraModel, MotionState, Target};
    /// use roitrack_genicam::FakeGigeCamera;
    /// let still = MotionState::at_rest(Default::default(), [0.0, 0.0, 0.6].into());
    /// let fake = FakeGigeCamera::start_rendering_at("127.0.0.2", &CameraModel::canonical(), &Target::grid4x4(),
    ///     move |_t| still, Default::default(), 2).unwrap();
    /// assert_eq!(fake.address(), "127.0.0.2");
    /// ```
    pub fn start_rendering_at(
        address: &str,
        camera: &CameraModel,
        target: &Target,
        truth: impl Fn(f64) -> MotionState + Send + Sync + 'static,
        sensor: SensorModel,
        seed: u64,
    ) -> Result<Self, GenicamError> {
        let renderer = RoiRenderer::new(camera.clone(), target.clone(), sensor)
            .map_err(|e| GenicamError::Fake(e.to_string()))?;
        let scene = Arc::new(Scene {
            renderer,
            truth: Box::new(truth),
            clock: Arc::new(SceneClock::default()),
            state: Mutex::new((
                ChaCha8Rng::seed_from_u64(seed),
                RenderScratch::new(),
                Vec::new(),
            )),
            rendered: AtomicUsize::new(0),
            refused: AtomicUsize::new(0),
            origin: Instant::now(),
            last_ns: AtomicU64::new(0),
            fake: AtomicPtr::new(std::ptr::null_mut()),
        });
        // Unique per camera (a GigE Vision serial number holds at most 16 characters).
        let serial = if address == FAKE_ADDRESS {
            format!("ROITRACK-{}", std::process::id())
        } else {
            let host = address.rsplit('.').next().unwrap_or(address);
            format!("RT-{}-{host}", std::process::id() % 10_000_000)
        };
        let gv = GvFakeCamera::new(Some(address), Some(&serial));
        if !gv.is_running() {
            return Err(GenicamError::Fake(format!(
                "cannot listen on {address}'s GVCP port (3956): another fake camera is running there, or no \
                 interface has that address{}",
                if address == FAKE_ADDRESS {
                    ""
                } else {
                    " (a loopback address other than 127.0.0.1 must be added to lo first: `ip addr add \
                     ADDRESS/8 dev lo`)"
                }
            )));
        }
        let fake = gv
            .fake_camera()
            .ok_or_else(|| GenicamError::Fake("no fake camera inside the GigE one".into()))?;
        // Triggered frames wait for the fake camera's next frame slot: make the slots short.
        fake.set_trigger_frequency(20_000.0);
        // SAFETY: the scene outlives the callback: `stop` removes the callback before the scene can be dropped.
        unsafe {
            let raw: *mut aravis_sys::ArvFakeCamera = fake.to_glib_none().0;
            scene.fake.store(raw, Ordering::SeqCst);
            aravis_sys::arv_fake_camera_set_fill_pattern(
                raw,
                Some(fill_scene),
                Arc::as_ptr(&scene) as *mut c_void,
            );
        }
        Ok(Self {
            gv: Mutex::new(Some(gv)),
            scene,
            serial,
            address: address.to_string(),
        })
    }

    /// The address to open it at ([`FAKE_ADDRESS`] unless started elsewhere).
    pub fn address(&self) -> &str {
        &self.address
    }

    /// The serial number it was started with (check it when opening the camera: [`crate::GenicamOptions`]).
    pub fn serial(&self) -> &str {
        &self.serial
    }

    /// Its clock: set it to each ROI's time before triggering it ([`crate::GenicamCamera::with_scene_clock`]).
    pub fn clock(&self) -> Arc<SceneClock> {
        self.scene.clock.clone()
    }

    /// Its device clock's reading (s) at a host instant: what it would stamp a buffer begun then with. The host's
    /// clock and the fake camera's are the same clock, so the true offset between them is known (a real camera's is
    /// only estimated).
    ///
    /// ```no_run
    /// use roitrack_genicam::{FAKE_DEVICE_CLOCK_START_S, FakeGigeCamera};
    /// use roitrack_sim::{Scenario, ScenarioKind};
    /// let fake = FakeGigeCamera::start(&Scenario::new(ScenarioKind::Orthoglide, 1), Default::default(), 1).unwrap();
    /// assert!(fake.device_time_at_s(std::time::Instant::now()) > FAKE_DEVICE_CLOCK_START_S);
    /// ```
    pub fn device_time_at_s(&self, instant: Instant) -> f64 {
        let since_origin_s = if instant >= self.scene.origin {
            instant.duration_since(self.scene.origin).as_secs_f64()
        } else {
            -self.scene.origin.duration_since(instant).as_secs_f64()
        };
        FAKE_DEVICE_CLOCK_START_S + since_origin_s
    }

    /// Buffers rendered, and buffers it could not render (a window off the camera model, an unknown format).
    pub fn rendered(&self) -> (usize, usize) {
        (
            self.scene.rendered.load(Ordering::Relaxed),
            self.scene.refused.load(Ordering::Relaxed),
        )
    }

    /// Whether the camera still serves.
    pub fn is_running(&self) -> bool {
        self.gv.lock().map(|gv| gv.is_some()).unwrap_or(false)
    }

    /// Stops the camera: it no longer answers, as an unplugged one.
    pub fn stop(&self) {
        let Ok(mut gv) = self.gv.lock() else {
            return;
        };
        if let Some(gv) = gv.take() {
            if let Some(fake) = gv.fake_camera() {
                // SAFETY: the default pattern again, so that the scene is no longer referenced.
                unsafe {
                    let raw: *mut aravis_sys::ArvFakeCamera = fake.to_glib_none().0;
                    aravis_sys::arv_fake_camera_set_fill_pattern(raw, None, std::ptr::null_mut());
                }
            }
            drop(gv);
        }
    }
}

impl Drop for FakeGigeCamera {
    fn drop(&mut self) {
        self.stop();
    }
}
