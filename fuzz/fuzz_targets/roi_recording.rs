//! The streaming ROI recording reader on arbitrary bytes, every record read: an `Ok` or an error naming the file,
//! never a panic, a hang or an allocation driven by a corrupt size field.
#![no_main]
use libfuzzer_sys::fuzz_target;
use roitrack_formats::RoiRecordingReader;

fuzz_target!(|data: &[u8]| {
    let result = RoiRecordingReader::from_reader(data, "r.bin")
        .and_then(|r| r.collect::<Result<Vec<_>, _>>());
    if let Err(e) = result {
        assert!(e.to_string().starts_with("r.bin"), "{e}");
    }
});
