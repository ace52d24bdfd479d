//! A live GenICam ROI camera for roitrack's real-time loop: GigE Vision and USB3 Vision cameras driven through Aravis
//! (feature `genicam`, off by default: it needs Debian's `libaravis-dev`), and Aravis' fake GigE Vision camera,
//! started in-process on 127.0.0.1, rendering a simulated target at the ROI and time of each buffer.
//!
//! - [`GenicamCamera`] implements [`roitrack_image::RoiCamera`]: it opens one camera by its IP address (an id, which
//!   Aravis finds by a discovery broadcast, only when allowed), in Mono8, Mono12, Mono16, Mono12Packed or Mono12p,
//!   reads a fixed-size window whose `OffsetX`/`OffsetY` it moves onto each ROI the scheduler asks for (on the
//!   camera's increments), by software trigger or free run, and converts each buffer's device timestamp to the
//!   loop's clock. Incomplete and lost buffers are counted and the grab is retried; a camera that
//!   stops answering ends the run with [`roitrack_image::GrabError::Disconnected`], the estimates so far kept.
//! - [`FakeGigeCamera`] is Aravis' fake camera whose images are the scenario's target rendered by
//!   [`roitrack_sim::RoiRenderer`] at the scene time the host sets, stamped by a device clock of its own.
//! - [`run_live`] runs the two-thread loop on such a camera and reports what the camera did ([`LiveReport`]);
//!   [`run_rig_live`] runs a rig of them, one acquisition thread per camera and one fused track ([`run_fake_rig`]:
//!   a fake camera per camera of a simulated rig, each on a loopback address of its own).
//! - [`ClockOffset`] (always built) estimates the offset between a device's clock and the host's.
//!
//! Never enumerate devices: Aravis' discovery broadcasts on every network interface. Only `roitrack cameras --scan`
//! ([`scan`]) does, when asked.
#![deny(missing_docs)]
// The links above name the items of the feature `genicam`: without it they have nothing to point to.
#![cfg_attr(not(feature = "genicam"), allow(rustdoc::broken_intra_doc_links))]

mod clock;

pub use clock::ClockOffset;

#[cfg(feature = "genicam")]
mod camera;
#[cfg(feature = "genicam")]
mod fake;
#[cfg(feature = "genicam")]
mod live;
#[cfg(feature = "genicam")]
mod rig;

#[cfg(feature = "genicam")]
pub use camera::{
    CameraStats, GenicamCamera, GenicamError, GenicamOptions, PixelFormatChoice, TriggerChoice,
    scan,
};
#[cfg(feature = "genicam")]
pub use fake::{
    FAKE_ADDRESS, FAKE_DEVICE_CLOCK_START_S, FAKE_MAX_FRAME_RATE_HZ, FakeGigeCamera, SceneClock,
};
#[cfg(feature = "genicam")]
pub use live::{
    LiveOptions, LiveReport, run_device, run_fake, run_live, timestamp_to_estimate_us,
    truth_samples,
};
#[cfg(feature = "genicam")]
pub use rig::{MAX_FAKE_RIG_CAMERAS, RigLiveReport, run_device_rig, run_fake_rig, run_rig_live};
