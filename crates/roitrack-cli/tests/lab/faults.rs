//! The `roitrack lab faults` table (the fault flags of `simulate` it is made of: tests/faults.rs).

use crate::common::ok;

#[test]
fn faults_json_reports_every_row() {
    let stdout = ok(&["lab", "faults", "--json", "--quick"]);
    let rows: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let faults: Vec<&str> = rows.iter().map(|r| r["fault"].as_str().unwrap()).collect();
    assert_eq!(
        faults,
        [
            "clean",
            "burst 40 ROIs lost",
            "jump 20 mm in x",
            "4 blobs leave image 0.4 s"
        ]
    );
    for r in &rows {
        assert_eq!(r["scenario"], "orthoglide");
        assert!(r["position_rmse_mm"].as_f64().unwrap() > 0.0);
        assert!(r["velocity_rmse_mm_s"].as_f64().unwrap() > 0.0);
        assert!(r["unflagged_wrong"].is_u64() && r["lost"].is_u64());
    }
    assert!(rows[0]["recovery_ms"].is_null() && rows[0]["fault_end_s"].is_null());
    assert!(rows[1]["recovery_ms"].as_f64().unwrap() >= 0.0);
    // The burst barely disturbs the clean run; the jump costs accuracy.
    let rmse = |r: &serde_json::Value| r["position_rmse_mm"].as_f64().unwrap();
    assert!(rmse(&rows[1]) < 2.0 * rmse(&rows[0]));
    assert!(rmse(&rows[2]) > rmse(&rows[0]));
    // The estimate that first sees the jump cannot tell it from an outlier: it is flagged (disputed), and no
    // estimate is wrong without a flag.
    assert!(rows[2]["flagged"].as_u64().unwrap() >= 1);
    // Blobs leaving the image and coming back: tracked throughout, recovered within 50 ms of the end.
    assert!(rmse(&rows[3]) < 1.5 * rmse(&rows[0]));
    assert!(rows[3]["recovery_ms"].as_f64().unwrap() <= 50.0);
    for r in &rows {
        assert_eq!(r["unflagged_wrong"], 0, "{}", r["fault"]);
    }
}
