//! Track a recording: camera calibration, target and measured centroids from files in, poses, twists and diagnostics
//! files out.
//!
//! ```sh
//! cargo run --release -p roitrack --example track_recording                      # a simulated recording
//! cargo run --release -p roitrack --example track_recording -- CAMERA.yaml TARGET.csv MEASUREMENTS.csv OUT_DIR
//! ```
//!
//! Without arguments it first writes a recording of its own (the orthoglide scenario, 4 kHz, 0.1 px) to a temporary
//! folder, with its ground truth, and scores the estimates against it at the end.

use std::path::{Path, PathBuf};

use roitrack::eval::{EvalOptions, evaluate};
use roitrack::formats::{self, EstimateWriter, MeasurementReader};
use roitrack::sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
use roitrack::{TrackStatus, Tracker, TrackerConfig};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scratch = tempfile::tempdir()?;
    let (camera_path, target_path, measurements_path, out) = match args.as_slice() {
        [camera, target, measurements, out] => (
            PathBuf::from(camera),
            PathBuf::from(target),
            PathBuf::from(measurements),
            PathBuf::from(out),
        ),
        [] => write_simulated_recording(scratch.path())?,
        _ => {
            return Err(
                "usage: track_recording [CAMERA.yaml TARGET.csv MEASUREMENTS.csv OUT_DIR]".into(),
            );
        }
    };

    // The calibration and the target, as a user has them.
    let camera = formats::read_camera_yaml(&camera_path)?;
    let target = formats::read_target_csv(&target_path)?;
    let ids = target.points().iter().map(|p| p.id);
    // Measurements are streamed: a recording of any length is tracked in constant memory.
    let measurements = MeasurementReader::open(&measurements_path)?.with_known_ids(ids);

    std::fs::create_dir_all(&out)?;
    let (poses, twists, diagnostics) = (
        out.join("poses.tum"),
        out.join("twists.csv"),
        out.join("diagnostics.csv"),
    );
    let mut writer = EstimateWriter::create(&poses, &twists, Some(&diagnostics))?;
    let mut tracker = Tracker::new(camera, target, TrackerConfig::default())?;
    let report = roitrack::track(&mut tracker, measurements, |e| writer.write(e))?;
    // The files appear, complete, only now.
    writer.finish()?;

    let counts = report.estimates;
    println!(
        "{} measurements -> {} estimates: {} tracking, {} converging, {} disputed, {} degenerate, {} lost",
        report.measurements,
        counts.total(),
        counts.get(TrackStatus::Tracking),
        counts.get(TrackStatus::Converging),
        counts.get(TrackStatus::Disputed),
        counts.get(TrackStatus::Degenerate),
        counts.get(TrackStatus::Lost),
    );
    println!(
        "wrote {}, {} and {}",
        poses.display(),
        twists.display(),
        diagnostics.display()
    );

    // With a ground truth next to the measurements (as the simulated recording has), score the estimates.
    let truth_dir = measurements_path.parent().unwrap_or(Path::new("."));
    let (truth_poses, truth_twists) = (
        truth_dir.join("gt_poses.tum"),
        truth_dir.join("gt_twists.csv"),
    );
    if truth_poses.exists() && truth_twists.exists() {
        let metrics = evaluate(
            &formats::read_tum(&truth_poses)?,
            Some(&formats::read_twists_csv(&truth_twists)?),
            &formats::read_tum(&poses)?,
            Some(&formats::read_twists_csv(&twists)?),
            &EvalOptions::default(),
        )?;
        print!("{}", metrics.to_table());
    }
    Ok(())
}

/// Simulates the orthoglide scenario and writes its camera, target, measurements and ground truth into `dir`.
fn write_simulated_recording(dir: &Path) -> Result<(PathBuf, PathBuf, PathBuf, PathBuf)> {
    let run = simulate(
        &Scenario::new(ScenarioKind::Orthoglide, 1),
        &SimulationOptions::default(),
    )?;
    let paths = (
        dir.join("camera.yaml"),
        dir.join("target.csv"),
        dir.join("measurements.csv"),
        dir.join("out"),
    );
    formats::write_camera_yaml(&paths.0, &run.camera)?;
    formats::write_target_csv(&paths.1, &run.target)?;
    formats::write_measurements_csv(&paths.2, &run.measurements)?;
    formats::write_tum(dir.join("gt_poses.tum"), &run.truth_poses)?;
    formats::write_twists_csv(dir.join("gt_twists.csv"), &run.truth_twists)?;
    println!("simulated recording in {}", dir.display());
    Ok(paths)
}
