//! A GenICam camera (GigE Vision or USB3 Vision, through Aravis) as a [`RoiCamera`].
//!
//! Changing a GenICam camera's `Width`/`Height` needs acquisition stopped and restarted (about 100 ms on Aravis' fake
//! camera), but `OffsetX`/`OffsetY` can move between two frames: the camera reads a window of fixed size
//! ([`GenicamOptions::roi_size_px`]) and moves it onto each ROI the scheduler asks for. The full frame of an
//! initialisation is the one place where the size changes.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use aravis::glib::prelude::Cast;
use aravis::prelude::*;
use aravis::{Buffer, BufferStatus, Camera, GvStreamOption, PixelFormat, Stream};
use roitrack_image::{Frame, GrabError, Roi, RoiCamera, RoiImage, RoiTrigger};
use thiserror::Error;

use crate::ClockOffset;
use crate::fake::SceneClock;

/// The pixel formats roitrack reads (one value a pixel; 12 bits in a 16-bit container, little-endian).
///
/// ```
/// use roitrack_genicam::PixelFormatChoice;
/// assert_eq!(PixelFormatChoice::Mono12.bit_depth(), 12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormatChoice {
    Mono8,
    Mono12,
    Mono16,
}

impl PixelFormatChoice {
    fn aravis(self) -> PixelFormat {
        match self {
            Self::Mono8 => PixelFormat::MONO_8,
            Self::Mono12 => PixelFormat::MONO_12,
            Self::Mono16 => PixelFormat::MONO_16,
        }
    }

    /// Bits of a pixel value.
    pub fn bit_depth(self) -> u8 {
        match self {
            Self::Mono8 => 8,
            Self::Mono12 => 12,
            Self::Mono16 => 16,
        }
    }

    fn bytes(self) -> usize {
        if self == Self::Mono8 { 1 } else { 2 }
    }
}

/// How each ROI is started.
///
/// ```
/// use roitrack_genicam::{GenicamOptions, TriggerChoice};
/// assert_eq!(GenicamOptions::default().trigger, TriggerChoice::Software);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriggerChoice {
    /// `TriggerMode On`, `TriggerSource Software`: one `TriggerSoftware` command a ROI, sent once the window moved.
    Software,
    /// `TriggerMode Off`: the camera streams at its own rate; after each move the frames still read from the old
    /// window are skipped (and counted).
    FreeRun,
}

/// How a camera is opened and driven.
///
/// ```
/// use roitrack_genicam::{GenicamOptions, PixelFormatChoice};
/// let options = GenicamOptions {
///     address: "192.168.1.20".into(),
///     pixel_format: PixelFormatChoice::Mono12,
///     exposure_us: Some(100.0),
///     ..GenicamOptions::default()
/// };
/// assert_eq!((options.roi_size_px, options.timeout_s), (32, 0.2));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct GenicamOptions {
    /// The camera: its IP address (GigE Vision) or its Aravis id (`Vendor-Model-Serial`, USB3 Vision too). Never a
    /// scan of the network.
    pub address: String,
    /// Refuse a camera whose serial number is not this one (the fake camera's check that it opened its own).
    pub expected_serial: Option<String>,
    pub pixel_format: PixelFormatChoice,
    /// Side of the square window every ROI is read through (px), rounded up to the camera's width and height
    /// increments.
    pub roi_size_px: u32,
    /// `ExposureTime` (µs); `None` keeps the camera's.
    pub exposure_us: Option<f64>,
    pub trigger: TriggerChoice,
    /// Free run: the frame rate asked for (`AcquisitionFrameRate`, Hz), if the camera has it.
    pub frame_rate_hz: Option<f64>,
    /// How long a ROI may take (s) before its grab counts as lost.
    pub timeout_s: f64,
    /// After this many lost grabs in a row (and no answer to a register read), the camera is taken as gone.
    pub disconnect_after: u32,
    /// The device's timestamps are already on the loop's clock (the fake camera, whose clock is the scenario's);
    /// otherwise they are converted to the host's clock through the estimated offset ([`ClockOffset`]).
    pub device_clock_is_loop_clock: bool,
}

