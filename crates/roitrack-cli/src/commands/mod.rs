//! One module per subcommand.

pub mod bench;
pub mod compare;
pub mod demo;
pub mod detect;
pub mod eval;
pub mod faults;
pub mod frame_study;
#[cfg(feature = "genicam")]
pub mod live;
pub mod plot;
pub mod pnp_bench;
pub mod simulate;
pub mod soak;
pub mod target;
pub mod track;
pub mod tradeoff;
