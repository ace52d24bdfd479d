//! `roitrack lab compare --sweep --quick`: the sweep table's shape, its JSON, `--check` and the options it refuses. The
//! targets themselves are the estimator's job: these tests pass whether they hold or not.

use crate::common::{fails, ok, roitrack};

#[test]
fn the_quick_sweep_prints_its_tables_and_json_and_check_names_the_failures() {
    let markdown = ok(&["lab", "compare", "--sweep", "--quick"]);
    assert!(markdown.starts_with("Quick mode"), "{markdown}");
    // The accuracy table: a header, a rule and one row per accuracy case, each with 13 cells.
    let table: Vec<&str> = markdown
        .lines()
        .skip_while(|l| !l.starts_with("| case |"))
        .take_while(|l| l.starts_with('|'))
        .collect();
    assert!(table.len() > 2, "{markdown}");
    for line in &table {
        assert_eq!(line.matches('|').count(), 14, "{line}");
    }
    assert!(
        table[2..]
            .iter()
            .any(|l| l.starts_with("| 4 kHz, 0.1 px |"))
    );
    for header in ["| scene | noise px |", "| target | what |"] {
        assert!(markdown.contains(header), "{header} in {markdown}");
    }
    assert!(markdown.contains("checks hold") || markdown.contains("checks do not hold"));

    let json: serde_json::Value =
        serde_json::from_str(ok(&["lab", "compare", "--sweep", "--quick", "--json"]).trim())
            .unwrap();
    let cases = json["cases"].as_array().unwrap();
    assert_eq!(
        cases.len(),
        table.len() - 2 + 2,
        "5 accuracy and 2 calibration cases"
    );
    for case in cases {
        assert!(case["default"]["position_rmse_mm"].as_f64().unwrap() > 0.0);
        assert!(
            case["told_truth"]["summary"]["consistency"]["count"]
                .as_u64()
                .unwrap()
                > 0
        );
    }
    let failures: Vec<&str> = json["failures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    assert_eq!(json["holds"].as_bool().unwrap(), failures.is_empty());

    // --check fails exactly when a target does not hold, naming each failure.
    let checked = roitrack(&["lab", "compare", "--sweep", "--quick", "--check"]);
    let stderr = String::from_utf8_lossy(&checked.stderr);
    assert_eq!(checked.status.success(), failures.is_empty(), "{stderr}");
    for failure in &failures {
        assert!(stderr.contains(failure), "{failure} not in {stderr}");
    }
}

#[test]
fn options_that_do_not_apply_are_refused() {
    for args in [
        &["lab", "compare", "--sweep", "--scenario", "spin"][..],
        &["lab", "compare", "--sweep", "--noise-px", "0.3"],
        &["lab", "compare", "--sweep", "--seed", "2"],
        &["lab", "compare", "--quick"],
        &["lab", "compare", "--check"],
    ] {
        let stderr = fails(args);
        assert!(
            stderr.contains("cannot be used with") || stderr.contains("required"),
            "{args:?}: {stderr}"
        );
    }
}
