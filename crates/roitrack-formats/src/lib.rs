//! # roitrack-formats
//!
//! The files roitrack reads and writes (docs/model.md), with strict readers whose errors name the file, the line and
//! the field, and writers that never leave a half-written file behind:
//!
//! | file | reader | writer |
//! | --- | --- | --- |
//! | camera: ROS camera_info YAML | [`read_camera_yaml`], [`parse_camera_yaml`] | [`write_camera_yaml`], [`camera_yaml_string`] |
//! | camera: any calibration file (ROS YAML or topic echo, OpenCV FileStorage YAML or XML, Kalibr camchain, BoofCV YAML), by content | [`read_camera_file`], [`parse_camera_file`] | |
//! | target: CSV `id,x,y,z[,diameter]` (m, object frame) | [`read_target_csv`], [`parse_target_csv`] | [`write_target_csv`], [`target_csv_string`] |
//! | measurements: CSV `t,id,u,v` (s, raw px) | [`MeasurementReader`] (streaming), [`read_measurements_csv`] | [`MeasurementWriter`], [`write_measurements_csv`] |
//! | poses: TUM `t tx ty tz qx qy qz qw` (camera_T_object) | [`read_tum`], [`parse_tum`] | [`PoseWriter`], [`write_tum`] |
//! | ROI recordings ([`roitrack_image::RoiImage`]s): binary, see [`RoiRecordingReader`] | [`RoiRecordingReader`] (streaming) | [`RoiRecordingWriter`] |
//! | rig: YAML, cameras with their calibration files, poses in the rig and clocks | [`read_rig_yaml`], [`parse_rig_yaml`] | [`write_rig_yaml`], [`rig_yaml_string`] |
//! | twists: CSV `t,vx,vy,vz,wx,wy,wz` (camera frame) | [`read_twists_csv`], [`parse_twists_csv`] | [`TwistWriter`], [`write_twists_csv`] |
//! | estimates: poses, twists, diagnostics and covariance CSV together | | [`EstimateWriter`] |
//! | covariance: CSV `t,c0_0,c0_1,...,c11_11`, the 12 x 12 covariance's upper triangle per estimate | | [`CovarianceWriter`] |
//! | full frames ([`roitrack_image::Frame`]): PNG, JPEG, PGM/PPM, TIFF, 8 or 16 bits, colour made grey | [`read_frame`], [`decode_frame`] | [`write_frame_png`] |
//! | timed frame streams: a folder of images, a pattern `frame_%05d.png`, a glob or a video (by ffmpeg), with a timestamps CSV `t[,file]` or a frame rate | [`FrameSource`] | |
//! | detection overlays: a frame as an RGB PNG with marks and ids drawn on it | | [`write_overlay_png`] |
//!
//! Every reader refuses non-finite numbers and times out of order; every writer refuses what the reader would refuse
//! and writes numbers with full round-trip precision (the shortest decimal that reads back to the same `f64`).
//! Writers go through [`AtomicFile`]: the file appears at its path, complete, only on `finish()`; with an open
//! [`OutputSet`], only when the whole run's outputs are committed together.
//!
//! No function here panics on any input; all failures are [`FormatError`]s.
//!
//! ```
//! use roitrack_core::{Measurement, Target};
//! use roitrack_formats::{MeasurementReader, MeasurementWriter, read_target_csv, write_target_csv};
//!
//! # fn main() -> Result<(), roitrack_formats::FormatError> {
//! let dir = tempfile::tempdir().unwrap();
//! let target_path = dir.path().join("target.csv");
//! write_target_csv(&target_path, &Target::grid4x4())?;
//! let target = read_target_csv(&target_path)?;
//!
//! let path = dir.path().join("measurements.csv");
//! let mut writer = MeasurementWriter::create(&path)?;
//! writer.write(&Measurement { t_s: 0.0, id: 5, u_px: 512.25, v_px: 498.5 })?;
//! writer.finish()?; // only now does measurements.csv appear
//!
//! // Stream the rows back, refusing ids the target does not have.
//! let ids = target.points().iter().map(|p| p.id);
//! for m in MeasurementReader::open(&path)?.with_known_ids(ids) {
//!     let m = m?;
//!     assert_eq!((m.id, m.u_px), (5, 512.25));
//! }
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

