//! Image sequences: rolling-shutter skew, global-shutter timing, dark blobs on uneven light, determinism, validation
//! and the ground truth. `cargo test --release -p roitrack-sim --test frames -- --ignored --nocapture` also prints
//! the rendering speed on the whole orthoglide scenario.

use std::time::Instant;

use nalgebra::Vector2;
use roitrack_core::time::{Readout, TimeModelError};
use roitrack_core::{Measurement, so3};
use roitrack_image::{CentroidOptions, Frame, Polarity, Roi, measure_blob};
use roitrack_sim::{
    DEFAULT_TRUTH_RATE_HZ, FrameOptions, FrameSequence, FrameSequenceError, Scenario, ScenarioKind,
};

const ROI_SIZE_PX: u32 = 40;
const LINE_DELAY_S: f64 = 30e-6;

/// The orthoglide time of the fastest sideways (image u) motion: about 1 m/s on the circle.
fn fastest_sideways_s(scenario: &Scenario) -> f64 {
    let steps = (scenario.duration_s * 1000.0) as usize;
    (0..steps)
        .map(|k| k as f64 / 1000.0)
        .max_by(|a, b| {
            let vx = |t: f64| scenario.state_at(t).velocity_mps.x.abs();
            vx(*a).total_cmp(&vx(*b))
        })
        .unwrap()
}

/// One frame around the fastest sideways motion, its middle row exposed at that time.
fn frame_at_speed(readout: Readout, polarity: Polarity) -> (FrameSequence, Frame) {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let t_fast_s = fastest_sideways_s(&scenario);
    let speed = scenario.state_at(t_fast_s).velocity_mps;
    assert!(speed.x.abs() > 0.9 && speed.y.abs() < 0.2, "{speed:?}");
    let options = FrameOptions {
        readout,
        polarity,
        start_s: t_fast_s - 512.0 * LINE_DELAY_S,
        frame_count: Some(1),
        ..FrameOptions::default()
    };
    let mut frames = FrameSequence::new(&scenario, &options).unwrap();
    let mut frame = Frame::default();
    frames.render(0, &mut frame);
    (frames, frame)
}

/// How a blob's ROI is prepared for [`measure_blob`], which wants bright blobs on a dark background.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Prepare {
    /// As rendered.
    Bright,
    /// Dark blobs inverted (`max - value`), the plane through the ROI's border (the local light) taken away.
    Inverted,
    /// Dark blobs divided by the plane through the ROI's border (flat-fielded): `1 - value / light`, the ink's
    /// coverage, whatever the light's slope across the blob.
    FlatFielded,
}

/// The centroid of the blob in a 40 x 40 ROI centred on (u, v).
fn measure(frame: &Frame, u_px: f64, v_px: f64, prepare: Prepare) -> Vector2<f64> {
    let roi = Roi::centred(u_px, v_px, ROI_SIZE_PX, frame.width, frame.height).unwrap();
    let mut pixels = vec![0u16; roi.len()];
    roi.crop_from(&frame.pixels, frame.width, &mut pixels);
    let max = f64::from((1u32 << frame.bit_depth) - 1);
    let n = ROI_SIZE_PX as usize;
    let values: Vec<f64> = pixels.iter().map(|&p| f64::from(p)).collect();
    let plane = border_plane(&values, n);
    for (index, p) in pixels.iter_mut().enumerate() {
        let (i, j) = ((index % n) as f64, (index / n) as f64);
        let light = plane[0] + plane[1] * i + plane[2] * j;
        let prepared = match prepare {
            Prepare::Bright => continue,
            // max - value less the plane of max - value: light - value, offset to keep the noise above 0.
            Prepare::Inverted => 20.0 + light - values[index],
            Prepare::FlatFielded => 20.0 + 200.0 * (1.0 - values[index] / light),
        };
        *p = prepared.round().clamp(0.0, max) as u16;
    }
    let c = measure_blob(&pixels, &roi, &CentroidOptions::default())
        .unwrap_or_else(|e| panic!("blob at ({u_px:.1}, {v_px:.1}): {e}"));
    Vector2::new(c.u_px, c.v_px)
}