impl Default for GenicamOptions {
    fn default() -> Self {
        Self {
            address: String::new(),
            expected_serial: None,
            pixel_format: PixelFormatChoice::Mono8,
            roi_size_px: 32,
            exposure_us: None,
            trigger: TriggerChoice::Software,
            frame_rate_hz: None,
            timeout_s: 0.2,
            disconnect_after: 5,
            device_clock_is_loop_clock: false,
        }
    }
}

/// Opening or setting up a camera failed.
///
/// ```
/// use roitrack_genicam::GenicamError;
/// let e = GenicamError::Open { address: "10.0.0.7".into(), reason: "no answer".into() };
/// assert_eq!(e.to_string(), "cannot open the camera at '10.0.0.7': no answer");
/// ```
#[derive(Debug, Error)]
pub enum GenicamError {
    #[error("cannot open the camera at '{address}': {reason}")]
    Open { address: String, reason: String },
    #[error("camera '{address}': {feature}: {reason}")]
    Feature {
        address: String,
        feature: &'static str,
        reason: String,
    },
    #[error(
        "camera '{address}' has serial number '{found}', not '{expected}' (another camera at that address?)"
    )]
    Serial {
        address: String,
        found: String,
        expected: String,
    },
    #[error("the fake camera: {0}")]
    Fake(String),
    #[error("the loop: {0}")]
    Loop(#[from] roitrack_pipeline::PipelineError),
}

/// What the camera did during a run.
///
/// ```
/// use roitrack_genicam::CameraStats;
/// let stats = CameraStats { rois: 95, stale: 5, ..CameraStats::default() };
/// assert_eq!(stats.moved_fraction(), 0.95);
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CameraStats {
    /// ROI buffers received complete and read from the window asked for.
    pub rois: u64,
    /// ROI grabs that gave no image within the timeout.
    pub lost: u64,
    /// Buffers that arrived incomplete (missing packets, size mismatch, ...): skipped.
    pub incomplete: u64,
    /// Complete buffers read from another window than the one asked for (the offset had not moved yet): skipped.
    pub stale: u64,
    /// Times the window was moved, and the moves the camera refused.
    pub moves: u64,
    pub refused_moves: u64,
    /// Full frames read.
    pub full_frames: u64,
    /// Per ROI: host time from the start of the grab (move, trigger) to the buffer in hand (µs).
    pub grab_us: Vec<f64>,
    /// `device - host` clock offset (s): the estimate at the end, and how far it moved during the run.
    pub clock_offset_s: Option<f64>,
    pub clock_change_s: Option<f64>,
    /// Mean and standard deviation of the buffers' arrival latency above the smallest (s).
    pub arrival_jitter_s: Option<(f64, f64)>,
}

impl CameraStats {
    /// The fraction of the complete ROI buffers that came from the window asked for.
    pub fn moved_fraction(&self) -> f64 {
        self.rois as f64 / (self.rois + self.stale).max(1) as f64
    }
}

/// A GenICam camera through Aravis.
///
/// ```no_run
/// use roitrack_genicam::{GenicamCamera, GenicamOptions};
/// let options = GenicamOptions { address: "192.168.1.20".into(), ..GenicamOptions::default() };
/// let camera = GenicamCamera::open(&options, (1024, 1024)).unwrap();
/// println!("{}", camera.description());
/// ```
pub struct GenicamCamera {
    camera: Camera,
    stream: Stream,
    options: GenicamOptions,
    description: String,
    /// The window's size (px) and the offsets' increments and largest values.
    window: (u32, u32),
    increments: (u32, u32),
    /// The frame read at initialisation (the camera model's size).
    full_size: (u32, u32),
    current: Option<(u32, u32)>,
    stats: CameraStats,
    clock: ClockOffset,
    /// Host instant and loop time of the first grab: the loop's clock on the host.
    epoch: Option<(Instant, f64)>,
    scene_clock: Option<Arc<SceneClock>>,
    stop: Option<Arc<AtomicBool>>,
    lost_in_a_row: u32,
}

