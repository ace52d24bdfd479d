//! The sweep harness in quick mode: what must hold whatever the default estimator does (the targets themselves are
//! the estimator's job, and are not asserted here).

use roitrack_experiments::adaptive::{Goal, Purpose, SweepError, SweepOptions, cases, sweep};

#[test]
fn every_case_keeps_its_blobs_in_the_image_and_simulates() {
    for case in cases() {
        for &seed in &case.seeds {
            let scenario = case.scenario(seed);
            let margin = scenario.min_image_margin_px();
            assert!(margin > 0.0, "{}: margin {margin} px", case.name);
        }
    }
    let all = cases();
    let names: Vec<&str> = all.iter().map(|c| c.name).collect();
    let mut unique = names.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), names.len(), "case names are unique");
    // The calibration set: every built-in scenario but the sweep, at four noise levels.
    let calibration: Vec<_> = all.iter().filter(|c| c.in_calibration_set).collect();
    assert_eq!(calibration.len(), 16);
    for noise_px in [0.03, 0.1, 0.3, 1.0] {
        assert_eq!(
            calibration
                .iter()
                .filter(|c| c.noise_px == noise_px)
                .count(),
            4
        );
    }
}

#[test]
fn the_quick_sweep_measures_honestly() {
    let options = SweepOptions::quick();
    let result = sweep(&options, None).unwrap();
    assert_eq!(result.cases.len(), options.cases.len());
    for (r, case) in result.cases.iter().zip(&options.cases) {
        assert_eq!(r.case.name, case.name, "cases in the options' order");
        let name = case.name;
        let d = &r.default;
        if d.runs_without_estimates > 0 {
            // The default filter never initialised: every target fails, and the figures say so.
            assert!(case.goals().iter().all(|&g| !r.holds(g)), "{name}");
            assert!(d.position_rmse_mm.is_nan(), "{name}");
            continue;
        }
        assert!(d.estimates > 0, "{name}");
        assert_eq!(
            d.converging + d.tracking + d.degenerate + d.disputed + d.lost,
            d.estimates,
            "{name}"
        );
        assert_eq!(
            d.consistency.count + d.consistency.skipped,
            d.estimates,
            "{name}"
        );
        assert!(d.position_rmse_mm > 0.0, "{name}");
        assert_eq!(
            d.max_vouched_error_mm.is_finite(),
            d.converging + d.tracking > 0,
            "{name}"
        );
        // A hand-tuned filter works with the noise it is told: the told-the-truth one with the true noise.
        let truth = &r.told_truth;
        assert!(
            (truth.summary.mean_noise_px - case.noise_px).abs() < 1e-12,
            "{name}: {}",
            truth.summary.mean_noise_px
        );
        assert_eq!(
            (
                truth.tuning.noise_factor,
                truth.tuning.linear_accel_psd,
                truth.tuning.angular_accel_psd
            ),
            (1.0, 1.0, 10.0),
            "{name}"
        );
        match case.purpose {
            Purpose::Calibration => {
                assert!(r.best.is_none() && r.nominal_mm.is_none() && r.beyond_bound.is_none());
                assert_eq!(r.visited.len(), 1, "{name}: the told-the-truth run alone");
            }
            Purpose::Accuracy => {
                let best = r.best.as_ref().unwrap();
                // The search runs the grid's default point: the best is at most it, and at most every point run.
                assert!(
                    best.summary.position_rmse_mm <= truth.summary.position_rmse_mm,
                    "{name}"
                );
                // (A setting that never started on some seed is no candidate: its RMSE is over the other seeds.)
                for v in r.visited.iter().filter(|v| v.runs_without_estimates == 0) {
                    assert!(
                        best.summary.position_rmse_mm <= v.position_rmse_mm,
                        "{name}"
                    );
                }
                assert!(r.visited.iter().any(|v| v.tuning == best.tuning));
                assert!(r.visited.len() >= 5, "{name}: the coarse stage at least");
                assert_eq!(r.nominal_mm, Some(best.summary.position_rmse_mm));
                assert!(r.beyond_bound.unwrap() <= d.converging + d.tracking);
                let ratio = d.position_rmse_mm / best.summary.position_rmse_mm;
                assert!((r.rmse_ratio() - ratio).abs() < 1e-12);
                assert_eq!(r.holds(Goal::Rmse), ratio <= 1.2);
            }
        }
    }
    // The told-the-truth filter on orthoglide at 0.1 px: its covariance is about right for the position.
    let ortho = result
        .cases
        .iter()
        .find(|r| r.case.name == "4 kHz, 0.1 px")
        .unwrap();
    let c = &ortho.told_truth.summary.consistency;
    assert!(c.count > 100, "{c:?}");
    assert!(
        (0.5..=2.0).contains(&c.position_nees_per_dof) && c.position_inside_99 >= 0.95,
        "{c:?}"
    );
    // Its twist covariance is calibrated against the estimates' own history (velocity NEES / 3 was 0.26 before).
    assert!(
        (0.5..=2.0).contains(&c.velocity_nees_per_dof) && c.velocity_inside_99 >= 0.95,
        "{c:?}"
    );
    // So is the default filter's, on this case and on the still target far away.
    for name in ["4 kHz, 0.1 px", "still 1.6 m"] {
        let r = result.cases.iter().find(|r| r.case.name == name).unwrap();
        let c = &r.default.consistency;
        assert!(
            (0.5..=2.0).contains(&c.velocity_nees_per_dof) && c.velocity_inside_99 >= 0.95,
            "{name}: {c:?}"
        );
    }
    // Every check is one target of one case, and the failures are the checks that do not hold.
    let checks = result.checks();
    let goals: usize = result.cases.iter().map(|r| r.case.goals().len()).sum();
    assert_eq!(checks.len(), goals);
    assert_eq!(
        result.failures().len(),
        checks.iter().filter(|c| !c.holds).count()
    );
    // The table has a row per accuracy case, the calibration table one per case of the set.
    let markdown = result.markdown();
    let rows = |header: &str| {
        markdown
            .split(header)
            .nth(1)
            .unwrap()
            .lines()
            .skip(2)
            .take_while(|l| l.starts_with('|'))
            .count()
    };
    let accuracy = options
        .cases
        .iter()
        .filter(|c| c.purpose == Purpose::Accuracy)
        .count();
    let calibration = options
        .cases
        .iter()
        .filter(|c| c.in_calibration_set)
        .count();
    assert_eq!(rows("| case |"), accuracy);
    assert_eq!(rows("| scene |"), calibration);
    assert_eq!(rows("| target |"), Goal::ALL.len());
    let json: serde_json::Value = serde_json::from_str(&result.json()).unwrap();
    assert_eq!(json["cases"].as_array().unwrap().len(), options.cases.len());
    assert_eq!(json["holds"], result.failures().is_empty());
}

