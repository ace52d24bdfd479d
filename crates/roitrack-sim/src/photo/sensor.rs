//! The sensor: blur, read and shot noise, and the JPEG-like quantisation of a compressed photograph.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::NOISE_STREAM;
use super::rays::Area;
use super::scene::PhotoScene;

/// Separable blur of the area, cropped to the `w` x `h` image.
pub(super) fn blur(radiance: &[f64], area: &Area, kernel: &[f64], w: usize, h: usize) -> Vec<f64> {
    let m = area.margin;
    // Horizontal pass: the image's columns, every row of the area.
    let mut rows = vec![0.0; area.height * w];
    for j in 0..area.height {
        let src = &radiance[j * area.width..(j + 1) * area.width];
        for (i, out) in rows[j * w..(j + 1) * w].iter_mut().enumerate() {
            *out = kernel
                .iter()
                .zip(&src[i..i + kernel.len()])
                .map(|(k, x)| k * x)
                .sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for (t, &weight) in kernel.iter().enumerate() {
        for j in 0..h {
            let src = &rows[(j + t) * w..(j + t + 1) * w];
            for (o, &x) in out[j * w..(j + 1) * w].iter_mut().zip(src) {
                *o += weight * x;
            }
        }
    }
    debug_assert_eq!(kernel.len(), 2 * m + 1);
    out
}

/// Read and shot noise, drawn in row-major order from the scene's noise stream.
pub(super) fn add_noise(values: &mut [f64], scene: &PhotoScene) {
    if scene.noise_sigma == 0.0 && scene.shot_noise_full_well_e.is_none() {
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed);
    rng.set_stream(NOISE_STREAM);
    let read2 = scene.noise_sigma * scene.noise_sigma;
    let inv_full_well = scene.shot_noise_full_well_e.map_or(0.0, |fw| 1.0 / fw);
    for x in values.iter_mut() {
        let sigma = (read2 + x.max(0.0) * inv_full_well).sqrt();
        let z: f64 = rng.sample(StandardNormal);
        *x += sigma * z;
    }
}

/// `x` rounded to the nearest integer (ties to even) for |x| < 2^51, in two additions (`f64::round` is a library
/// call on baseline x86-64).
#[inline]
fn round_fast(x: f64) -> f64 {
    const SHIFT: f64 = 6_755_399_441_055_744.0; // 1.5 * 2^52
    (x + SHIFT) - SHIFT
}

/// The standard JPEG luminance quantisation table (ITU T.81, Annex K), row-major.
const JPEG_LUMINANCE: [f64; 64] = [
    16., 11., 10., 16., 24., 40., 51., 61., 12., 12., 14., 19., 26., 58., 60., 55., 14., 13., 16.,
    24., 40., 57., 69., 56., 14., 17., 22., 29., 51., 87., 80., 62., 18., 22., 37., 56., 68., 109.,
    103., 77., 24., 35., 55., 64., 81., 104., 113., 92., 49., 64., 78., 87., 103., 121., 120.,
    101., 72., 92., 95., 98., 112., 100., 103., 99.,
];

/// JPEG-like compression of the image (values in 0..1): 8-bit levels, 8 x 8 blocks (edge blocks padded by
/// repeating the last row and column), orthonormal DCT (JPEG's scaling), coefficients quantised with the luminance
/// table at `quality`, and back.
pub(super) fn jpeg_like(values: &mut [f64], w: usize, h: usize, quality: u8) {
    let quality = f64::from(quality.clamp(1, 100));
    let scale = if quality < 50.0 {
        5000.0 / quality
    } else {
        200.0 - 2.0 * quality
    };
    let table: Vec<f64> = JPEG_LUMINANCE
        .iter()
        .map(|q| ((q * scale + 50.0) / 100.0).floor().clamp(1.0, 255.0))
        .collect();
    let mut basis = [[0.0; 8]; 8];
    for (u, row) in basis.iter_mut().enumerate() {
        let c = if u == 0 { (0.125f64).sqrt() } else { 0.5 };
        for (x, b) in row.iter_mut().enumerate() {
            *b = c * ((2 * x + 1) as f64 * u as f64 * std::f64::consts::PI / 16.0).cos();
        }
    }
    let mut block = [[0.0; 8]; 8];
    let mut tmp = [[0.0; 8]; 8];
    for by in (0..h).step_by(8) {
        for bx in (0..w).step_by(8) {
            for (y, row) in block.iter_mut().enumerate() {
                for (x, b) in row.iter_mut().enumerate() {
                    let v = values[(by + y).min(h - 1) * w + (bx + x).min(w - 1)];
                    *b = round_fast((v * 255.0).clamp(0.0, 255.0)) - 128.0;
                }
            }
            // Forward: F = B X Bᵀ; quantise; inverse: X = Bᵀ F B.
            for u in 0..8 {
                for x in 0..8 {
                    tmp[u][x] = (0..8).map(|y| basis[u][y] * block[y][x]).sum();
                }
            }
            for u in 0..8 {
                for v in 0..8 {
                    let f: f64 = (0..8).map(|x| tmp[u][x] * basis[v][x]).sum();
                    let q = table[u * 8 + v];
                    block[u][v] = round_fast(f / q) * q;
                }
            }
            for y in 0..8 {
                for v in 0..8 {
                    tmp[y][v] = (0..8).map(|u| basis[u][y] * block[u][v]).sum();
                }
            }
            for y in 0..8.min(h - by) {
                for x in 0..8.min(w - bx) {
                    let f: f64 = (0..8).map(|v| tmp[y][v] * basis[v][x]).sum();
                    values[(by + y) * w + bx + x] =
                        round_fast((f + 128.0).clamp(0.0, 255.0)) / 255.0;
                }
            }
        }
    }
}