fn feature_error(address: &str, feature: &'static str, e: impl std::fmt::Display) -> GenicamError {
    GenicamError::Feature {
        address: address.to_string(),
        feature,
        reason: e.to_string(),
    }
}

/// A window of `size` centred on `roi`, its offsets on the nearest multiples of `increments`, within `sensor`.
fn window_on(roi: &Roi, size: (u32, u32), increments: (u32, u32), sensor: (u32, u32)) -> Roi {
    let (w, h) = size;
    let x = i64::from(roi.x0) + i64::from(roi.width / 2) - i64::from(w / 2);
    let y = i64::from(roi.y0) + i64::from(roi.height / 2) - i64::from(h / 2);
    let x0 = snap(x, increments.0, sensor.0.saturating_sub(w));
    let y0 = snap(y, increments.1, sensor.1.saturating_sub(h));
    Roi::new(x0, y0, w, h)
}

/// `value` moved onto the nearest multiple of `increment` and into `[0, max]` (onto a multiple too).
fn snap(value: i64, increment: u32, max: u32) -> u32 {
    let inc = i64::from(increment.max(1));
    let snapped = (value + inc / 2).div_euclid(inc) * inc;
    let max_snapped = i64::from(max).div_euclid(inc) * inc;
    snapped.clamp(0, max_snapped) as u32
}

/// `value` rounded up to a multiple of `increment`.
fn round_up(value: u32, increment: u32) -> u32 {
    let inc = increment.max(1);
    value.div_ceil(inc) * inc
}