/// Least-squares plane a + b i + c j through the border pixels of an n x n ROI.
fn border_plane(values: &[f64], n: usize) -> [f64; 3] {
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for j in 0..n {
        for i in 0..n {
            if i == 0 || j == 0 || i == n - 1 || j == n - 1 {
                let row = nalgebra::Vector3::new(1.0, i as f64, j as f64);
                ata += row * row.transpose();
                atb += row * values[j * n + i];
            }
        }
    }
    let x = ata.lu().solve(&atb).unwrap();
    [x[0], x[1], x[2]]
}

/// The projection of point `id`'s centre at `t_s` (raw pixels).
fn projection_at(frames: &FrameSequence, id: u32, t_s: f64) -> Vector2<f64> {
    let target = &frames.scenario().target;
    let point = &target.points()[target.index_of(id).unwrap()];
    let state = frames.state_at(t_s);
    frames
        .camera()
        .raw_pixel_from_cam(&state.point_in_cam_at(&point.point_in_obj_m, 0.0))
        .unwrap()
}

/// The largest distance between each blob's centroid and its true centre.
fn worst_error_px(frame: &Frame, blobs: &[Measurement], prepare: Prepare) -> f64 {
    blobs
        .iter()
        .map(|b| (measure(frame, b.u_px, b.v_px, prepare) - Vector2::new(b.u_px, b.v_px)).norm())
        .fold(0.0, f64::max)
}

#[test]
fn a_rolling_shutter_shows_each_blob_at_its_row_time() {
    let (frames, frame) = frame_at_speed(
        Readout::RollingShutter {
            line_delay_s: LINE_DELAY_S,
        },
        Polarity::Bright,
    );
    let t_frame_s = frames.frame_time_s(0);
    let blobs = frames.true_blob_centres(0);
    assert_eq!(blobs.len(), 16);
    for b in &blobs {
        assert!((b.t_s - (t_frame_s + b.v_px * LINE_DELAY_S)).abs() < 1e-12);
        let measured = measure(&frame, b.u_px, b.v_px, Prepare::Bright);
        let at_row_px = (measured - Vector2::new(b.u_px, b.v_px)).norm();
        let at_frame_px = (measured - projection_at(&frames, b.id, t_frame_s)).norm();
        assert!(at_row_px < 0.15, "blob {}: {at_row_px} px", b.id);
        assert!(at_frame_px > 1.0, "blob {}: {at_frame_px} px", b.id);
    }
    // The skew: the grid's bottom row is read later than its top row, so it has moved further sideways.
    let u_of = |id: u32, at_frame: bool| {
        let b = blobs.iter().find(|b| b.id == id).unwrap();
        if at_frame {
            projection_at(&frames, id, t_frame_s).x
        } else {
            b.u_px
        }
    };
    let skew_px = (u_of(12, false) - u_of(0, false)) - (u_of(12, true) - u_of(0, true));
    assert!(skew_px.abs() > 2.0, "skew {skew_px} px");
    eprintln!(
        "rolling, bright: worst centroid error {:.4} px, skew across the grid {skew_px:.2} px",
        worst_error_px(&frame, &blobs, Prepare::Bright)
    );
}

#[test]
fn a_rolling_shutter_follows_fast_rotation_too() {
    // The random scenario: up to 1.5 m/s and 4 rad/s, the target tilting and turning while the rows are read.
    let scenario = Scenario::new(ScenarioKind::Random, 2);
    let options = FrameOptions {
        readout: Readout::RollingShutter {
            line_delay_s: LINE_DELAY_S,
        },
        frame_count: Some(100),
        ..FrameOptions::default()
    };
    let mut frames = FrameSequence::new(&scenario, &options).unwrap();
    let mut frame = Frame::default();
    let mut worst: f64 = 0.0;
    let mut measured = 0;
    for k in (0..100).step_by(11) {
        frames.render(k, &mut frame);
        let blobs = frames.true_blob_centres(k);
        assert_eq!(blobs.len(), 16, "frame {k}");
        worst = worst.max(worst_error_px(&frame, &blobs, Prepare::Bright));
        measured += blobs.len();
    }
    assert!(worst < 0.15, "{worst} px");
    eprintln!(
        "random scenario, rolling, bright: worst centroid error {worst:.4} px over {measured} blobs"
    );
}

