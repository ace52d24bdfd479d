//! `track --rig`: every camera's input of a rig read, merged in rig time and fused into one pose and twist.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use roitrack::formats::{EstimateWriter, check_output_paths};

use super::TrackArgs;
use super::frames::{frame_camera, frame_config, frame_timing};
use super::one_camera::centroid_options;

/// One camera's input of a rig run, read and checked against that camera.
struct CameraStream {
    camera: usize,
    /// The option and its file or source, for messages: `--images cam1=frames/`.
    label: String,
    reader: roitrack::camera_input::MeasurementStream,
}

/// `--measurements NAME=FILE` (or `--rois`, `--images`) as (name, file); refused without the `=`.
/// `option NAME=FILE` of a rig run: the index of the rig's camera NAME, the name and the file; an error naming the
/// rig's cameras if it has no such camera.
fn rig_camera(
    option: &str,
    value: &std::path::Path,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
) -> Result<(usize, String, PathBuf)> {
    let (name, path) = split_camera_file(option, value)?;
    let Some(c) = rig.index_of(&name) else {
        let names: Vec<&str> = rig.cameras().iter().map(|c| c.name.as_str()).collect();
        bail!(
            "{option} {name}={}: {} has no camera '{name}' (its cameras: {})",
            path.display(),
            rig_path.display(),
            names.join(", ")
        );
    };
    Ok((c, name, path))
}

fn split_camera_file(option: &str, text: &std::path::Path) -> Result<(String, PathBuf)> {
    let text = text.to_string_lossy();
    match text.split_once('=') {
        Some((name, file)) if !name.is_empty() && !file.is_empty() => {
            Ok((name.to_string(), PathBuf::from(file)))
        }
        _ => bail!(
            "{option} {text}: with --rig, give NAME=FILE, the name of a camera of the rig and its input"
        ),
    }
}

/// Every camera's input of a rig run (`NAME=...` of --measurements, --rois, --images), by camera: each name a camera
/// of the rig, given once.
fn rig_inputs(
    args: &TrackArgs,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
) -> Result<Vec<Option<roitrack::camera_input::CameraInput>>> {
    use roitrack::camera_input::CameraInput;
    let timestamps = per_camera("--timestamps", &args.timestamps, rig_path, rig)?;
    let topics = per_camera("--topic", &args.topic, rig_path, rig)?;
    let mut inputs: Vec<Option<CameraInput>> = vec![None; rig.len()];
    let given = [
        ("--measurements", &args.measurements),
        ("--rois", &args.rois),
        ("--images", &args.images),
    ];
    for (option, values) in given {
        for value in values {
            let (c, name, path) = rig_camera(option, value, rig_path, rig)?;
            if let Some(before) = &inputs[c] {
                bail!(
                    "{option} {name}={}: camera '{name}' is given twice (also {} {name}={}): one input per camera",
                    path.display(),
                    before.option(),
                    before.path().display()
                );
            }
            let bag = option != "--rois" && crate::ros::is_bag(&path);
            let topic = topics[c].as_ref().map(|t| t.to_string_lossy().into_owned());
            inputs[c] = Some(match (option, bag, topic) {
                (_, true, None) => bail!(
                    "{option} {name}={}: a ROS 2 bag: give camera '{name}''s topic, --topic {name}=TOPIC",
                    path.display()
                ),
                (_, false, Some(topic)) => bail!(
                    "--topic {name}={topic}: camera '{name}''s input ({option} {name}={}) is not a ROS 2 bag (a .mcap \
                     file or a rosbag2 folder)",
                    path.display()
                ),
                ("--measurements", true, Some(topic)) => {
                    CameraInput::BagMeasurements { bag: path, topic }
                }
                ("--images", true, Some(topic)) => CameraInput::BagImages {
                    bag: path,
                    topic,
                    config: Box::new(frame_config(args)?),
                },
                ("--measurements", ..) => CameraInput::Measurements {
                    path,
                    time_units: args.time_units.map(Into::into),
                },
                ("--rois", ..) => CameraInput::Rois {
                    path,
                    options: centroid_options(args),
                },
                _ => CameraInput::Images {
                    source: path,
                    timing: frame_timing(args, timestamps[c].clone()),
                    config: Box::new(frame_config(args)?),
                },
            });
        }
    }
    if let Some((name, path)) = timestamps.iter().enumerate().find_map(|(c, path)| {
        let path = path.as_ref()?;
        let frames = matches!(inputs[c], Some(CameraInput::Images { .. }));
        (!frames).then_some((&rig.cameras()[c].name, path))
    }) {
        bail!(
            "--timestamps {name}={}: camera '{name}' has no --images {name}=..., whose frames' times it would give",
            path.display()
        );
    }
    if let Some((name, topic)) = topics.iter().enumerate().find_map(|(c, topic)| {
        let topic = topic.as_ref()?;
        inputs[c]
            .is_none()
            .then_some((&rig.cameras()[c].name, topic))
    }) {
        bail!(
            "--topic {name}={}: camera '{name}' has no input (--measurements {name}=BAG or --images {name}=BAG)",
            topic.display()
        );
    }
    Ok(inputs)
}

