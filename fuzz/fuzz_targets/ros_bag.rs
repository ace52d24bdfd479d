//! The ROS 2 bag readers (roitrack_ros::BagFrameSource, BagMeasurementSource) on arbitrary bytes: the camera info,
//! every frame of the image topic and every measurement of the measurement topic read: frames, measurements or an
//! error naming the bag, never a panic, a hang or an allocation driven by a corrupt size field.
//!
//! The reader runs mcap's chunk decoding under `catch_unwind` (mcap 0.26 panics on some corrupt records) and turns
//! such a panic into an error naming the bag. libFuzzer's panic hook aborts on every panic, caught or not, so this
//! target puts the standard hook back: a panic the reader catches is then what the reader makes of it (an error,
//! checked below), and a panic it does not catch still unwinds out of the target, which libFuzzer counts as a crash.
#![no_main]
use libfuzzer_sys::fuzz_target;
use roitrack_image::Frame;
use roitrack_ros::{BagFrameSource, BagMeasurementSource};

static STANDARD_PANIC_HOOK: std::sync::Once = std::sync::Once::new();

fuzz_target!(|data: &[u8]| {
    STANDARD_PANIC_HOOK.call_once(|| {
        let _ = std::panic::take_hook();
    });
    let check = |e: roitrack_formats::FormatError| {
        assert!(e.to_string().starts_with("b.mcap"), "{e}");
    };
    match BagMeasurementSource::from_bytes("b.mcap", data.to_vec(), "/roitrack/measurements") {
        Err(e) => check(e),
        Ok(source) => {
            for m in source.with_known_ids([1, 2, 3]).with_image_size(640, 480) {
                match m {
                    Ok(m) => assert!(m.t_s.is_finite() && m.u_px.is_finite() && m.v_px.is_finite()),
                    Err(e) => check(e),
                }
            }
        }
    }
    match BagFrameSource::from_bytes("b.mcap", data.to_vec(), "/roitrack/image") {
        Err(e) => check(e),
        Ok(mut source) => {
            if let Err(e) = source.camera_info("/roitrack/camera_info") {
                check(e);
            }
            let mut frame = Frame::default();
            while let Some(info) = source.next_frame(&mut frame) {
                if let Err(e) = info {
                    check(e);
                }
            }
        }
    }
});
