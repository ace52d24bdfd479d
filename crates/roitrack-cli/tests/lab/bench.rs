//! `roitrack lab bench --json`: the loop's figures (with the fake camera's: tests/live.rs).

use crate::common::ok;

fn f(v: &serde_json::Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"))
}

#[test]
fn bench_prints_the_loop_figures_as_json() {
    let out = ok(&["lab", "bench", "--json", "--rois", "2000", "--repeats", "1"]);
    let m: serde_json::Value = serde_json::from_str(&out).unwrap();
    for key in [
        "loop_k10_rois_per_s",
        "loop_k1_rois_per_s",
        "latency_us_p50",
        "latency_us_p99",
        "kalman_update_us_median",
        "kalman_update_us_p99",
        "estimate_handle_read_ns_median",
        "estimate_handle_read_ns_p99",
        "rig4_meas_per_s",
        "rig4_running_meas_per_s",
    ] {
        assert!(f(&m, key) > 0.0, "{key} in {m}");
    }
    assert_eq!(m["loop_k10_dropped"].as_u64(), Some(0));
}
