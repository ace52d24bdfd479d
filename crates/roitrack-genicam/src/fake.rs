//! Aravis' fake GigE Vision camera, started in this process on 127.0.0.1, serving images of a simulated target.
//!
//! The fake camera speaks the real protocol (GVCP registers, GVSP packets) on the loopback interface; roitrack only
//! replaces its test pattern: at each buffer it renders the scenario's target ([`RoiRenderer`]) in the window its
//! registers say (`OffsetX`, `OffsetY`, `Width`, `Height`) at the time its clock says, and stamps the buffer with that
//! time. Its clock is the scenario's: [`SceneClock`], which the host sets to each ROI's time before triggering it.
//! Only one fake camera can own 127.0.0.1's GVCP port at a time.

use std::ffi::c_void;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use aravis::GvFakeCamera;
use aravis::glib::translate::ToGlibPtr;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use roitrack_image::{RenderScratch, Roi, RoiRenderer, SensorModel};
use roitrack_sim::Scenario;

use crate::GenicamError;

/// The address of the fake camera.
///
/// ```
/// assert_eq!(roitrack_genicam::FAKE_ADDRESS, "127.0.0.1");
/// ```
pub const FAKE_ADDRESS: &str = "127.0.0.1";

/// The fake camera's clock (s, the scenario's time): the time of the next buffer it renders.
///
/// ```
/// let clock = roitrack_genicam::SceneClock::default();
/// clock.set(1.25);
/// assert_eq!(clock.get(), 1.25);
/// ```
#[derive(Debug, Default)]
pub struct SceneClock(AtomicU64);

impl SceneClock {
    pub fn set(&self, t_s: f64) {
        self.0.store(t_s.to_bits(), Ordering::SeqCst);
    }

    pub fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::SeqCst))
    }
}

/// What the fake camera's thread renders from.
struct Scene {
    renderer: RoiRenderer,
    scenario: Scenario,
    clock: Arc<SceneClock>,
    /// Noise generator, rendering scratch and a pixel buffer, used by the fake camera's thread only.
    state: Mutex<(ChaCha8Rng, RenderScratch, Vec<u16>)>,
    rendered: AtomicUsize,
    refused: AtomicUsize,
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
    let (mut x, mut y, mut w, mut h) = (0, 0, 0, 0);
    // SAFETY: the buffer is the fake camera's, valid during this call.
    let pixels = unsafe {
        aravis_sys::arv_buffer_get_image_region(buffer, &mut x, &mut y, &mut w, &mut h);
        aravis_sys::arv_buffer_get_data(buffer, std::ptr::null_mut())
    };
    // Mono8 only: some Aravis 0.8 releases size the fake camera's payload as one byte a pixel whatever the format,
    // so a 16-bit image could overrun its buffer.
    let bytes = usize::from(pixel_format == aravis_sys::ARV_PIXEL_FORMAT_MONO_8);
    let camera = scene.renderer.camera();
    let fits = x >= 0 && y >= 0 && w > 0 && h > 0;
    let roi = Roi::new(
        x.max(0) as u32,
        y.max(0) as u32,
        w.max(0) as u32,
        h.max(0) as u32,
    );
    let n = roi.len();
    if bytes == 0 || !fits || !roi.fits_in(camera.width_px, camera.height_px) || pixels.is_null() {
        scene.refused.fetch_add(1, Ordering::Relaxed);
        return;
    }
    let t_s = scene.clock.get();
    let Ok(mut state) = scene.state.lock() else {
        return;
    };
    let (rng, scratch, out) = &mut *state;
    out.resize(n, 0);
    let truth = |t: f64| scene.scenario.state_at(t);
    scene
        .renderer
        .render_readout(&truth, &roi, t_s, rng, scratch, out);
    // SAFETY: the fake camera calls this only with a buffer of at least its payload, `Width * Height` pixels of its
    // pixel format (it marks a smaller one SIZE_MISMATCH and returns before), which is the region read above.
    let target = unsafe { std::slice::from_raw_parts_mut(pixels, n * bytes) };
    let shift = scene.renderer.sensor().bit_depth.saturating_sub(8);
    for (t, &v) in target.iter_mut().zip(out.iter()) {
        *t = (v >> shift).min(255) as u8;
    }
    // The buffer's device timestamp: the scenario's time of its exposure (ns; scenarios start at 0).
    // SAFETY: as above.
    unsafe { aravis_sys::arv_buffer_set_timestamp(buffer, (t_s.max(0.0) * 1e9).round() as u64) };
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
}

// SAFETY: the GObject is reference counted atomically and the fake camera serialises its own work on its thread;
// this handle only starts it and, under its mutex, stops it.
unsafe impl Send for FakeGigeCamera {}
unsafe impl Sync for FakeGigeCamera {}

impl FakeGigeCamera {
    /// Starts the fake camera on 127.0.0.1, rendering `scenario` with `sensor` (served as Mono8, deeper sensors shifted
    /// down to 8 bits), noise
    /// seeded with `seed`. Refused if 127.0.0.1's GVCP port is taken (another fake camera).
    pub fn start(
        scenario: &Scenario,
        sensor: SensorModel,
        seed: u64,
    ) -> Result<Self, GenicamError> {
        let renderer = RoiRenderer::new(scenario.camera.clone(), scenario.target.clone(), sensor)
            .map_err(|e| GenicamError::Fake(e.to_string()))?;
        let scene = Arc::new(Scene {
            renderer,
            scenario: scenario.clone(),
            clock: Arc::new(SceneClock::default()),
            state: Mutex::new((
                ChaCha8Rng::seed_from_u64(seed),
                RenderScratch::new(),
                Vec::new(),
            )),
            rendered: AtomicUsize::new(0),
            refused: AtomicUsize::new(0),
        });
        let serial = format!("ROITRACK-{}", std::process::id());
        let gv = GvFakeCamera::new(Some(FAKE_ADDRESS), Some(&serial));
        if !gv.is_running() {
            return Err(GenicamError::Fake(format!(
                "cannot listen on {FAKE_ADDRESS}'s GVCP port (3956): another fake camera is running?"
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
        })
    }

    pub fn address(&self) -> &str {
        FAKE_ADDRESS
    }

    /// The serial number it was started with (check it when opening the camera: [`crate::GenicamOptions`]).
    pub fn serial(&self) -> &str {
        &self.serial
    }

    /// Its clock: set it to each ROI's time before triggering it ([`crate::GenicamCamera::with_scene_clock`]).
    pub fn clock(&self) -> Arc<SceneClock> {
        self.scene.clock.clone()
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
