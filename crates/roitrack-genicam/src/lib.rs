//! A live GenICam ROI camera for roitrack's real-time loop: GigE Vision and USB3 Vision cameras driven through Aravis
//! (feature `genicam`, off by default: it needs Debian's `libaravis-dev`), and Aravis' fake GigE Vision camera,
//! started in-process on 127.0.0.1, rendering a simulated target at the ROI and time of each buffer.
//!
//! - [`GenicamCamera`] implements [`roitrack_image::RoiCamera`]: it opens one camera by its address or id (never by
//!   scanning the network), reads a fixed-size window whose `OffsetX`/`OffsetY` it moves onto each ROI the scheduler
//!   asks for (on the camera's increments), by software trigger or free run, and converts each buffer's device
//!   timestamp to the loop's clock. Incomplete and lost buffers are counted and the grab is retried; a camera that
//!   stops answering ends the run with [`roitrack_image::GrabError::Disconnected`], the estimates so far kept.
//! - [`FakeGigeCamera`] is Aravis' fake camera whose images are the scenario's target rendered by
//!   [`roitrack_image::RoiRenderer`]; its clock is the scenario's time.
//! - [`run_live`] runs the two-thread loop on such a camera and reports what the camera did ([`LiveReport`]).
//! - [`ClockOffset`] (always built) estimates the offset between a device's clock and the host's.
//!
//! Never enumerate devices: Aravis' discovery broadcasts on every network interface. Only `roitrack cameras --scan`
//! ([`scan`]) does, when asked.

mod clock;

pub use clock::ClockOffset;

#[cfg(feature = "genicam")]
mod camera;
#[cfg(feature = "genicam")]
mod fake;
#[cfg(feature = "genicam")]
mod live;

#[cfg(feature = "genicam")]
pub use camera::{
    CameraStats, GenicamCamera, GenicamError, GenicamOptions, PixelFormatChoice, TriggerChoice,
    scan,
};
#[cfg(feature = "genicam")]
pub use fake::{FAKE_ADDRESS, FakeGigeCamera, SceneClock};
#[cfg(feature = "genicam")]
pub use live::{LiveOptions, LiveReport, run_device, run_fake, run_live, truth_samples};
