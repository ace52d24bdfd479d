//! The live loop through Aravis' fake GigE Vision camera on 127.0.0.1 (feature `genicam`). Only one fake camera can
//! own 127.0.0.1: the tests take turns (a lock here; CI also runs them with one test thread).
#![cfg(feature = "genicam")]

use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::AtomicBool;

use roitrack_genicam::{LiveOptions, run_fake};
use roitrack_sim::{Scenario, ScenarioKind};

static ONE_FAKE_CAMERA: Mutex<()> = Mutex::new(());

#[test]
fn smoke() {
    let _turn = ONE_FAKE_CAMERA.lock().unwrap_or_else(|e| e.into_inner());
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let options = LiveOptions {
        duration_s: 0.5,
        ..LiveOptions::default()
    };
    let report = run_fake(
        &scenario,
        &options,
        1,
        Arc::new(AtomicBool::new(false)),
        |_| {},
    )
    .unwrap();
    println!("{}", report.summary());
}
