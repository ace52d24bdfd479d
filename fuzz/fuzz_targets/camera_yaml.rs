//! The camera YAML reader on arbitrary bytes: an `Ok` or an error naming the file, never a panic or a hang.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Err(e) = roitrack_formats::parse_camera_yaml(&text, "c.yaml") {
        assert!(e.to_string().starts_with("c.yaml"), "{e}");
    }
});
