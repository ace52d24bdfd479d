//! The lab's commands (`roitrack lab ...`, the feature `lab`), end to end: `cargo test --release -p roitrack-cli
//! --features lab --test lab` (scripts/test runs it).

#[path = "../common/mod.rs"]
mod common;
#[path = "../common/rig.rs"]
mod rig;
#[path = "../common/venv.rs"]
mod venv;

mod bench;
mod compare;
mod faults;
mod frame_study;
mod own_rig;
mod pnp_bench;
mod soak;
