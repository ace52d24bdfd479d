//! What the tests of this crate and of the crates built on it share (feature `test-support`).

use nalgebra::{Rotation3, Vector3};

use crate::MotionState;

/// A state `spread` from rest at 0.6 m on the axis (1: rotations up to 0.6 rad, 2 m/s, 30 rad/s), drawn from `rng`.
///
/// ```
/// use rand::SeedableRng;
///
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
/// let state = roitrack_core::test_support::drawn_state(&mut rng, 1.0);
/// assert!((state.cam_t_obj_m.z - 0.6).abs() <= 0.05);
/// ```
pub fn drawn_state(rng: &mut rand_chacha::ChaCha8Rng, spread: f64) -> MotionState {
    use rand::Rng;
    let mut v3 = |m: f64| {
        spread
            * Vector3::new(
                rng.random_range(-m..m),
                rng.random_range(-m..m),
                rng.random_range(-m..m),
            )
    };
    MotionState {
        cam_r_obj: Rotation3::new(v3(0.6)),
        cam_t_obj_m: Vector3::new(0.0, 0.0, 0.6) + v3(0.05),
        velocity_mps: v3(2.0),
        angular_velocity_radps: v3(30.0),
    }
}
