//! Specular glints painted onto a rendered frame: the sun on leaves, water and chrome outdoors, which give the bright
//! polarity of a photograph of dark printed circles many small blobs (and its lattices by chance).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_image::Frame;

/// Least distance (px) of a glint from every circle centre given: glints beside the target, not on it.
const CLEAR_OF_CIRCLES_PX: f64 = 30.0;

/// Adds `count` small saturated spots (1.5 to 4 px in radius, a 1 px soft edge) to `frame`, each at least 30 px from
/// every point of `circles_px` and 8 px from the border, placed by `seed`.
///
/// ```
/// use roitrack_image::Frame;
/// use roitrack_sim::glints::add_glints;
///
/// let mut frame = Frame::new(320, 240, 8);
/// add_glints(&mut frame, &[(160.0, 120.0)], 20, 1);
/// assert!(frame.pixels.iter().any(|&p| p == 255));
/// // Nothing near the circle.
/// assert_eq!(frame.pixels[120 * 320 + 160], 0);
/// ```
pub fn add_glints(frame: &mut Frame, circles_px: &[(f64, f64)], count: usize, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let full = f64::from((1u32 << frame.bit_depth) - 1);
    let (w, h) = (frame.width as usize, frame.height as usize);
    let mut placed = 0;
    while placed < count {
        let (u, v) = (
            rng.random_range(8.0..w as f64 - 8.0),
            rng.random_range(8.0..h as f64 - 8.0),
        );
        let r = rng.random_range(1.5..4.0);
        if circles_px
            .iter()
            .any(|&(cu, cv)| (cu - u).hypot(cv - v) < CLEAR_OF_CIRCLES_PX)
        {
            continue;
        }
        placed += 1;
        for j in (v - r - 2.0) as usize..=(v + r + 2.0) as usize {
            for i in (u - r - 2.0) as usize..=(u + r + 2.0) as usize {
                let weight = (r + 1.0 - (i as f64 - u).hypot(j as f64 - v)).clamp(0.0, 1.0);
                let p = &mut frame.pixels[j * w + i];
                *p = (f64::from(*p) + weight * (full - f64::from(*p))).round() as u16;
            }
        }
    }
}