/// Each camera's `option NAME=VALUE` of a rig run (--timestamps, --topic), by camera: each name a camera of the rig,
/// given once.
fn per_camera(
    option: &str,
    values: &[PathBuf],
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
) -> Result<Vec<Option<PathBuf>>> {
    let mut per_camera: Vec<Option<PathBuf>> = vec![None; rig.len()];
    for value in values {
        let (c, name, path) = rig_camera(option, value, rig_path, rig)?;
        if let Some(before) = &per_camera[c] {
            bail!(
                "{option} {name}={}: camera '{name}' is given twice (also {option} {name}={})",
                path.display(),
                before.display()
            );
        }
        per_camera[c] = Some(path);
    }
    Ok(per_camera)
}

/// `track --rig`: every camera's input turned into measurements (frames through the camera's own frame tracker) and
/// merged in the order of their rig times (as far as the rig file gives
/// the clocks; the tracker's reorder buffer takes the rest), fused into one pose and twist in the rig's frame.
pub(super) fn run_rig(args: &TrackArgs, rig_path: &std::path::Path) -> Result<()> {
    check_rig_options(args)?;
    let file = roitrack::formats::read_rig_yaml(rig_path, &Default::default())?;
    let rig = &file.rig;
    let target = args.target.read()?;
    // Each NAME=...: a camera of the rig, once.
    let inputs = rig_inputs(args, rig_path, rig)?;
    if inputs[0].is_none() {
        let first = &rig.cameras()[0].name;
        bail!(
            "the first camera of {}, '{first}', holds the rig's clock: give its input ({first}=FILE to \
             --measurements, --rois or --images)",
            rig_path.display(),
        );
    }
    check_rig_paths(args, rig_path, &file, &inputs)?;
    let streams = open_camera_streams(args, rig, &inputs, &target)?;
    let any_frames = inputs.iter().flatten().any(|i| i.is_frames());
    let mut tracker = rig_tracker(args, rig_path, rig, target, any_frames)?;
    let mut writer =
        EstimateWriter::create(&args.poses, &args.twists, args.diagnostics.as_deref())?
            .with_covariance(args.covariance.as_deref())?;
    // The fused estimates (rig frame, rig clock) also to the bag, the live view and the DDS bus, each if asked.
    let bag_options = args.ros.rig_bag_options();
    let mut bag = args.ros.open_with_options(None, None, &bag_options)?;
    bag.publish_on_ros2(args.ros2.start(None, &bag_options)?);
    let start = Instant::now();
    let (count, estimates) = if tracker.is_single() {
        track_rig_of_one(&mut tracker, streams, rig_path, &mut bag, &mut writer)?
    } else {
        track_merged_streams(&mut tracker, streams, rig_path, rig, &mut bag, &mut writer)?
    };
    writer.finish()?;
    bag.finish()?;
    let clocks = tracker.clocks();
    if let Some(out) = &args.rig_out {
        let calibrations = file.calibrations_for_output(out);
        roitrack::formats::write_rig_yaml(out, rig, &calibrations, Some(&clocks))?;
    }
    let seconds = start.elapsed().as_secs_f64();
    print_learnt_clocks(rig, &clocks);
    let report = tracker.report();
    eprintln!(
        "roitrack: {count} measurements of {} cameras -> {estimates} estimates in {seconds:.3} s ({:.2} us per \
         measurement); fused {}, rejected by the gate {}, fused tracks started {}, instants widened {}",
        rig.len(),
        1e6 * seconds / count.max(1) as f64,
        report.fused,
        report.gated,
        report.starts,
        report.instants_widened
    );
    Ok(())
}