impl GenicamCamera {
    /// Opens the camera at `options.address` (no scan), checks its serial number if asked, and sets it up: pixel
    /// format, exposure, trigger, a window of `roi_size_px` at the sensor's origin, a stream without Aravis' packet
    /// socket (which delivers frames in batches), and buffers large enough for a `full_size` frame.
    pub fn open(options: &GenicamOptions, full_size: (u32, u32)) -> Result<Self, GenicamError> {
        let address = options.address.as_str();
        if address.is_empty() {
            return Err(GenicamError::Open {
                address: String::new(),
                reason: "no address or id given (roitrack never scans the network for a camera)"
                    .into(),
            });
        }
        let camera = Camera::new(Some(address)).map_err(|e| GenicamError::Open {
            address: address.to_string(),
            reason: e.to_string(),
        })?;
        let serial = camera
            .device_serial_number()
            .map(|s| s.to_string())
            .unwrap_or_default();
        if let Some(expected) = &options.expected_serial
            && &serial != expected
        {
            return Err(GenicamError::Serial {
                address: address.to_string(),
                found: serial,
                expected: expected.clone(),
            });
        }
        let model = camera
            .model_name()
            .map(|s| s.to_string())
            .unwrap_or_default();
        let vendor = camera
            .vendor_name()
            .map(|s| s.to_string())
            .unwrap_or_default();
        let _ = camera.stop_acquisition();
        camera
            .set_pixel_format(options.pixel_format.aravis())
            .map_err(|e| feature_error(address, "PixelFormat", e))?;
        if let Some(exposure_us) = options.exposure_us {
            camera
                .set_exposure_time(exposure_us)
                .map_err(|e| feature_error(address, "ExposureTime", e))?;
        }
        let (sensor_w, sensor_h) = camera
            .sensor_size()
            .map_err(|e| feature_error(address, "SensorWidth/SensorHeight", e))?;
        if full_size.0 > sensor_w as u32 || full_size.1 > sensor_h as u32 {
            return Err(feature_error(
                address,
                "SensorWidth/SensorHeight",
                format!(
                    "the sensor is {sensor_w} x {sensor_h}, the camera model {} x {}",
                    full_size.0, full_size.1
                ),
            ));
        }
        let width_inc = camera.width_increment().unwrap_or(1).max(1) as u32;
        let height_inc = camera.height_increment().unwrap_or(1).max(1) as u32;
        let x_inc = camera.x_offset_increment().unwrap_or(1).max(1) as u32;
        let y_inc = camera.y_offset_increment().unwrap_or(1).max(1) as u32;
        let window = (
            round_up(options.roi_size_px, width_inc),
            round_up(options.roi_size_px, height_inc),
        );
        camera
            .set_region(0, 0, window.0 as i32, window.1 as i32)
            .map_err(|e| feature_error(address, "Width/Height", e))?;
        match options.trigger {
            TriggerChoice::Software => {
                camera
                    .set_trigger("Software")
                    .map_err(|e| feature_error(address, "TriggerMode/TriggerSource", e))?;
            }
            TriggerChoice::FreeRun => {
                let _ = camera.clear_triggers();
                if let Some(rate) = options.frame_rate_hz {
                    camera
                        .set_frame_rate(rate)
                        .map_err(|e| feature_error(address, "AcquisitionFrameRate", e))?;
                }
            }
        }
        camera
            .set_acquisition_mode(aravis::AcquisitionMode::Continuous)
            .map_err(|e| feature_error(address, "AcquisitionMode", e))?;
        if camera.is_gv_device() {
            camera.gv_set_stream_options(GvStreamOption::PACKET_SOCKET_DISABLED);
        }
        let stream = camera.create_stream().map_err(|e| GenicamError::Open {
            address: address.to_string(),
            reason: format!("no stream: {e}"),
        })?;
        // A full frame arrives as one burst of packets: give the socket room for it (the kernel caps the size at
        // net.core.rmem_max).
        if let Some(gv_stream) = stream.downcast_ref::<aravis::GvStream>() {
            gv_stream.set_socket_buffer(aravis::GvStreamSocketBuffer::Fixed);
            gv_stream.set_socket_buffer_size(8 << 20);
        }
        let payload_full =
            full_size.0 as usize * full_size.1 as usize * options.pixel_format.bytes() + 4096;
        for _ in 0..8 {
            stream.push_buffer(Buffer::new_allocate(payload_full));
        }
        camera
            .start_acquisition()
            .map_err(|e| feature_error(address, "AcquisitionStart", e))?;
        let description = format!(
            "{vendor} {model} (serial {serial}) at {address}: sensor {sensor_w} x {sensor_h}, window {} x {} \
             (increments: width {width_inc}, height {height_inc}, OffsetX {x_inc}, OffsetY {y_inc}), {:?}, {}",
            window.0,
            window.1,
            options.pixel_format,
            match options.trigger {
                TriggerChoice::Software => "software trigger",
                TriggerChoice::FreeRun => "free run",
            }
        );
        Ok(Self {
            camera,
            stream,
            options: options.clone(),
            description,
            window,
            increments: (x_inc, y_inc),
            full_size,
            current: Some((0, 0)),
            stats: CameraStats::default(),
            clock: ClockOffset::new(256),
            epoch: None,
            scene_clock: None,
            stop: None,
            lost_in_a_row: 0,
        })
    }

    /// The fake camera's clock: each ROI's time is told to it before the ROI is triggered, so that it renders the
    /// scenario at that time (see [`crate::FakeGigeCamera`]).
    pub fn with_scene_clock(mut self, clock: Arc<SceneClock>) -> Self {
        self.scene_clock = Some(clock);
        self
    }

    /// A flag that stops the run (Ctrl-C): the next grab ends it with [`GrabError::Stopped`].
    pub fn with_stop_flag(mut self, stop: Arc<AtomicBool>) -> Self {
        self.stop = Some(stop);
        self
    }

    /// Vendor, model, serial number, address, sensor, window, increments, pixel format and trigger.
    pub fn description(&self) -> &str {
        &self.description
    }

