//! One camera's measurements, from a CSV, a ROI recording or replayed from a bag, tracked and written.

use std::path::PathBuf;

use anyhow::{Context, Result};
use roitrack::formats::{
    EstimateWriter, FormatError, MeasurementReader, RoiRecordingReader, TimedMeasurements,
    open_input,
};
use roitrack::image::CentroidOptions;
use roitrack::pipeline::RoiEvent;
use roitrack::{EstimatorReport, Measurement, TrackStatus, Tracker};

use super::TrackArgs;

/// Checked measurements in time order, from a measurements CSV or replayed from a bag: the two differ only in how
/// they are opened.
type MeasurementSource = Box<dyn Iterator<Item = Result<Measurement, FormatError>>>;

/// Where every estimate of a one-camera run goes: paced (--paced), then to the files, the bag, the live view and the
/// DDS bus.
pub(super) struct EstimateSinks {
    pub(super) writer: EstimateWriter,
    pub(super) bag: crate::ros::Bag,
    pacer: Option<roitrack::ros::Pacer>,
}

impl EstimateSinks {
    /// The bag (--mcap, --foxglove; with --rois, room for the ROIs) and the DDS node (--ros2) opened for `camera`
    /// beside `writer`. A node that cannot start fails here, before tracking (and --ros2-wait-s waits here for
    /// subscribers).
    pub(super) fn open(
        args: &TrackArgs,
        camera: &roitrack::CameraModel,
        writer: EstimateWriter,
    ) -> Result<Self> {
        let mut bag = if !args.rois.is_empty() {
            args.ros.open_for_rois(Some(camera), None)?
        } else {
            args.ros.open(Some(camera), None)?
        };
        bag.publish_on_ros2(args.ros2.start(Some(camera), &args.ros.bag_options())?);
        Ok(EstimateSinks {
            writer,
            bag,
            pacer: args.pace.pacer(),
        })
    }

    fn estimate(&mut self, e: &roitrack::Estimate) -> Result<(), FormatError> {
        if let Some(pacer) = &mut self.pacer {
            pacer.wait_until(e.t_ref_s);
        }
        self.writer.write(e).and_then(|()| self.bag.estimate(e))
    }
}

/// The measurements to track and where they come from: replayed from a bag, or read from a CSV; checked either way
/// (known ids, centroids on the camera's image, times in order and, from a CSV, in seconds or converted). `None`
/// without either (a ROI recording instead).
pub(super) fn open_measurements(
    args: &TrackArgs,
    replay: Option<roitrack::ros::BagMeasurementSource>,
    known_ids: &[u32],
    camera: &roitrack::CameraModel,
) -> Result<Option<(PathBuf, MeasurementSource)>> {
    Ok(match (replay, args.measurements.first()) {
        (Some(source), _) => Some((source.bag().to_path_buf(), Box::new(source))),
        (None, Some(path)) => {
            let reader = MeasurementReader::from_reader(open_input(path)?, path)?
                .with_known_ids(known_ids.iter().copied())
                .with_image_size(camera.width_px, camera.height_px);
            let reader = TimedMeasurements::new(reader, args.time_units.map(Into::into));
            Some((path.clone(), Box::new(reader)))
        }
        (None, None) => None,
    })
}

/// Tracks `source`, read from `path`; each measurement also goes to the bag's /roitrack/measurements. A signal
/// stops the run at the next measurement, through the error path (src/signals.rs).
pub(super) fn track_measurements(
    tracker: &mut Tracker,
    path: &std::path::Path,
    source: MeasurementSource,
    sinks: &mut EstimateSinks,
    tick: &dyn Fn(usize),
) -> Result<EstimatorReport> {
    // A RefCell: the estimates' sink writes to the bag too.
    let sinks = std::cell::RefCell::new(sinks);
    let measurements = source.enumerate().map(|(k, m)| {
        tick(k);
        crate::signals::check(path)?;
        let m = m?;
        sinks
            .borrow_mut()
            .bag
            .measurements(std::slice::from_ref(&m))?;
        Ok::<_, FormatError>(m)
    });
    let report = roitrack::track(tracker, measurements, |e| sinks.borrow_mut().estimate(e))
        .with_context(|| format!("tracking {} failed", path.display()))?;
    Ok(report)
}

/// Tracks the ROI recording at `path`, each ROI centroided here with `options`; every ROI and what its centroid gave
/// also goes to the bag (its measurement; with --mcap-rois, the image).
pub(super) fn track_roi_recording(
    tracker: &mut Tracker,
    path: &std::path::Path,
    known_ids: Vec<u32>,
    options: &CentroidOptions,
    time: &roitrack::core::time::TimeModel,
    sinks: &mut EstimateSinks,
    tick: &dyn Fn(usize),
) -> Result<roitrack::pipeline::RoiTrackReport> {
    let reader = RoiRecordingReader::open(path)?.with_known_ids(known_ids);
    let images = reader.enumerate().map(|(k, image)| {
        tick(k);
        crate::signals::check(path)?;
        image
    });
    let report =
        roitrack::pipeline::track_rois_with(tracker, options, time, images, |event| match event {
            RoiEvent::Roi { image, measured } => sinks.bag.roi(image, measured.ok()),
            RoiEvent::Estimate(e) => sinks.estimate(e),
        })
        .with_context(|| format!("tracking {} failed", path.display()))?;
    Ok(report)
}

/// --rois' centroid options: the defaults, without the symmetry check with --no-symmetry-check.
pub(super) fn centroid_options(args: &TrackArgs) -> CentroidOptions {
    let mut options = CentroidOptions::default();
    if args.no_symmetry_check {
        options.symmetry = None;
    }
    options
}

/// The one-camera run's closing lines on stderr: the ROIs centroided (with --rois), then the measurements, the
/// estimates and the time per measurement.
pub(super) fn print_one_camera_summary(
    rois: Option<&roitrack::pipeline::RoiTrackReport>,
    report: &EstimatorReport,
    seconds: f64,
) {
    let EstimatorReport {
        measurements,
        estimates,
        ..
    } = report;
    if let Some(rois) = rois {
        eprintln!(
            "roitrack: {} ROIs centroided; rejected: {}",
            rois.rois, rois.rejections
        );
    }
    eprintln!(
        "roitrack: {measurements} measurements -> {} estimates ({} degenerate, {} lost) in {seconds:.3} s ({:.2} us \
         per measurement)",
        estimates.total(),
        estimates.get(TrackStatus::Degenerate),
        estimates.get(TrackStatus::Lost),
        1e6 * seconds / (*measurements).max(1) as f64
    );
}