#[test]
fn a_global_shutter_shows_every_blob_at_the_frame_time() {
    let (frames, frame) = frame_at_speed(Readout::GlobalShutter, Polarity::Bright);
    let t_frame_s = frames.frame_time_s(0);
    assert_eq!(frame.t_s, t_frame_s);
    let blobs = frames.true_blob_centres(0);
    assert_eq!(blobs.len(), 16);
    for b in &blobs {
        assert_eq!(b.t_s, t_frame_s);
        assert!(
            (projection_at(&frames, b.id, t_frame_s) - Vector2::new(b.u_px, b.v_px)).norm() < 0.05
        );
    }
    let worst = worst_error_px(&frame, &blobs, Prepare::Bright);
    assert!(worst < 0.15, "{worst} px");
    eprintln!("global, bright: worst centroid error {worst:.4} px");
}

#[test]
fn dark_blobs_on_uneven_light_are_measured_at_their_row_time() {
    for readout in [
        Readout::GlobalShutter,
        Readout::RollingShutter {
            line_delay_s: LINE_DELAY_S,
        },
    ] {
        let (frames, frame) = frame_at_speed(readout, Polarity::Dark);
        let blobs = frames.true_blob_centres(0);
        assert_eq!(blobs.len(), 16);
        // Inverted, a blob's centroid leans towards the lit side where the light slopes across it (by up to 0.1 px on
        // the shadow's flank); flat-fielded, it does not: the image is right, the lean is the light's.
        let inverted = worst_error_px(&frame, &blobs, Prepare::Inverted);
        let flat = worst_error_px(&frame, &blobs, Prepare::FlatFielded);
        assert!(inverted < 0.2, "{readout:?}: {inverted} px");
        assert!(flat < 0.05, "{readout:?}: {flat} px");
        eprintln!(
            "{readout:?}, dark: worst centroid error {inverted:.4} px inverted, {flat:.4} px flat-fielded"
        );
        // Each blob is a quarter or so of the light around it.
        for b in &blobs {
            let (i, j) = (b.u_px.round() as i64, b.v_px.round() as i64);
            let mean = |di: std::ops::RangeInclusive<i64>, dj: std::ops::RangeInclusive<i64>| {
                let mut sum = 0.0;
                let mut n = 0.0;
                for y in dj.clone() {
                    for x in di.clone() {
                        sum += f64::from(frame.pixels[frame.index((i + x) as u32, (j + y) as u32)]);
                        n += 1.0;
                    }
                }
                sum / n
            };
            let core = mean(-1..=1, -1..=1);
            let around = 0.5 * (mean(-19..=-17, -1..=1) + mean(17..=19, -1..=1));
            let ratio = core / around;
            assert!((0.18..0.35).contains(&ratio), "blob {}: {ratio}", b.id);
        }
    }
    // The light is uneven: the corners differ by about 2x.
    let (_, frame) = frame_at_speed(Readout::GlobalShutter, Polarity::Dark);
    let corner = |i0: u32, j0: u32| {
        let mut sum = 0.0;
        for j in j0..j0 + 32 {
            for i in i0..i0 + 32 {
                sum += f64::from(frame.pixels[frame.index(i, j)]);
            }
        }
        sum / 1024.0
    };
    let far = frame.width - 32;
    let corners = [
        corner(0, 0),
        corner(far, 0),
        corner(0, far),
        corner(far, far),
    ];
    let (lo, hi) = corners
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &c| (lo.min(c), hi.max(c)));
    assert!(hi / lo > 1.5, "corners {corners:?}");
    let max = frame.pixels.iter().copied().max().unwrap();
    assert!(max < 255, "saturated: {max}");
    eprintln!("dark corners (DN): {corners:?}, ratio {:.2}", hi / lo);
}

#[test]
fn a_frame_does_not_depend_on_what_was_rendered_before() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    for polarity in [Polarity::Bright, Polarity::Dark] {
        let options = FrameOptions {
            readout: Readout::RollingShutter {
                line_delay_s: LINE_DELAY_S,
            },
            polarity,
            seed: 7,
            ..FrameOptions::default()
        };
        let mut frames = FrameSequence::new(&scenario, &options).unwrap();
        let (mut first, mut other, mut again) =
            (Frame::default(), Frame::default(), Frame::default());
        frames.render(5, &mut first);
        frames.render(5, &mut again);
        assert_eq!(first, again);
        frames.render(9, &mut other);
        frames.render(5, &mut again);
        assert_eq!(first, again);
        let mut fresh = FrameSequence::new(&scenario, &options).unwrap();
        fresh.render(5, &mut again);
        assert_eq!(first, again);
        assert_eq!(first.t_s, 5.0 / 30.0);
        // Frames 0 and 1 see the target at rest, but with their own noise.
        frames.render(0, &mut first);
        frames.render(1, &mut other);
        assert_ne!(first.pixels, other.pixels);
        // Another seed, other noise.
        let mut reseeded =
            FrameSequence::new(&scenario, &FrameOptions { seed: 8, ..options }).unwrap();
        reseeded.render(0, &mut other);
        assert_ne!(first.pixels, other.pixels);
    }
}