    /// Whether the device's timestamps are taken as the loop's times ([`GenicamOptions::device_clock_is_loop_clock`]).
    pub fn device_clock_is_loop_clock(&self) -> bool {
        self.options.device_clock_is_loop_clock
    }

    /// The window every ROI is read through (px).
    pub fn window(&self) -> (u32, u32) {
        self.window
    }

    /// What the camera did so far, with the clock offset's estimate.
    pub fn stats(&self) -> CameraStats {
        let mut stats = self.stats.clone();
        stats.clock_offset_s = self.clock.offset_s();
        stats.clock_change_s = self.clock.change_s();
        stats.arrival_jitter_s = self.clock.jitter_s();
        stats
    }

    fn check_stop(&self) -> Result<(), GrabError> {
        if self.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst)) {
            return Err(GrabError::Stopped {
                reason: "interrupted (Ctrl-C)".into(),
            });
        }
        Ok(())
    }

    fn disconnected(&self, what: impl std::fmt::Display) -> GrabError {
        GrabError::Disconnected {
            reason: format!("camera '{}': {what}", self.options.address),
        }
    }

    /// The loop's time now, on the host (s).
    fn host_now_s(&mut self, t_s: f64) -> f64 {
        let (instant, t0) = *self.epoch.get_or_insert((Instant::now(), t_s));
        t0 + instant.elapsed().as_secs_f64()
    }

    /// The window of the camera's size on `roi`'s centre, on the offsets' increments, within the sensor's part that
    /// the camera model covers.
    pub fn window_for(&self, roi: &Roi) -> Roi {
        window_on(roi, self.window, self.increments, self.full_size)
    }

    fn move_to(&mut self, x0: u32, y0: u32) -> Result<(), GrabError> {
        if self.current == Some((x0, y0)) {
            return Ok(());
        }
        self.stats.moves += 1;
        // A failed write leaves the offset unknown: it is written again next time.
        self.current = None;
        let result = self
            .camera
            .set_integer("OffsetX", i64::from(x0))
            .and_then(|()| self.camera.set_integer("OffsetY", i64::from(y0)));
        match result {
            Ok(()) => {
                self.current = Some((x0, y0));
                Ok(())
            }
            Err(e) => {
                self.stats.refused_moves += 1;
                // A camera that does not answer is gone; one that refuses the value is not.
                if self.camera.integer("OffsetX").is_err() {
                    Err(self.disconnected(format!("no answer ({e})")))
                } else {
                    Err(GrabError::InvalidRoi {
                        roi: Roi::new(x0, y0, self.window.0, self.window.1),
                        reason: e.to_string(),
                    })
                }
            }
        }
    }

    fn trigger(&mut self, t_s: f64) -> Result<(), GrabError> {
        if let Some(clock) = &self.scene_clock {
            clock.set(t_s);
        }
        if self.options.trigger == TriggerChoice::Software
            && let Err(e) = self.camera.software_trigger()
        {
            return Err(self.disconnected(format!("TriggerSoftware: {e}")));
        }
        Ok(())
    }

    /// Waits for the complete buffer from window `want` (x0, y0, width, height); the buffers of other windows and
    /// incomplete ones are counted and given back. `Ok(None)`: nothing within the timeout.
    fn wait_buffer(&mut self, want: (u32, u32, u32, u32), timeout: Duration) -> Option<Buffer> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            let buffer = self.stream.timeout_pop_buffer(left.as_micros() as u64)?;
            if buffer.status() != BufferStatus::Success {
                self.stats.incomplete += 1;
                self.stream.push_buffer(buffer);
                continue;
            }
            let (x, y, w, h) = buffer.image_region();
            if (x as u32, y as u32, w as u32, h as u32) != want {
                self.stats.stale += 1;
                self.stream.push_buffer(buffer);
                continue;
            }
            return Some(buffer);
        }
    }

    fn lost(&mut self) -> GrabError {
        self.stats.lost += 1;
        self.lost_in_a_row += 1;
        if self.lost_in_a_row >= self.options.disconnect_after.max(1) {
            // Many silent grabs in a row: ask the camera a register to tell a gone camera from a slow one.
            if let Err(e) = self.camera.integer("Width") {
                return self.disconnected(format!(
                    "no image for {} grabs in a row and no answer ({e})",
                    self.lost_in_a_row
                ));
            }
            // A camera that answers but sends nothing for ten times as long has lost its stream.
            if self.lost_in_a_row >= 10 * self.options.disconnect_after.max(1) {
                return self.disconnected(format!(
                    "no image for {} grabs in a row although it answers: its stream does not reach this host                      (a firewall on UDP, another interface?)",
                    self.lost_in_a_row
                ));
            }
        }
        GrabError::Timeout {
            timeout_s: self.options.timeout_s,
        }
    }

    /// The buffer's pixels into `out` (row-major, `w * h` values), its time on the loop's clock.
    fn read_pixels(
        &mut self,
        buffer: &Buffer,
        t_s: f64,
        out: &mut [u16],
    ) -> Result<f64, GrabError> {
        let (data, size) = buffer.data();
        let bytes = self.options.pixel_format.bytes();
        if data.is_null() || size < out.len() * bytes {
            return Err(GrabError::Dropped {
                reason: format!("a buffer of {size} bytes for {} pixels", out.len()),
            });
        }
        // SAFETY: Aravis owns `size` bytes at `data` while we hold the popped buffer.
        let raw = unsafe { std::slice::from_raw_parts(data as *const u8, out.len() * bytes) };
        if bytes == 1 {
            for (o, &v) in out.iter_mut().zip(raw) {
                *o = u16::from(v);
            }
        } else {
            let max = (1u32 << self.options.pixel_format.bit_depth()) - 1;
            for (o, pair) in out.iter_mut().zip(raw.chunks_exact(2)) {
                *o = u16::from_le_bytes([pair[0], pair[1]]).min(max as u16);
            }
        }
        let device_s = buffer.timestamp() as f64 * 1e-9;
        let host_s = self.host_now_s(t_s);
        self.clock.update(device_s, host_s);
        Ok(if self.options.device_clock_is_loop_clock {
            device_s
        } else {
            self.clock.to_host_s(device_s).unwrap_or(host_s)
        })
    }

    fn set_full_frame(&mut self, full: bool) -> Result<(), GrabError> {
        let (w, h) = if full { self.full_size } else { self.window };
        let _ = self.camera.stop_acquisition();
        let result = self
            .camera
            .set_region(0, 0, w as i32, h as i32)
            .and_then(|()| self.camera.start_acquisition());
        self.current = Some((0, 0));
        result.map_err(|e| self.disconnected(format!("Width/Height {w} x {h}: {e}")))
    }
}

