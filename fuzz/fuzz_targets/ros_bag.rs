//! The ROS 2 bag reader (roitrack_ros::BagFrameSource) on arbitrary bytes: the camera info and every frame of the
//! image topic read: frames or an error naming the bag, never a panic, a hang or an allocation driven by a corrupt
//! size field.
//!
//! The reader runs mcap's chunk decoding under `catch_unwind` (mcap 0.26 panics on some corrupt records) and turns
//! such a panic into an error naming the bag. libFuzzer's panic hook aborts on every panic, caught or not, so this
//! target puts the standard hook back: a panic the reader catches is then what the reader makes of it (an error,
//! checked below), and a panic it does not catch still unwinds out of the target, which libFuzzer counts as a crash.
#![no_main]
use libfuzzer_sys::fuzz_target;
use roitrack_image::Frame;
use roitrack_ros::BagFrameSource;

static STANDARD_PANIC_HOOK: std::sync::Once = std::sync::Once::new();

fuzz_target!(|data: &[u8]| {
    STANDARD_PANIC_HOOK.call_once(|| {
        let _ = std::panic::take_hook();
    });
    let check = |e: roitrack_formats::FormatError| {
        assert!(e.to_string().starts_with("b.mcap"), "{e}");
    };
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
