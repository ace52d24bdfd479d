//! The streaming measurements CSV reader on arbitrary bytes, every record read: an `Ok` or an error naming the file,
//! never a panic or a hang.
#![no_main]
use libfuzzer_sys::fuzz_target;
use roitrack_formats::MeasurementReader;

fuzz_target!(|data: &[u8]| {
    let result = MeasurementReader::from_reader(data, "m.csv")
        .and_then(|r| r.with_known_ids(0..16).collect::<Result<Vec<_>, _>>());
    if let Err(e) = result {
        assert!(e.to_string().starts_with("m.csv"), "{e}");
    }
});