/// Refuses the options a rig run does not take: --camera (the rig gives the cameras), the one-camera bag topics,
/// --mcap-rois.
fn check_rig_options(args: &TrackArgs) -> Result<()> {
    if args.camera.is_some() {
        bail!("--rig gives the cameras: leave out --camera");
    }
    if args.mcap_in.measurement_topic.is_some() || args.mcap_in.image_topic.is_some() {
        bail!(
            "--rig: a camera's bag topic is --topic NAME=TOPIC (not --measurement-topic or --image-topic)"
        );
    }
    if args.ros.mcap_rois {
        bail!("--mcap-rois: a rig's bag holds its fused estimates only");
    }
    Ok(())
}

/// Every given camera's input opened as measurements against its camera (with the time model of --shutter and
/// --exposure-s for frames), in the rig's order, each labelled for messages.
fn open_camera_streams(
    args: &TrackArgs,
    rig: &roitrack::estimators::rig::Rig,
    inputs: &[Option<roitrack::camera_input::CameraInput>],
    target: &roitrack::Target,
) -> Result<Vec<CameraStream>> {
    let mut streams = Vec::new();
    for (c, input) in inputs.iter().enumerate() {
        let Some(input) = input else { continue };
        let name = &rig.cameras()[c].name;
        let label = match input.topic() {
            Some(topic) => format!(
                "{} {name}={} --topic {name}={topic}",
                input.option(),
                input.path().display()
            ),
            None => format!("{} {name}={}", input.option(), input.path().display()),
        };
        let camera = if input.is_frames() {
            frame_camera(args, rig.cameras()[c].camera.clone())?
        } else {
            rig.cameras()[c].camera.clone()
        };
        let reader = roitrack::camera_input::open_camera_input(input, &camera, target)
            .with_context(|| format!("camera '{name}' ({label})"))?;
        streams.push(CameraStream {
            camera: c,
            label,
            reader,
        });
    }
    Ok(streams)
}

/// The rig's tracker, with the frame tracker's estimator options when any camera gives frames. A pose left out of
/// the rig file is the file's fault, not the options': the error names the file.
fn rig_tracker(
    args: &TrackArgs,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
    target: roitrack::Target,
    any_frames: bool,
) -> Result<roitrack::estimators::rig::RigTracker> {
    let config = roitrack::estimators::rig::RigTrackerConfig {
        tracker: if any_frames {
            frame_config(args)?.tracker
        } else {
            args.estimator.config()?
        },
        ..Default::default()
    };
    roitrack::estimators::rig::RigTracker::new(rig.clone(), target, config).map_err(|e| match e {
        roitrack::estimators::rig::RigError::MountUnknown { .. } => {
            anyhow::anyhow!("{}: {e}", rig_path.display())
        }
        e => anyhow::Error::new(e),
    })
}

/// One camera that is the rig: the single-camera path itself (readouts of one time pushed whole). The measurements
/// read and the estimates written.
fn track_rig_of_one(
    tracker: &mut roitrack::estimators::rig::RigTracker,
    mut streams: Vec<CameraStream>,
    rig_path: &std::path::Path,
    bag: &mut crate::ros::Bag,
    writer: &mut EstimateWriter,
) -> Result<(usize, usize)> {
    let mut estimates = 0usize;
    let stream = streams.remove(0);
    let path = stream.label.clone();
    let single = tracker.camera_tracker(0).expect("a rig has a first camera");
    let measurements = stream.reader.map(|m| {
        crate::signals::check(rig_path)?;
        m
    });
    let report = roitrack::track(single, measurements, |e| {
        estimates += 1;
        bag.estimate(e)?;
        writer.write(e)
    })
    .with_context(|| format!("tracking {path} failed"))?;
    let count = report.measurements;
    if report.estimates.total() == 0 {
        bail!(
            "{path}: no estimate from {count} measurements: {}",
            report.why_no_start()
        );
    }
    Ok((count, estimates))
}

