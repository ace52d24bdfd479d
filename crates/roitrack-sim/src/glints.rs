//! Specular glints painted onto a rendered frame: the sun on leaves, water and chrome outdoors, which give the bright
//! polarity of a photograph of dark printed circles many small blobs (and its lattices by chance).

use crate::photo::RenderedPhoto;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Least distance (px) of a glint from every circle centre given: glints beside the target, not on it.
const CLEAR_OF_CIRCLES_PX: f64 = 30.0;

/// Adds `count` small saturated spots (1.5 to 4 px in radius, a 1 px soft edge) to `photo`'s frame, each at least
/// 30 px from the true centre of every circle seen and 8 px from the border, placed by `seed`.
///
/// ```
/// use nalgebra::Rotation3;
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_sim::glints::add_glints;
/// use roitrack_sim::photo::{PhotoScene, render_photo};
///
/// let scene = PhotoScene::facing(CameraModel::canonical(), Target::grid4x4(), 0.6, Rotation3::identity());
/// let mut photo = render_photo(&scene).unwrap();
/// let before = photo.frame.pixels.clone();
/// add_glints(&mut photo, 20, 1);
/// assert_ne!(photo.frame.pixels, before);
/// // Nothing on a circle.
/// let centre = photo.truth[5].centre_px.unwrap();
/// let at = |pixels: &[u16]| pixels[centre.y.round() as usize * 1024 + centre.x.round() as usize];
/// assert_eq!(at(&photo.frame.pixels), at(&before));
/// ```
pub fn add_glints(photo: &mut RenderedPhoto, count: usize, seed: u64) {
    let circles_px: Vec<(f64, f64)> = photo
        .truth
        .iter()
        .filter_map(|p| p.centre_px.map(|c| (c.x, c.y)))
        .collect();
    let frame = &mut photo.frame;
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
