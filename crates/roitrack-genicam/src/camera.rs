//! A GenICam camera (GigE Vision or USB3 Vision, through Aravis) as a [`RoiCamera`].
//!
//! Changing a GenICam camera's `Width`/`Height` needs acquisition stopped and restarted (far longer than a frame:
//! docs/cameras.md, "The ROI: a window moved between frames"), but `OffsetX`/`OffsetY` can move between two frames: the
//! camera reads a window of fixed size ([`GenicamOptions::roi_size_px`]) and moves it onto each ROI the scheduler asks
//! for. The full frame of an initialisation is the one place where the size changes.

use std::net::{IpAddr, Ipv4Addr, SocketAddrV4, UdpSocket};
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

/// The pixel formats roitrack reads: one grey value a pixel, 8 bits, or 12 or 16 bits in a 16-bit little-endian
/// container, or 12 bits packed two pixels in three bytes (`Mono12Packed`, GigE Vision's layout, and `Mono12p`, the
/// PFNC layout of USB3 Vision and newer GigE cameras).
///
/// ```
/// use roitrack_genicam::PixelFormatChoice;
/// assert_eq!(PixelFormatChoice::Mono12.bit_depth(), 12);
/// assert_eq!(PixelFormatChoice::Mono12Packed.payload_bytes(32 * 32), 1536);
/// assert_eq!(PixelFormatChoice::from_genicam_name("Mono16"), Some(PixelFormatChoice::Mono16));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormatChoice {
    /// 8 bits a pixel, one byte each.
    Mono8,
    /// 12 bits a pixel in a 16-bit little-endian container.
    Mono12,
    /// 16 bits a pixel, little-endian.
    Mono16,
    /// 12 bits a pixel, two pixels in three bytes, GigE Vision's layout: each pixel's 8 high bits in a byte of its
    /// own, their low 4 bits together in the middle byte.
    Mono12Packed,
    /// 12 bits a pixel, two pixels in three bytes, PFNC's layout (USB3 Vision, newer GigE cameras): least
    /// significant bits first.
    Mono12p,
}

/// PFNC's `Mono12p` (Aravis 0.8 has no constant for it).
const PIXEL_FORMAT_MONO_12_P: u32 = 0x010C_0047;

impl PixelFormatChoice {
    /// Every format roitrack reads, in the order of preference when none is asked for.
    pub const ALL: [Self; 5] = [
        Self::Mono8,
        Self::Mono12,
        Self::Mono16,
        Self::Mono12Packed,
        Self::Mono12p,
    ];

    /// The value the camera's `PixelFormat` feature takes (and buffers report).
    fn pfnc(self) -> u32 {
        match self {
            Self::Mono8 => PixelFormat::MONO_8.raw(),
            Self::Mono12 => PixelFormat::MONO_12.raw(),
            Self::Mono16 => PixelFormat::MONO_16.raw(),
            Self::Mono12Packed => PixelFormat::MONO_12_PACKED.raw(),
            Self::Mono12p => PIXEL_FORMAT_MONO_12_P,
        }
    }

