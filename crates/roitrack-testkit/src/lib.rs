//! # roitrack-testkit
//!
//! What the tests of every roitrack crate share, defined once:
//!
//! - [`jacobian`]: the Jacobian checker, central differences at identity, near identity and random states, with one
//!   step and tolerance rule;
//! - [`alloc`]: the counting allocator of the allocation tests, per thread and in all.
//!
//! A dev-dependency only, and it depends on no roitrack crate (only nalgebra and rand), so that every crate's tests,
//! roitrack-core's included, can use it without a cycle.
#![deny(missing_docs)]

pub mod alloc;
pub mod jacobian;

pub use jacobian::check_jacobian;

/// The random number generators `check_jacobian`'s `draw` is given, for crates that have no rand of their own.
pub use rand;
pub use rand_chacha;