impl RoiCamera for GenicamCamera {
    fn grab_roi(&mut self, trigger: &RoiTrigger, image: &mut RoiImage) -> Result<(), GrabError> {
        self.check_stop()?;
        let start = Instant::now();
        self.host_now_s(trigger.t_s);
        let window = self.window_for(&trigger.roi);
        self.move_to(window.x0, window.y0)?;
        self.trigger(trigger.t_s)?;
        let timeout = Duration::from_secs_f64(self.options.timeout_s.max(1e-3));
        let want = (window.x0, window.y0, window.width, window.height);
        let Some(buffer) = self.wait_buffer(want, timeout) else {
            return Err(self.lost());
        };
        self.lost_in_a_row = 0;
        image.set(
            trigger.t_s,
            trigger.point_id,
            window,
            self.options.pixel_format.bit_depth(),
        );
        let read = self.read_pixels(&buffer, trigger.t_s, &mut image.pixels);
        self.stream.push_buffer(buffer);
        image.t_s = read?;
        self.stats.rois += 1;
        self.stats.grab_us.push(start.elapsed().as_secs_f64() * 1e6);
        Ok(())
    }

    fn grab_full_frame(&mut self, t_s: f64, frame: &mut Frame) -> Result<(), GrabError> {
        self.check_stop()?;
        self.host_now_s(t_s);
        self.set_full_frame(true)?;
        let (w, h) = self.full_size;
        let result = (|| {
            self.trigger(t_s)?;
            // A full frame is larger and comes after a restart: ten times a ROI's timeout, at least 2 s.
            let timeout = Duration::from_secs_f64((10.0 * self.options.timeout_s).max(2.0));
            let Some(buffer) = self.wait_buffer((0, 0, w, h), timeout) else {
                return Err(self.lost());
            };
            self.lost_in_a_row = 0;
            frame.resize(w, h, self.options.pixel_format.bit_depth());
            let read = self.read_pixels(&buffer, t_s, &mut frame.pixels);
            self.stream.push_buffer(buffer);
            frame.t_s = read?;
            Ok(())
        })();
        let back = self.set_full_frame(false);
        result?;
        back?;
        self.stats.full_frames += 1;
        Ok(())
    }
}