    /// The name of the entry of the GenICam `PixelFormat` enumeration.
    pub fn genicam_name(self) -> &'static str {
        match self {
            Self::Mono8 => "Mono8",
            Self::Mono12 => "Mono12",
            Self::Mono16 => "Mono16",
            Self::Mono12Packed => "Mono12Packed",
            Self::Mono12p => "Mono12p",
        }
    }

    /// The format of a GenICam `PixelFormat` entry, if roitrack reads it.
    pub fn from_genicam_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.genicam_name() == name)
    }

    /// Bits of a pixel value.
    pub fn bit_depth(self) -> u8 {
        match self {
            Self::Mono8 => 8,
            Self::Mono16 => 16,
            Self::Mono12 | Self::Mono12Packed | Self::Mono12p => 12,
        }
    }

    /// Bytes of an image of `pixels` pixels.
    pub fn payload_bytes(self, pixels: usize) -> usize {
        match self {
            Self::Mono8 => pixels,
            Self::Mono12 | Self::Mono16 => 2 * pixels,
            Self::Mono12Packed | Self::Mono12p => (3 * pixels).div_ceil(2),
        }
    }

    /// The pixel values of `raw` (at least [`Self::payload_bytes`] of `out.len()`) into `out`, row-major.
    ///
    /// ```
    /// use roitrack_genicam::PixelFormatChoice;
    /// // Two 12-bit pixels 0xABC and 0x123: GigE Vision's Mono12Packed keeps each pixel's 8 high bits in a byte of
    /// // its own and their low 4 bits together in the middle byte; PFNC's Mono12p packs them least significant first.
    /// let mut out = [0u16; 2];
    /// PixelFormatChoice::Mono12Packed.unpack(&[0xAB, 0x3C, 0x12], &mut out);
    /// assert_eq!(out, [0xABC, 0x123]);
    /// PixelFormatChoice::Mono12p.unpack(&[0xBC, 0x3A, 0x12], &mut out);
    /// assert_eq!(out, [0xABC, 0x123]);
    /// ```
    pub fn unpack(self, raw: &[u8], out: &mut [u16]) {
        match self {
            Self::Mono8 => {
                for (o, &v) in out.iter_mut().zip(raw) {
                    *o = u16::from(v);
                }
            }
            Self::Mono12 | Self::Mono16 => {
                let max = ((1u32 << self.bit_depth()) - 1) as u16;
                for (o, pair) in out.iter_mut().zip(raw.chunks_exact(2)) {
                    *o = u16::from_le_bytes([pair[0], pair[1]]).min(max);
                }
            }
            Self::Mono12Packed | Self::Mono12p => {
                for (pair, bytes) in out.chunks_mut(2).zip(raw.chunks(3)) {
                    let b = |i: usize| u16::from(bytes.get(i).copied().unwrap_or(0));
                    let (first, second) = if self == Self::Mono12Packed {
                        ((b(0) << 4) | (b(1) & 0x0F), (b(2) << 4) | (b(1) >> 4))
                    } else {
                        (b(0) | ((b(1) & 0x0F) << 8), (b(1) >> 4) | (b(2) << 4))
                    };
                    pair[0] = first;
                    if let Some(p) = pair.get_mut(1) {
                        *p = second;
                    }
                }
            }
        }
    }
}

impl std::fmt::Display for PixelFormatChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.genicam_name())
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
///     pixel_format: Some(PixelFormatChoice::Mono12),
///     exposure_us: Some(100.0),
///     ..GenicamOptions::default()
/// };
/// assert_eq!((options.roi_size_px, options.timeout_s), (32, 0.2));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct GenicamOptions {
    /// The camera: its IPv4 address (GigE Vision, optionally with the GVCP port `:3956`), opened directly, with no
    /// discovery. Anything else (an Aravis id `Vendor-Model-Serial`, a USB3 Vision camera) is refused unless
    /// [`Self::allow_discovery`]: Aravis finds such a camera by a discovery that broadcasts on every network interface.
    pub address: String,
    /// Let Aravis search for a camera given by its id (a GigE Vision discovery broadcast on every interface, then the
    /// USB bus). Off by default.
    pub allow_discovery: bool,
    /// Refuse a camera whose serial number is not this one (the fake camera's check that it opened its own).
    pub expected_serial: Option<String>,
    /// The pixel format; `None`: Mono8 if the camera offers it, else the first of [`PixelFormatChoice::ALL`] it
    /// offers. One the camera does not offer is refused, with the list of those it does.
    pub pixel_format: Option<PixelFormatChoice>,
    /// Side of the square window every ROI is read through (px), rounded up to the camera's width and height
    /// increments.
    pub roi_size_px: u32,
    /// `ExposureTime` (µs); `None` keeps the camera's.
    pub exposure_us: Option<f64>,
    /// How each ROI is started: software trigger (the default) or free run.
    pub trigger: TriggerChoice,
    /// Free run: the frame rate asked for (`AcquisitionFrameRate`, Hz), if the camera has it.
    pub frame_rate_hz: Option<f64>,
    /// How long a ROI may take (s) before its grab counts as lost.
    pub timeout_s: f64,
    /// After this many lost grabs in a row (and no answer to a register read), the camera is taken as gone.
    pub disconnect_after: u32,
    /// GigE: the stream socket's receive buffer (bytes; the kernel caps it at `net.core.rmem_max`). A full frame
    /// arrives as one burst of packets: too small a buffer loses packets.
    pub socket_buffer_bytes: usize,
    /// GigE: ask the camera to send lost packets again (Aravis' packet resend).
    pub packet_resend: bool,
}

