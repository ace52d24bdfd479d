//! What the randomised photograph tests (key_dot.rs, nominal_files.rs) share: how a random view of a target is drawn.

use nalgebra::Rotation3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use roitrack_sim::photo::CircleShade;

/// A random view's tilt (up to 0.5 rad about x and y, any turn about z) and its circles' shade (bright on dark or
/// dark on light, even odds), drawn from `rng` in that order.
pub fn random_tilt_and_shade(rng: &mut ChaCha8Rng) -> (Rotation3<f64>, CircleShade) {
    let tilt = Rotation3::from_euler_angles(
        rng.random_range(-0.5..0.5),
        rng.random_range(-0.5..0.5),
        rng.random_range(-3.1..3.1),
    );
    let shade = if rng.random_bool(0.5) {
        CircleShade::BrightOnDark
    } else {
        CircleShade::DarkOnLight
    };
    (tilt, shade)
}
