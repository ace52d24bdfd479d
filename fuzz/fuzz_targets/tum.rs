//! The TUM trajectory reader on arbitrary bytes: an `Ok` or an error naming the file, never a panic or a hang.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(e) = roitrack_formats::parse_tum(data, "p.tum") {
        assert!(e.to_string().starts_with("p.tum"), "{e}");
    }
});