impl Drop for GenicamCamera {
    fn drop(&mut self) {
        let _ = self.camera.stop_acquisition();
    }
}

/// ```no_run
/// for (id, address, protocol) in roitrack_genicam::scan() {
///     println!("{id} {address} {protocol}");
/// }
/// ```
///
/// The cameras Aravis finds on every interface (GigE Vision discovery broadcasts on each network, USB3 Vision
/// enumerates the bus): `roitrack cameras --scan` only, never implicitly. Each line: id, address, protocol.
pub fn scan() -> Vec<(String, String, String)> {
    // SAFETY: Aravis' device list is only read right after it is updated, on this thread.
    let devices = unsafe { aravis::get_device_list() };
    devices
        .into_iter()
        .map(|d| {
            (
                d.id.to_string_lossy().into_owned(),
                d.address.to_string_lossy().into_owned(),
                d.protocol.to_string_lossy().into_owned(),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_snap_onto_the_nearest_increment_within_the_sensor() {
        assert_eq!(snap(37, 4, 1000), 36);
        assert_eq!(snap(39, 4, 1000), 40);
        assert_eq!(snap(-5, 4, 1000), 0);
        assert_eq!(snap(2000, 8, 1001), 1000);
        assert_eq!(round_up(30, 16), 32);
        assert_eq!(round_up(32, 1), 32);
    }

    #[test]
    fn the_window_is_centred_on_the_roi_within_half_an_increment() {
        let sensor = (1024, 1024);
        // A 20 px ROI whose centre is (110, 210): a 32 px window from (94, 194), on increments of 1 and 16.
        let roi = Roi::new(100, 200, 20, 20);
        assert_eq!(
            window_on(&roi, (32, 32), (1, 1), sensor),
            Roi::new(94, 194, 32, 32)
        );
        assert_eq!(
            window_on(&roi, (32, 32), (16, 16), sensor),
            Roi::new(96, 192, 32, 32)
        );
        // Near the edges it stays on the sensor.
        assert_eq!(
            window_on(&Roi::new(0, 0, 12, 12), (32, 32), (4, 4), sensor),
            Roi::new(0, 0, 32, 32)
        );
        let corner = window_on(&Roi::new(1010, 1012, 12, 12), (32, 32), (8, 8), sensor);
        assert_eq!((corner.x0, corner.y0), (992, 992));
        for x0 in 0..1000 {
            let window = window_on(&Roi::new(x0, 500, 16, 16), (32, 32), (8, 2), sensor);
            assert!(
                window.fits_in(1024, 1024)
                    && window.x0.is_multiple_of(8)
                    && window.y0.is_multiple_of(2)
            );
            let centre_error = (i64::from(window.x0) + 16) - (i64::from(x0) + 8);
            assert!(
                centre_error.abs() <= 4 || !(8..=984).contains(&x0),
                "{x0}: {window:?}"
            );
        }
    }
}