/// Several cameras: their measurements merged by the rig file's clocks (or by each camera's own when the file
/// leaves them out) and fused. The measurements read and the estimates written.
fn track_merged_streams(
    tracker: &mut roitrack::estimators::rig::RigTracker,
    streams: Vec<CameraStream>,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
    bag: &mut crate::ros::Bag,
    writer: &mut EstimateWriter,
) -> Result<(usize, usize)> {
    let mut count = 0usize;
    let mut estimates = 0usize;
    let clocks: Vec<roitrack::estimators::rig::ClockModel> =
        rig.cameras().iter().map(|c| c.clock).collect();
    let labels: Vec<String> = streams.iter().map(|s| s.label.clone()).collect();
    let streams_cameras: Vec<usize> = streams.iter().map(|s| s.camera).collect();
    let merged = roitrack::estimators::rig::merge_streams(
        streams.into_iter().map(|s| (s.camera, s.reader)).collect(),
        &clocks,
    );
    for (k, m) in merged {
        crate::signals::check(rig_path)?;
        // k: the stream's position among the streams given.
        let label = &labels[k];
        let m = m.with_context(|| {
            format!(
                "camera '{}' ({label})",
                rig.cameras()[streams_cameras[k]].name
            )
        })?;
        count += 1;
        let fused = tracker
            .push(&m)
            .with_context(|| format!("tracking {label} failed"))?;
        for e in fused {
            bag.estimate(&e.estimate)?;
            writer.write(&e.estimate)?;
            estimates += 1;
        }
    }
    for e in tracker.finish() {
        bag.estimate(&e.estimate)?;
        writer.write(&e.estimate)?;
        estimates += 1;
    }
    if estimates == 0 {
        bail!(
            "{}: no estimate from {count} measurements: no camera's own track started, or no clock offset was found \
             (the target must move)",
            rig_path.display()
        );
    }
    Ok((count, estimates))
}

/// Each clock the rig file left out, as learnt (or not found), on stderr.
fn print_learnt_clocks(
    rig: &roitrack::estimators::rig::Rig,
    clocks: &[roitrack::estimators::rig::ClockEstimate],
) {
    for (camera, clock) in rig.cameras().iter().zip(clocks).skip(1) {
        if !camera.clock_known() {
            eprintln!(
                "roitrack: camera '{}': clock offset {:.6} s ± {:.1} us, drift {:.2} ppm ± {:.2} ppm{}",
                camera.name,
                clock.offset_s,
                clock.offset_sigma_s * 1e6,
                clock.drift_ppm,
                clock.drift_sigma_ppm,
                if clock.synced {
                    ""
                } else {
                    " (not found: the camera was left out)"
                }
            );
        }
    }
}

/// The rig run's inputs (the rig, its calibrations, the target, the measurement files) against its outputs.
fn check_rig_paths(
    args: &TrackArgs,
    rig_path: &std::path::Path,
    file: &roitrack::formats::RigFile,
    given: &[Option<roitrack::camera_input::CameraInput>],
) -> Result<()> {
    let mut inputs = vec![
        ("--target", args.target.target.as_path()),
        ("--rig", rig_path),
    ];
    for path in &file.calibration_paths {
        inputs.push(("--rig's calibration", path.as_path()));
    }
    for input in given.iter().flatten() {
        inputs.push((input.option(), input.path()));
    }
    let mut outputs = vec![
        ("--poses", args.poses.as_path()),
        ("--twists", args.twists.as_path()),
    ];
    for (name, path) in [
        ("--diagnostics", &args.diagnostics),
        ("--covariance", &args.covariance),
        ("--rig-out", &args.rig_out),
    ] {
        if let Some(path) = path {
            outputs.push((name, path.as_path()));
        }
    }
    check_output_paths(&inputs, &outputs)?;
    Ok(())
}
