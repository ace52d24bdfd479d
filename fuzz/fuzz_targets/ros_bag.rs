//! The ROS 2 bag reader (roitrack_ros::BagFrameSource) on arbitrary bytes: the camera info and every frame of the
//! image topic read: frames or an error naming the bag, never a panic, a hang or an allocation driven by a corrupt
//! size field.
#![no_main]
use libfuzzer_sys::fuzz_target;
use roitrack_image::Frame;
use roitrack_ros::BagFrameSource;

fuzz_target!(|data: &[u8]| {
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
