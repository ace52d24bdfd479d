//! One module per subcommand.

pub mod bench;
pub mod compare;
pub mod demo;
pub mod eval;
pub mod pnp_bench;
pub mod simulate;
pub mod target;
pub mod track;
pub mod tradeoff;
