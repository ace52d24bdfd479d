//! The bag readers on damaged input: a valid bag of image frames and of their measured centroids (written by
//! roitrack's own writer), truncated at every length of a sample and with bytes changed at random, read from start to
//! end by the frame reader and by the measurement reader. Every outcome must be frames and measurements or an error
//! naming the bag and the topic; never a panic, never a hang.

use roitrack_core::{CameraModel, Measurement};
use roitrack_image::Frame;
use roitrack_ros::{BagFrameSource, BagMeasurementSource, BagOptions, BagWriter};

fn valid_bag() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frames.mcap");
    let mut camera = CameraModel::canonical();
    camera.width_px = 32;
    camera.height_px = 24;
    // One chunk (about 14 KB of frames), its indexes and the summary: damage lands in each of them.
    let mut bag = BagWriter::create(&path, &BagOptions::default(), Some(camera)).unwrap();
    for k in 0..12u16 {
        let mut frame = Frame::new(32, 24, if k % 2 == 0 { 8 } else { 12 });
        for (i, p) in frame.pixels.iter_mut().enumerate() {
            *p = (i as u16 * 7 + k) % 200;
        }
        frame.t_s = 0.1 * f64::from(k);
        let measured: Vec<Measurement> = (0..3)
            .map(|i| Measurement {
                t_s: frame.t_s,
                id: i + 1,
                u_px: 4.0 + 8.0 * f64::from(i),
                v_px: 12.5,
            })
            .collect();
        bag.write_frame(&frame, None, &measured).unwrap();
        bag.write_measurements(&measured).unwrap();
    }
    bag.finish().unwrap();
    std::fs::read(&path).unwrap()
}

/// Reads every frame of the topic, then every measurement; the number of frames read, or the first error's text.
fn read_all(bytes: Vec<u8>) -> Result<usize, String> {
    let mut source = BagFrameSource::from_bytes("damaged.mcap", bytes.clone(), "/roitrack/image")
        .map_err(|e| e.to_string())?;
    let _ = source.camera_info("/roitrack/camera_info");
    let mut frame = Frame::default();
    let mut count = 0;
    while let Some(info) = source.next_frame(&mut frame) {
        info.map_err(|e| e.to_string())?;
        count += 1;
        assert!(count <= 12, "more frames than were written");
    }
    let source = BagMeasurementSource::from_bytes("damaged.mcap", bytes, "/roitrack/measurements")
        .map_err(|e| e.to_string())?;
    let mut measurements = 0;
    for m in source.with_known_ids([1, 2, 3]) {
        let m = m.map_err(|e| e.to_string())?;
        assert!(m.t_s.is_finite() && m.u_px.is_finite() && m.v_px.is_finite());
        measurements += 1;
        assert!(measurements <= 36, "more measurements than were written");
    }
    Ok(count + measurements)
}

fn check_error(error: &str) {
    assert!(
        error.starts_with("damaged.mcap"),
        "the error does not name the bag: {error}"
    );
}

#[test]
fn the_valid_bag_reads_back() {
    assert_eq!(read_all(valid_bag()), Ok(12 + 36));
}

#[test]
fn truncated_bags_are_refused_naming_the_bag() {
    let bytes = valid_bag();
    for length in (0..bytes.len()).step_by(7) {
        match read_all(bytes[..length].to_vec()) {
            Ok(count) => panic!("truncated at {length} of {}: {count} frames", bytes.len()),
            Err(e) => check_error(&e),
        }
    }
}

#[test]
fn bags_with_damaged_bytes_give_frames_or_an_error_never_a_panic() {
    let bytes = valid_bag();
    // A small deterministic generator (xorshift): the same damage on every run.
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for _ in 0..2000 {
        let mut damaged = bytes.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() % damaged.len() as u64) as usize;
            damaged[at] = next() as u8;
        }
        if let Err(e) = read_all(damaged) {
            check_error(&e);
        }
    }
}

/// Found by the fuzz target `ros_bag`: a chunk index whose offset and length overflow, on which mcap 0.26's
/// `Summary::stream_chunk` panics; the reader checks the index first.
#[test]
fn a_chunk_index_pointing_outside_the_file_is_an_error() {
    let bytes = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/chunk_index_overflow.mcap"
    ))
    .unwrap();
    match read_all(bytes) {
        Ok(count) => panic!("{count} frames from a corrupt bag"),
        Err(e) => {
            check_error(&e);
            assert!(e.contains("outside the file"), "{e}");
        }
    }
}

/// Found by the fuzz target `ros_bag` in CI: a chunk whose message record is shorter than its fields, on which mcap
/// 0.26's linear reader panics (a slice out of range) while streaming the chunk; the reader catches it and names the
/// bag.
#[test]
fn a_chunk_record_shorter_than_its_fields_is_an_error() {
    let bytes = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/chunk_record_short_field.mcap"
    ))
    .unwrap();
    if let Err(e) = read_all(bytes) {
        check_error(&e);
    }
}