#[test]
fn the_figures_do_not_depend_on_the_number_of_threads() {
    let mut options = SweepOptions::quick();
    options
        .cases
        .retain(|c| c.name == "static, 0.3 px" || c.name == "2x3 target");
    options.max_duration_s = Some(0.3);
    let one = sweep(
        &SweepOptions {
            threads: 1,
            ..options.clone()
        },
        None,
    )
    .unwrap();
    let two = sweep(
        &SweepOptions {
            threads: 2,
            ..options
        },
        None,
    )
    .unwrap();
    for (a, b) in one.cases.iter().zip(&two.cases) {
        assert_eq!(a.case.name, b.case.name);
        assert_eq!(a.default.position_rmse_mm, b.default.position_rmse_mm);
        assert_eq!(a.visited.len(), b.visited.len());
    }
    assert_eq!(one.markdown(), two.markdown());
}

#[test]
fn other_seeds_are_simulated_and_pooled() {
    let mut options = SweepOptions::quick();
    options.cases.retain(|c| c.name == "static, 0.3 px");
    options.max_duration_s = Some(0.3);
    let one = sweep(&options.clone().with_seeds(&[2]), None).unwrap();
    let two = sweep(&options.clone().with_seeds(&[2, 3]), None).unwrap();
    let (one, two) = (&one.cases[0].default, &two.cases[0].default);
    // Two seeds: twice the estimates, and another RMSE (the second seed's noise is another draw).
    assert_eq!(two.estimates, 2 * one.estimates);
    assert_ne!(two.position_rmse_mm, one.position_rmse_mm);
    assert!(matches!(
        sweep(&options.with_seeds(&[]), None),
        Err(SweepError::NoSeeds {
            case: "static, 0.3 px"
        })
    ));
}
