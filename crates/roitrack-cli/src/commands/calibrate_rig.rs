//! `roitrack calibrate-rig`: every camera's pose in the rig and its clock, found from a recording of the moving
//! target seen by at least two cameras at a time (`roitrack_estimators::rig::RigCalibrator`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use roitrack::estimators::rig::{RigCalibrationConfig, RigCalibrator, RigMeasurement};
use roitrack::formats::{MeasurementReader, TimedMeasurements, check_output_paths, open_input};

use crate::args::{EstimatorArgs, TargetArgs, TimeUnitArg};

/// Find the cameras' poses in a rig (camera_T_rig) and their clocks (offset, drift) from a recording of the moving
/// target, seen by at least two cameras at a time, and write the rig file with them and their standard deviations.
#[derive(Debug, Args)]
pub struct CalibrateRigArgs {
    /// The rig (YAML; docs/rig.md): every camera's name and calibration file. A camera's camera_T_rig, clock_offset_s
    /// and clock_drift_ppm may be left out: they are found; those given are kept. The first camera's frame (when its
    /// pose is left out) and its clock are the rig's.
    #[arg(long, value_name = "RIG.yaml")]
    pub rig: PathBuf,
    #[command(flatten)]
    pub target: TargetArgs,
    /// One NAME=FILE per camera of the rig (repeated): its measured centroids (CSV t,id,u,v; raw pixels; its own
    /// clock). Every camera whose pose or clock is to be found needs one.
    #[arg(long, value_name = "NAME=FILE", required = true)]
    pub measurements: Vec<PathBuf>,
    /// The unit of the measurements' times. Default: seconds, checked for a likely unit mistake as `track` does.
    #[arg(long, value_enum, value_name = "UNIT")]
    pub time_units: Option<TimeUnitArg>,
    /// An unknown clock offset is searched within ±this (s). Default: 0.1.
    #[arg(long, value_name = "S", default_value_t = 0.1, value_parser = crate::ranges::positive_up_to(10.0, " s", "ten seconds"))]
    pub max_offset_s: f64,
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    /// The rig file to write: every camera's camera_T_rig, clock_offset_s and clock_drift_ppm, with their standard
    /// deviations (camera_T_rig_sigma_m and camera_T_rig_sigma_deg about the camera's axes, clock_offset_sigma_s,
    /// clock_drift_sigma_ppm; 0 for what the rig file gave).
    #[arg(long, value_name = "RIG_OUT.yaml")]
    pub out: PathBuf,
}

/// Runs `calibrate-rig`.
pub fn run(args: &CalibrateRigArgs) -> Result<()> {
    let file = roitrack::formats::read_rig_yaml(&args.rig, &Default::default())?;
    let rig = &file.rig;
    let target = args.target.read()?;
    let known_ids: Vec<u32> = target.points().iter().map(|p| p.id).collect();
    let mut files: Vec<Option<PathBuf>> = vec![None; rig.len()];
    for given in &args.measurements {
        let text = given.to_string_lossy();
        let Some((name, path)) = text
            .split_once('=')
            .filter(|(n, f)| !n.is_empty() && !f.is_empty())
        else {
            bail!(
                "--measurements {text}: give NAME=FILE, the name of a camera of the rig and its measurements"
            );
        };
        let Some(c) = rig.index_of(name) else {
            let names: Vec<&str> = rig.cameras().iter().map(|c| c.name.as_str()).collect();
            bail!(
                "--measurements {name}={path}: {} has no camera '{name}' (its cameras: {})",
                args.rig.display(),
                names.join(", ")
            );
        };
        if files[c].is_some() {
            bail!("--measurements: camera '{name}' is given twice");
        }
        files[c] = Some(PathBuf::from(path));
    }
    for (c, camera) in rig.cameras().iter().enumerate() {
        let to_find = !camera.mount_known || !camera.clock_known();
        if files[c].is_none() && to_find {
            bail!(
                "camera '{0}': its camera_T_rig or clock is to be found: give --measurements {0}=FILE",
                camera.name
            );
        }
    }
    let mut inputs = vec![
        ("--rig", args.rig.as_path()),
        ("--target", args.target.target.as_path()),
    ];
    for path in &file.calibration_paths {
        inputs.push(("--rig's calibration", path.as_path()));
    }
    for path in files.iter().flatten() {
        inputs.push(("--measurements", path.as_path()));
    }
    check_output_paths(&inputs, &[("--out", args.out.as_path())])?;
    let config = RigCalibrationConfig {
        tracker: args.estimator.config()?,
        max_offset_s: args.max_offset_s,
        ..Default::default()
    };
    let mut calibrator =
        RigCalibrator::new(rig.clone(), target, config).context("invalid tracker options")?;
    let start = Instant::now();
    let mut count = 0usize;
    // Each camera's own tracker takes its measurements in its own time order: the files one after the other.
    for (c, path) in files.iter().enumerate() {
        let Some(path) = path else { continue };
        let camera = &rig.cameras()[c].camera;
        let reader = MeasurementReader::from_reader(open_input(path)?, path)?
            .with_known_ids(known_ids.iter().copied())
            .with_image_size(camera.width_px, camera.height_px);
        for m in TimedMeasurements::new(reader, args.time_units.map(Into::into)) {
            crate::signals::check(path)?;
            let measurement = m?;
            count += 1;
            calibrator
                .push(&RigMeasurement {
                    camera: c,
                    measurement,
                })
                .with_context(|| format!("{}", path.display()))?;
        }
    }
    let calibration = calibrator
        .finish()
        .with_context(|| format!("calibrating {} failed", args.rig.display()))?;
    let calibrations = file.calibrations_for_output(&args.out);
    roitrack::formats::write_calibrated_rig_yaml(&args.out, &calibration, &calibrations)?;
    for (camera, found) in rig.cameras().iter().zip(&calibration.cameras) {
        let Some(against) = found.placed_against else {
            continue;
        };
        let t = found.mount.camera_t_rig_m;
        eprintln!(
            "roitrack: camera '{}' (placed against '{}', {} estimates, residual {:.3} mm RMS): camera_T_rig \
             translation [{:.4}, {:.4}, {:.4}] m ± [{:.2}, {:.2}, {:.2}] mm, rotation ± [{:.3}, {:.3}, {:.3}] deg; \
             clock offset {:.6} s ± {:.1} us, drift {:.2} ppm ± {:.2} ppm",
            camera.name,
            rig.cameras()[against].name,
            found.samples,
            found.rms_residual_m * 1e3,
            t.x,
            t.y,
            t.z,
            found.mount_sigma_m.x * 1e3,
            found.mount_sigma_m.y * 1e3,
            found.mount_sigma_m.z * 1e3,
            found.mount_sigma_rad.x.to_degrees(),
            found.mount_sigma_rad.y.to_degrees(),
            found.mount_sigma_rad.z.to_degrees(),
            found.clock.offset_s,
            found.offset_sigma_s * 1e6,
            found.clock.drift_ppm,
            found.drift_sigma_ppm,
        );
    }
    eprintln!(
        "roitrack: {count} measurements of {} cameras calibrated in {:.3} s -> {}",
        rig.len(),
        start.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(())
}