impl Default for GenicamOptions {
    fn default() -> Self {
        Self {
            address: String::new(),
            allow_discovery: false,
            expected_serial: None,
            pixel_format: None,
            roi_size_px: 32,
            exposure_us: None,
            trigger: TriggerChoice::Software,
            frame_rate_hz: None,
            timeout_s: 0.2,
            disconnect_after: 5,
            socket_buffer_bytes: 8 << 20,
            packet_resend: true,
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
    /// The camera could not be opened (no answer, refused address, no stream).
    #[error("cannot open the camera at '{address}': {reason}")]
    Open {
        /// The address or id the camera was asked for by.
        address: String,
        /// What Aravis (or roitrack's own check) said.
        reason: String,
    },
    /// A GenICam feature could not be read or set (missing, out of range, not writable).
    #[error("camera '{address}': {feature}: {reason}")]
    Feature {
        /// The camera's address or id.
        address: String,
        /// The GenICam feature's name (`PixelFormat`, `OffsetX`, ...).
        feature: &'static str,
        /// What went wrong with it.
        reason: String,
    },
    /// The camera that answered is not the one [`GenicamOptions::expected_serial`] names.
    #[error(
        "camera '{address}' has serial number '{found}', not '{expected}' (another camera at that address?)"
    )]
    Serial {
        /// The camera's address.
        address: String,
        /// The serial number the camera reported.
        found: String,
        /// The serial number asked for.
        expected: String,
    },
    /// Aravis' fake GigE Vision camera could not be started.
    #[error("the fake camera: {0}")]
    Fake(String),
    /// The real-time loop run on the camera failed.
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
    /// Times the window was moved (its `OffsetX`/`OffsetY` written).
    pub moves: u64,
    /// Moves the camera refused (the offsets not written).
    pub refused_moves: u64,
    /// Full frames read.
    pub full_frames: u64,
    /// Per ROI: host time from the start of the grab (move, trigger) to the buffer in hand (µs).
    pub grab_us: Vec<f64>,
    /// Per ROI: its time on the loop's clock (s, what the estimates' `t_ref_s` refer to) and the host time from its
    /// buffer's timestamp (the device time on the host's clock, through the clock offset's estimate) to the grab's
    /// return (µs). With the loop's grab-to-estimate latency, the latency from buffer timestamp to estimate
    /// ([`crate::LiveReport::timestamp_to_estimate_us`]).
    pub timestamp_to_grab_us: Vec<(f64, f64)>,
    /// The fake camera: ROIs it exposed at another scene time than the ROI's slot (free run: a frame begun before
    /// the slot's time was set), each placed at its own time.
    pub retimed: u64,
    /// Aravis' stream: buffers it dropped because none was free to receive them (its `underruns`), whether or not
    /// roitrack was waiting for them.
    pub driver_underruns: u64,
    /// Aravis' stream: buffers it gave up on (its `failures`: missing packets, timeouts), whether or not roitrack
    /// was waiting for them.
    pub driver_failures: u64,
    /// `device - host` clock offset (s): the estimate at the end of the run; `None` before any buffer.
    pub clock_offset_s: Option<f64>,
    /// How far the `device - host` clock offset's estimate moved since the first block of buffers (s): the clocks'
    /// drift over the run, plus any change of the smallest arrival latency.
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
    pixel_format: PixelFormatChoice,
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

/// GigE Vision's control port (GVCP, UDP).
const GVCP_PORT: u16 = 3956;

/// What an address given by the user is.
#[derive(Debug, Clone, PartialEq)]
enum CameraAddress {
    /// An IPv4 address (optionally with `:3956`): opened directly.
    Gige(Ipv4Addr),
    /// Not an address (an Aravis id): only Aravis' search finds it.
    Id,
    /// An address that cannot be a camera's, and why.
    Invalid(String),
}

fn parse_address(text: &str) -> CameraAddress {
    let ip = match (text.parse::<Ipv4Addr>(), text.parse::<SocketAddrV4>()) {
        (Ok(ip), _) => ip,
        (_, Ok(socket)) if socket.port() == GVCP_PORT => *socket.ip(),
        (_, Ok(socket)) => {
            return CameraAddress::Invalid(format!(
                "GigE Vision cameras answer on UDP port {GVCP_PORT}, not {}: give the IP address alone",
                socket.port()
            ));
        }
        _ => return CameraAddress::Id,
    };
    if ip.is_unspecified() || ip.is_broadcast() || ip.is_multicast() {
        return CameraAddress::Invalid(format!(
            "{ip} is not one camera's address (unspecified, broadcast or multicast)"
        ));
    }
    CameraAddress::Gige(ip)
}

/// Opens the camera of `options.address`: a GigE Vision camera at an IPv4 address through a device made for that
/// address (Aravis 0.8's `arv_camera_new` sends a register read out of every interface to locate the address, and
/// falls back to a discovery broadcast when nothing answers); an id only with [`GenicamOptions::allow_discovery`].
fn open_camera(options: &GenicamOptions) -> Result<Camera, GenicamError> {
    let address = options.address.trim();
    let open_error = |reason: String| GenicamError::Open {
        address: address.to_string(),
        reason,
    };
    match parse_address(address) {
        CameraAddress::Gige(ip) => {
            // The interface that routes to the camera: the kernel's choice for a socket connected to it (a UDP
            // connect sends nothing).
            let interface = UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))
                .and_then(|socket| {
                    socket.connect((ip, GVCP_PORT))?;
                    socket.local_addr()
                })
                .map_err(|e| open_error(format!("no route from this host ({e})")))?;
            let device = aravis::GvDevice::new(
                &gio::InetAddress::from(interface.ip()),
                &gio::InetAddress::from(IpAddr::V4(ip)),
            )
            .map_err(|e| {
                open_error(format!(
                    "no GigE Vision camera answers there (UDP {GVCP_PORT}, from {}): {e}",
                    interface.ip()
                ))
            })?;
            Camera::with_device(&device).map_err(|e| open_error(e.to_string()))
        }
        CameraAddress::Invalid(reason) => Err(open_error(reason)),
        CameraAddress::Id if address.is_empty() => Err(open_error(
            "no address given (roitrack never scans the network for a camera)".into(),
        )),
        CameraAddress::Id if !options.allow_discovery => Err(open_error(
            "not an IPv4 address: Aravis would look for a camera of that id by a discovery broadcast on every network \
             interface (and a USB enumeration), which roitrack does only when asked. Give the camera's IP address, \
             or allow the search (`--allow-discovery`; USB3 Vision cameras need it; `roitrack cameras --scan` lists \
             the ids and addresses)"
                .into(),
        )),
        CameraAddress::Id => Camera::new(Some(address)).map_err(|e| open_error(e.to_string())),
    }
}

