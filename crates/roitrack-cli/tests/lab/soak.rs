//! `roitrack lab soak`: a long run stays flat.

#[test]
fn soak_run_has_flat_memory_error_and_time() {
    // 30 s of 4 kHz stream (the full 10-minute soak is `roitrack lab soak`, about 10 s).
    let stdout = crate::common::ok(&["lab", "soak", "--minutes", "0.5", "--json"]);
    let m: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(m["lost"].as_u64(), Some(0), "{m}");
    assert!(m["memory_growth_mib"].as_f64().unwrap().abs() < 1.0, "{m}");
    let errors = m["position_rmse_mm"].as_array().unwrap();
    assert!(errors.iter().all(|e| e.as_f64().unwrap() < 0.5), "{m}");
}
