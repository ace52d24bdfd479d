//! `roitrack lab frame-study` on a few frames: its table, its checks and its JSON.

use crate::common::{fails, ok};

#[test]
fn frame_study_prints_the_table_the_checks_and_json() {
    let args = [
        "lab",
        "frame-study",
        "--seeds",
        "1",
        "--frame-count",
        "8",
        "--threads",
        "2",
    ];
    let markdown = ok(&args);
    assert!(markdown.contains("| sequence | model |"), "{markdown}");
    for row in [
        "| global shutter, bright | global |",
        "| rolling shutter, bright | rolling |",
        "| rolling shutter, bright | global |",
        "| global shutter, dark | global |",
        "| rolling shutter, dark | rolling |",
    ] {
        assert!(markdown.contains(row), "{row} missing: {markdown}");
    }
    assert!(markdown.contains("| target | figure |"));
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let json: serde_json::Value = serde_json::from_str(&ok(&json_args)).unwrap();
    assert_eq!(json["rows"].as_array().unwrap().len(), 6);
    assert_eq!(json["checks"].as_array().unwrap().len(), 8);
    assert_eq!(json["frames_per_sequence"], 8);
    assert!(
        json["rows"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r["estimates"] == 8)
    );
    let stderr = fails(&["lab", "frame-study", "--seeds", "0"]);
    assert!(stderr.contains("--seeds"), "{stderr}");
}