#[test]
fn impossible_sequences_are_refused() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let refuse = |options: FrameOptions| FrameSequence::new(&scenario, &options).unwrap_err();
    // 1024 rows at 31 µs (31.7 ms) and a 2 ms exposure do not fit in 33.3 ms.
    let slow = refuse(FrameOptions {
        readout: Readout::RollingShutter {
            line_delay_s: 31e-6,
        },
        exposure_s: 2e-3,
        ..FrameOptions::default()
    });
    assert!(
        matches!(slow, FrameSequenceError::ReadoutTooLong { rows: 1024, .. }),
        "{slow:?}"
    );
    let message = slow.to_string();
    for number in ["1024 rows", "0.031744 s", "0.002 s", "30 Hz"] {
        assert!(message.contains(number), "{message}");
    }
    assert!(
        FrameSequence::new(
            &scenario,
            &FrameOptions {
                readout: Readout::RollingShutter {
                    line_delay_s: 31e-6
                },
                ..FrameOptions::default()
            }
        )
        .is_ok()
    );
    for fps_hz in [0.0, -30.0, f64::NAN, f64::INFINITY] {
        let error = refuse(FrameOptions {
            fps_hz,
            ..FrameOptions::default()
        });
        assert!(
            matches!(error, FrameSequenceError::FrameRate { .. }),
            "{error:?}"
        );
    }
    assert_eq!(
        refuse(FrameOptions {
            readout: Readout::SequentialRois,
            ..FrameOptions::default()
        }),
        FrameSequenceError::SequentialRois
    );
    assert_eq!(
        refuse(FrameOptions {
            exposure_s: -1e-3,
            ..FrameOptions::default()
        }),
        FrameSequenceError::TimeModel(TimeModelError::Exposure(-1e-3))
    );
    assert!(matches!(
        refuse(FrameOptions {
            exposure_s: 0.05,
            ..FrameOptions::default()
        }),
        FrameSequenceError::ExposureTooLong { .. }
    ));
    assert!(matches!(
        refuse(FrameOptions {
            frame_count: Some(0),
            ..FrameOptions::default()
        }),
        FrameSequenceError::NoFrames { .. }
    ));
    assert!(matches!(
        refuse(FrameOptions {
            start_s: 10.0,
            ..FrameOptions::default()
        }),
        FrameSequenceError::NoFrames { .. }
    ));
    let mut bad_sensor = FrameOptions::default();
    bad_sensor.sensor.bit_depth = 17;
    assert!(matches!(refuse(bad_sensor), FrameSequenceError::Sensor(_)));
    // A zero exposure is allowed (no motion blur).
    let sharp = FrameOptions {
        exposure_s: 0.0,
        ..FrameOptions::default()
    };
    assert!(FrameSequence::new(&scenario, &sharp).is_ok());
}

#[test]
fn the_camera_carries_the_time_model_and_the_span_fits_the_scenario() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let readout = Readout::RollingShutter {
        line_delay_s: LINE_DELAY_S,
    };
    let options = FrameOptions {
        readout,
        exposure_s: 2e-3,
        ..FrameOptions::default()
    };
    let frames = FrameSequence::new(&scenario, &options).unwrap();
    assert_eq!(frames.camera().time.readout, readout);
    assert_eq!(frames.camera().time.exposure_s, 2e-3);
    assert_eq!(frames.camera().intrinsics, scenario.camera.intrinsics);
    // Every frame's last row is exposed by the scenario's end, and one more frame would not be.
    let (start, end) = frames.span_s();
    assert_eq!(start, 0.0);
    assert!(end <= scenario.duration_s && end + 1.0 / 30.0 > scenario.duration_s);
    assert_eq!(frames.len(), 147);
    assert!((frames.frame_time_s(146) - 146.0 / 30.0).abs() < 1e-12);
}