/// The pixel format to use: the one asked for if the camera offers it, else (none asked) Mono8 or the first of
/// [`PixelFormatChoice::ALL`] it offers.
fn choose_pixel_format(
    asked: Option<PixelFormatChoice>,
    offered: &[String],
) -> Result<PixelFormatChoice, String> {
    let offers = |f: PixelFormatChoice| offered.iter().any(|o| o == f.genicam_name());
    let read: Vec<&str> = PixelFormatChoice::ALL
        .iter()
        .map(|f| f.genicam_name())
        .collect();
    match asked {
        Some(f) if offers(f) => Ok(f),
        Some(f) => Err(format!(
            "{f} is not offered; the camera offers {} (roitrack reads {})",
            offered.join(", "),
            read.join(", ")
        )),
        None => PixelFormatChoice::ALL
            .into_iter()
            .find(|&f| offers(f))
            .ok_or_else(|| {
                format!(
                    "the camera offers {}, none of which roitrack reads ({})",
                    offered.join(", "),
                    read.join(", ")
                )
            }),
    }
}

impl GenicamCamera {
    /// Opens the camera at `options.address` (no scan), checks its serial number if asked, and sets it up: pixel
    /// format, exposure, trigger, a window of `roi_size_px` at the sensor's origin, a stream without Aravis' packet
    /// socket (which delivers frames in batches), and buffers large enough for a `full_size` frame.
    pub fn open(options: &GenicamOptions, full_size: (u32, u32)) -> Result<Self, GenicamError> {
        let address = options.address.as_str();
        let camera = open_camera(options)?;
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
        let offered: Vec<String> = camera
            .dup_available_pixel_formats_as_strings()
            .map_err(|e| feature_error(address, "PixelFormat", e))?
            .iter()
            .map(|f| f.to_string())
            .collect();
        let pixel_format = choose_pixel_format(options.pixel_format, &offered)
            .map_err(|e| feature_error(address, "PixelFormat", e))?;
        camera
            .set_pixel_format_from_string(pixel_format.genicam_name())
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
            gv_stream.set_socket_buffer_size(
                i32::try_from(options.socket_buffer_bytes).unwrap_or(i32::MAX),
            );
            if !options.packet_resend {
                gv_stream.set_packet_resend(aravis::GvStreamPacketResend::Never);
            }
        }
        let payload_full =
            pixel_format.payload_bytes(full_size.0 as usize * full_size.1 as usize) + 4096;
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
            pixel_format,
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
            pixel_format,
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