mod atomic;
mod camera_file;
mod camera_xml;
mod camera_yaml;
mod covariance;
mod csv_util;
mod error;
mod estimates;
mod frame_source;
mod image_file;
mod limits;
mod measurements;
mod output_set;
mod overlay;
mod rig;
mod roi_recording;
mod row_writer;
mod run_readers;
mod target_csv;
mod tum;
mod twists;
mod units;
mod video;

pub use atomic::{AtomicFile, check_output_paths, open_input};
pub use camera_file::{
    CameraFileFormat, CameraFileOptions, detect_camera_format, distortion_from, parse_camera_file,
    read_camera_file,
};
pub use camera_yaml::{camera_yaml_string, parse_camera_yaml, read_camera_yaml, write_camera_yaml};
pub use covariance::{
    COVARIANCE_ENTRIES, COVARIANCE_SIZE, CovarianceWriter, covariance_entry_index,
    covariance_from_upper_triangle, covariance_header, covariance_upper_triangle,
};
pub use error::FormatError;
pub use estimates::{DIAGNOSTICS_HEADER, EstimateWriter};
pub use frame_source::{
    FRAME_IMAGE_EXTENSIONS, FrameInfo, FrameSource, FrameTiming, MAX_FRAME_RATE_HZ,
    MIN_FRAME_RATE_HZ, SourceKind,
};
pub use image_file::{
    FRAME_IMAGE_FORMATS, check_frame_size, decode_frame, read_frame, write_frame_png,
};
pub use limits::{
    DEFAULT_MAX_TRAJECTORY_FILE_BYTES, MAX_CAMERA_FILE_BYTES, MAX_IMAGE_FILE_BYTES, MAX_LINE_BYTES,
    MAX_TARGET_FILE_BYTES, MAX_TIMESTAMPS_FILE_BYTES, MAX_YAML_DEPTH,
};
pub use measurements::{
    CENTROID_EDGE_TOLERANCE_PX, MeasurementChecks, MeasurementField, MeasurementProblem,
    MeasurementReader, MeasurementWriter, read_measurements_csv, write_measurements_csv,
};
pub use output_set::{
    OutputDir, OutputSet, create_output_dir, keep_if_failed, partial_path, remove_at_commit,
    remove_dead_temporaries, remove_temporaries_before_exit,
};
pub use overlay::{MarkKind, OverlayMark, write_overlay_png};
pub use rig::{
    MAX_RIG_CAMERAS, RigFile, calibrated_rig_yaml_string, parse_rig_yaml, read_rig_yaml,
    rig_yaml_string, write_calibrated_rig_yaml, write_rig_yaml,
};
pub use roi_recording::{
    MAX_ROI_SIDE_PX, ROI_RECORDING_MAGIC, RoiRecordingReader, RoiRecordingWriter,
};
pub use run_readers::{
    CovarianceRow, DiagnosticsRow, parse_covariance_csv, parse_diagnostics_csv,
    read_covariance_csv, read_covariance_csv_limited, read_diagnostics_csv,
    read_diagnostics_csv_limited,
};
pub use target_csv::{parse_target_csv, read_target_csv, target_csv_string, write_target_csv};
pub use tum::{
    PoseWriter, QUATERNION_NORM_TOLERANCE, parse_tum, read_tum, read_tum_limited, write_tum,
};
pub use twists::{
    TwistWriter, parse_twists_csv, read_twists_csv, read_twists_csv_limited, write_twists_csv,
};
pub use units::{
    LengthUnit, MAX_PLAUSIBLE_ANGULAR_SPEED_RADPS, MAX_PLAUSIBLE_BLOB_DIAMETER_M,
    MAX_PLAUSIBLE_DISTANCE_M, MAX_PLAUSIBLE_MEDIAN_STEP_S, MAX_PLAUSIBLE_SPEED_MPS,
    MAX_PLAUSIBLE_TARGET_SPAN_M, MAX_PLAUSIBLE_TIME_S, TimeUnit, TimedMeasurements,
    parse_target_csv_in, read_target_csv_in,
};