#[test]
fn truth_samples_cover_the_span_and_are_the_scenarios() {
    for kind in [ScenarioKind::Orthoglide, ScenarioKind::Random] {
        let scenario = Scenario::new(kind, 3);
        let options = FrameOptions {
            readout: Readout::RollingShutter {
                line_delay_s: LINE_DELAY_S,
            },
            start_s: 0.25,
            frame_count: Some(40),
            ..FrameOptions::default()
        };
        let frames = FrameSequence::new(&scenario, &options).unwrap();
        let truth = frames.truth_samples(DEFAULT_TRUTH_RATE_HZ).unwrap();
        let (start, end) = frames.span_s();
        assert_eq!(start, 0.25);
        assert!((end - (0.25 + 39.0 / 30.0 + 1023.0 * LINE_DELAY_S)).abs() < 1e-12);
        assert_eq!(truth.poses.len(), truth.twists.len());
        assert_eq!(truth.poses[0].t_s, start);
        assert_eq!(truth.poses.last().unwrap().t_s, end);
        for w in truth.poses.windows(2) {
            let dt = w[1].t_s - w[0].t_s;
            assert!(
                dt > 0.0 && dt <= 1.0 / DEFAULT_TRUTH_RATE_HZ + 1e-12,
                "{dt}"
            );
        }
        for k in 0..frames.len() {
            let t = frames.frame_time_s(k);
            assert!(
                truth.poses.iter().any(|p| (p.t_s - t).abs() < 1e-9),
                "frame {k}"
            );
        }
        for (pose, twist) in truth.poses.iter().zip(&truth.twists) {
            let state = scenario.state_at(pose.t_s);
            assert_eq!(pose.t_s, twist.t_s);
            assert_eq!(pose.cam_from_obj, state.cam_from_obj());
            assert_eq!(twist.velocity_mps, state.velocity_mps);
            assert_eq!(twist.angular_velocity_radps, state.angular_velocity_radps);
        }
        // Interpolated between samples, the truth is within a micrometre and a microradian anywhere in the span.
        let (mut worst_m, mut worst_rad): (f64, f64) = (0.0, 0.0);
        for w in truth.poses.windows(2) {
            let s = 0.37;
            let t = w[0].t_s + s * (w[1].t_s - w[0].t_s);
            let position = w[0]
                .cam_from_obj
                .translation
                .vector
                .lerp(&w[1].cam_from_obj.translation.vector, s);
            let rotation = w[0]
                .cam_from_obj
                .rotation
                .slerp(&w[1].cam_from_obj.rotation, s);
            let state = scenario.state_at(t);
            worst_m = worst_m.max((position - state.cam_t_obj_m).norm());
            let r = rotation.to_rotation_matrix() * state.cam_r_obj.inverse();
            worst_rad = worst_rad.max(so3::log(&r).norm());
        }
        assert!(
            worst_m < 1e-6 && worst_rad < 1e-6,
            "{kind:?}: {worst_m} m, {worst_rad} rad"
        );
    }
    let frames = FrameSequence::new(
        &Scenario::new(ScenarioKind::Static, 1),
        &FrameOptions::default(),
    )
    .unwrap();
    assert_eq!(
        frames.truth_samples(0.0).unwrap_err(),
        FrameSequenceError::TruthRate { rate_hz: 0.0 }
    );
}

/// The rendering speed on the whole orthoglide scenario at 30 fps (run with `--ignored --nocapture` in release).
#[test]
#[ignore = "a measurement: takes tens of seconds"]
fn rendering_speed_on_the_whole_orthoglide() {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let rolling = Readout::RollingShutter {
        line_delay_s: LINE_DELAY_S,
    };
    for (readout, polarity) in [
        (Readout::GlobalShutter, Polarity::Bright),
        (rolling, Polarity::Bright),
        (Readout::GlobalShutter, Polarity::Dark),
        (rolling, Polarity::Dark),
    ] {
        let options = FrameOptions {
            readout,
            polarity,
            ..FrameOptions::default()
        };
        let mut frames = FrameSequence::new(&scenario, &options).unwrap();
        let mut frame = Frame::default();
        let start = Instant::now();
        for k in 0..frames.len() {
            frames.render(k, &mut frame);
        }
        let elapsed = start.elapsed().as_secs_f64();
        eprintln!(
            "{readout:?} {}: {} frames in {elapsed:.2} s, {:.1} ms a frame",
            polarity.name(),
            frames.len(),
            1e3 * elapsed / frames.len() as f64
        );
    }
}