    /// The host instant of the first grab and its time on the loop's clock: the loop's clock is that time plus the
    /// host time since (s); `None` before a grab.
    pub fn host_epoch(&self) -> Option<(Instant, f64)> {
        self.epoch
    }

    /// The pixel format in use.
    pub fn pixel_format(&self) -> PixelFormatChoice {
        self.pixel_format
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
        let (_completed, failures, underruns) = self.stream.statistics();
        stats.driver_failures = failures;
        stats.driver_underruns = underruns;
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

    /// The buffer's pixels into `out` (row-major, `w * h` values); the buffer's time on the loop's clock, and on
    /// the host's (s).
    ///
    /// A real camera's device timestamp goes to the host's clock through the estimated offset, and that is the
    /// loop's time. The fake camera's clock is a real clock too (the offset is estimated the same way), but the
    /// scene it rendered is the scenario at the time the host set: that scene time, which the fake camera recorded
    /// under the buffer's timestamp, is the loop's time.
    fn read_pixels(
        &mut self,
        buffer: &Buffer,
        t_s: f64,
        out: &mut [u16],
    ) -> Result<(f64, f64), GrabError> {
        let format = buffer.image_pixel_format().raw();
        if format != self.pixel_format.pfnc() {
            return Err(GrabError::Dropped {
                reason: format!(
                    "a buffer in pixel format {format:#010x}, not {} ({:#010x})",
                    self.pixel_format,
                    self.pixel_format.pfnc()
                ),
            });
        }
        let (data, size) = buffer.data();
        let bytes = self.pixel_format.payload_bytes(out.len());
        if data.is_null() || size < bytes {
            return Err(GrabError::Dropped {
                reason: format!(
                    "a buffer of {size} bytes for {} pixels of {}",
                    out.len(),
                    self.pixel_format
                ),
            });
        }
        // SAFETY: Aravis owns `size` bytes at `data` while we hold the popped buffer.
        let raw = unsafe { std::slice::from_raw_parts(data as *const u8, bytes) };
        self.pixel_format.unpack(raw, out);
        let device_ns = buffer.timestamp();
        let device_s = device_ns as f64 * 1e-9;
        let host_s = self.host_now_s(t_s);
        self.clock.update(device_s, host_s);
        let buffer_host_s = self.clock.to_host_s(device_s).unwrap_or(host_s);
        let loop_s = match &self.scene_clock {
            Some(scene) => scene
                .scene_time_of(device_ns)
                .ok_or_else(|| GrabError::Dropped {
                    reason: format!(
                        "the fake camera has no scene time for the buffer stamped {device_ns} ns"
                    ),
                })?,
            None => buffer_host_s,
        };
        Ok((loop_s, buffer_host_s))
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
        // The region the buffer reports (the one asked for: the others were skipped), at the time it reports.
        let (x, y, w, h) = buffer.image_region();
        let region = Roi::new(x as u32, y as u32, w as u32, h as u32);
        image.set(
            trigger.t_s,
            trigger.point_id,
            region,
            self.pixel_format.bit_depth(),
        );
        let read = self.read_pixels(&buffer, trigger.t_s, &mut image.pixels);
        self.stream.push_buffer(buffer);
        let (loop_s, buffer_host_s) = read?;
        image.t_s = loop_s;
        if self.scene_clock.is_some() && loop_s != trigger.t_s {
            self.stats.retimed += 1;
        }
        let returned_host_s = self.host_now_s(trigger.t_s);
        self.stats.rois += 1;
        self.stats.grab_us.push(start.elapsed().as_secs_f64() * 1e6);
        self.stats
            .timestamp_to_grab_us
            .push((loop_s, (returned_host_s - buffer_host_s) * 1e6));
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
            frame.resize(w, h, self.pixel_format.bit_depth());
            let read = self.read_pixels(&buffer, t_s, &mut frame.pixels);
            self.stream.push_buffer(buffer);
            frame.t_s = read?.0;
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
    fn only_an_ipv4_address_is_opened_directly() {
        let ip = |text: &str| CameraAddress::Gige(text.parse().unwrap());
        assert_eq!(parse_address("192.168.1.20"), ip("192.168.1.20"));
        assert_eq!(parse_address("192.168.1.20:3956"), ip("192.168.1.20"));
        for id in [
            "Aravis-Fake-GV01",
            "camera.local",
            "fe80::1",
            "192.168.1",
            "",
        ] {
            assert_eq!(parse_address(id), CameraAddress::Id, "{id}");
        }
        for bad in ["192.168.1.20:80", "255.255.255.255", "0.0.0.0", "239.1.2.3"] {
            assert!(
                matches!(parse_address(bad), CameraAddress::Invalid(_)),
                "{bad}"
            );
        }
    }

    #[test]
    fn the_pixel_format_is_the_one_asked_if_offered_else_mono8_first() {
        let offered = |names: &[&str]| names.iter().map(|n| n.to_string()).collect::<Vec<_>>();
        let fake = offered(&["BayerBG8", "Mono8", "RGB8", "Mono16"]);
        use PixelFormatChoice::*;
        assert_eq!(choose_pixel_format(None, &fake), Ok(Mono8));
        assert_eq!(choose_pixel_format(Some(Mono16), &fake), Ok(Mono16));
        let refused = choose_pixel_format(Some(Mono12p), &fake).unwrap_err();
        assert!(
            refused.starts_with(
                "Mono12p is not offered; the camera offers BayerBG8, Mono8, RGB8, Mono16"
            ),
            "{refused}"
        );
        let packed_only = offered(&["Mono12Packed", "BayerRG12Packed"]);
        assert_eq!(choose_pixel_format(None, &packed_only), Ok(Mono12Packed));
        assert!(choose_pixel_format(None, &offered(&["RGB8"])).is_err());
    }

    #[test]
    fn twelve_bit_pixels_unpack_and_sixteen_bit_containers_are_clamped_to_their_depth() {
        // Three pixels of Mono12Packed (the last pair half used): 0x123, 0xFFF, 0x800.
        let mut out = [0u16; 3];
        PixelFormatChoice::Mono12Packed.unpack(&[0x12, 0xF3, 0xFF, 0x80, 0x00], &mut out);
        assert_eq!(out, [0x123, 0xFFF, 0x800]);
        PixelFormatChoice::Mono12p.unpack(&[0x23, 0xF1, 0xFF, 0x00, 0x08], &mut out);
        assert_eq!(out, [0x123, 0xFFF, 0x800]);
        assert_eq!(PixelFormatChoice::Mono12p.payload_bytes(3), 5);
        // Mono12 in a 16-bit container: a value above 12 bits is clamped, not wrapped.
        let mut two = [0u16; 2];
        PixelFormatChoice::Mono12.unpack(&[0xFF, 0x0F, 0x00, 0xF0], &mut two);
        assert_eq!(two, [0x0FFF, 0x0FFF]);
        PixelFormatChoice::Mono16.unpack(&[0x34, 0x12, 0xFF, 0xFF], &mut two);
        assert_eq!(two, [0x1234, 0xFFFF]);
    }

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
