//! A run's files: `reference.tum` and `achieved.tum` (the platform's commanded and true poses, camera_T_object, TUM,
//! at every control tick, so that anyone can recompute the errors), the tracker's estimates (`estimates.tum`,
//! `estimates_twists.csv`, `estimates_diagnostics.csv`, roitrack's formats), and `servo.csv` (per tick: the path,
//! the platform, the error and the actuator forces). Written with roitrack-formats' atomic writers.

use std::io::Write as _;
use std::path::Path;

use roitrack_core::PoseSample;
use roitrack_formats::{AtomicFile, EstimateWriter, FormatError, create_output_dir, write_tum};

use crate::ServoReport;

/// The commanded platform poses of a run (TUM, camera_T_object, every control tick).
pub const REFERENCE_FILE: &str = "reference.tum";
/// The true platform poses of a run (TUM, every control tick).
pub const ACHIEVED_FILE: &str = "achieved.tum";
/// The tracker's estimated poses (TUM).
pub const ESTIMATES_FILE: &str = "estimates.tum";
/// The tracker's estimated twists (CSV).
pub const ESTIMATE_TWISTS_FILE: &str = "estimates_twists.csv";
/// The tracker's diagnostics per estimate (CSV: status, residual, sigmas).
pub const ESTIMATE_DIAGNOSTICS_FILE: &str = "estimates_diagnostics.csv";
/// Per control tick: path, platform, error and actuator forces (CSV).
pub const SAMPLES_FILE: &str = "servo.csv";
/// The header of `servo.csv` (robot frame: the camera's axes, origin at the platform's home; metres, newtons).
pub const SAMPLES_HEADER: &str = "t,ref_x,ref_y,ref_z,x,y,z,error_mm,force_0,force_1,force_2";

/// Writes the files of `report` into `dir` (created if missing).
///
/// ```
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig, run_servo};
/// use roitrack_servo::reference::ReferencePath;
/// let mut config = ServoConfig::new(ControllerKind::TrueState, CameraKind::Truth, 1.0);
/// config.path = ReferencePath::random(1, 0.5, 1.0);
/// let report = run_servo(&config).unwrap();
/// let dir = tempfile::tempdir().unwrap();
/// roitrack_servo::output::write_run(&report, dir.path()).unwrap();
/// let achieved = std::fs::read_to_string(dir.path().join("achieved.tum")).unwrap();
/// assert_eq!(achieved.lines().filter(|l| !l.starts_with('#')).count(), report.samples.len());
/// ```
pub fn write_run(report: &ServoReport, dir: &Path) -> Result<(), FormatError> {
    create_output_dir(dir)?;
    let path = &report.path;
    let poses =
        |position: &dyn Fn(&crate::ServoSample) -> nalgebra::Vector3<f64>| -> Vec<PoseSample> {
            report
                .samples
                .iter()
                .map(|s| {
                    PoseSample::from_state(
                        s.t_s,
                        &path.camera_state(&position(s), &nalgebra::Vector3::zeros()),
                    )
                })
                .collect()
        };
    write_tum(
        dir.join(REFERENCE_FILE),
        &poses(&|s| s.reference.position_m),
    )?;
    write_tum(dir.join(ACHIEVED_FILE), &poses(&|s| s.achieved_m))?;
    let mut estimates = EstimateWriter::create(
        &dir.join(ESTIMATES_FILE),
        &dir.join(ESTIMATE_TWISTS_FILE),
        Some(&dir.join(ESTIMATE_DIAGNOSTICS_FILE)),
    )?;
    for estimate in report.estimates.iter().filter(|e| e.state.is_finite()) {
        estimates.write(estimate)?;
    }
    estimates.finish()?;
    let samples_path = dir.join(SAMPLES_FILE);
    let mut file = AtomicFile::create(&samples_path)?;
    let io = |e| FormatError::io(&samples_path, "cannot write", e);
    writeln!(file, "{SAMPLES_HEADER}").map_err(io)?;
    for s in &report.samples {
        let (r, p, f) = (s.reference.position_m, s.achieved_m, s.force_n);
        writeln!(
            file,
            "{:.6},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.6},{:.3},{:.3},{:.3}",
            s.t_s,
            r.x,
            r.y,
            r.z,
            p.x,
            p.y,
            p.z,
            s.error_m() * 1e3,
            f.x,
            f.y,
            f.z
        )
        .map_err(io)?;
    }
    file.finish()
}

/// A run as the series its figures draw (robot frame), labelled `controller / camera`.
pub fn figure_series(report: &ServoReport) -> roitrack_plot::servo::ServoRunSeries {
    let array = |v: &nalgebra::Vector3<f64>| [v.x, v.y, v.z];
    roitrack_plot::servo::ServoRunSeries {
        label: format!("{} / {}", report.controller.name(), report.camera.name()),
        t_s: report.samples.iter().map(|s| s.t_s).collect(),
        reference_m: report
            .samples
            .iter()
            .map(|s| array(&s.reference.position_m))
            .collect(),
        achieved_m: report
            .samples
            .iter()
            .map(|s| array(&s.achieved_m))
            .collect(),
        force_n: report.samples.iter().map(|s| array(&s.force_n)).collect(),
    }
}

/// The figures of `reports` (the path, the error over time, the actuator forces: `servo_path`, `servo_error`,
/// `servo_forces`, PNG and SVG), rendered in memory for the caller to write with its other outputs.
///
/// ```
/// use roitrack_servo::{CameraKind, ControllerKind, ServoConfig, run_servo};
/// use roitrack_servo::reference::ReferencePath;
/// let mut config = ServoConfig::new(ControllerKind::TrueState, CameraKind::Truth, 1.0);
/// config.path = ReferencePath::random(1, 0.5, 1.0);
/// let report = run_servo(&config).unwrap();
/// let files = roitrack_servo::output::render_figures(&[report]).unwrap();
/// assert_eq!(files.len(), 6);
/// ```
pub fn render_figures(
    reports: &[ServoReport],
) -> Result<Vec<roitrack_plot::RenderedFile>, roitrack_plot::PlotError> {
    let series: Vec<_> = reports.iter().map(figure_series).collect();
    roitrack_plot::servo::render_servo_figures(&series)
}
