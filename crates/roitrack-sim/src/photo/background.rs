//! What lies outside the board: a flat level or a random value-noise texture ([`Background`]), with the clutter
//! drawn on it.

use super::PhotoError;
use super::clutter::draw_clutter;
use super::rays::Area;
use super::scene::{PhotoScene, check, unit};

/// Mixed into the seed of the background texture's hash.
const TEXTURE_SALT: u64 = 0x7e57_u64 << 40;

/// What lies behind the board, seen wherever the board is not (levels: fractions of full scale under unit light).
///
/// ```
/// use roitrack_sim::photo::Background;
/// let busy = Background::Texture { mean_level: 0.4, contrast: 0.3, scale_px: 30.0 };
/// assert_ne!(busy, Background::default());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Background {
    /// One flat level.
    Uniform {
        /// The level (fraction of full scale under unit light).
        level: f64,
    },
    /// A smooth random pattern (fractal value noise, four octaves from `scale_px` down): `mean_level` ± at most
    /// `contrast`, clipped to 0..1.
    Texture {
        /// The pattern's mean level (fraction of full scale under unit light).
        mean_level: f64,
        /// The most the pattern departs from its mean (fraction of full scale).
        contrast: f64,
        /// Size of the pattern's coarsest features (px).
        scale_px: f64,
    },
}

impl Default for Background {
    /// A flat mid-dark grey, 0.32.
    fn default() -> Self {
        Self::Uniform { level: 0.32 }
    }
}

impl Background {
    /// Levels within 0..1, a positive texture scale.
    pub(super) fn check(&self) -> Result<(), PhotoError> {
        match *self {
            Background::Uniform { level } => unit("background level", level)?,
            Background::Texture {
                mean_level,
                contrast,
                scale_px,
            } => {
                unit("background mean_level", mean_level)?;
                unit("background contrast", contrast)?;
                check(
                    "background scale_px",
                    scale_px,
                    scale_px > 0.0 && scale_px.is_finite(),
                    "positive",
                )?;
            }
        }
        Ok(())
    }
}

/// The background's level at every pixel of the area: the texture or flat level, with the clutter drawn on it.
pub(super) fn background_layer(
    scene: &PhotoScene,
    area: &Area,
    background_fraction: &[f64],
) -> Vec<f64> {
    let n = area.width * area.height;
    let mut layer = match scene.background {
        Background::Uniform { level } => vec![level; n],
        Background::Texture {
            mean_level,
            contrast,
            scale_px,
        } => texture_layer(
            scene.seed,
            area,
            background_fraction,
            (mean_level, contrast, scale_px),
        ),
    };
    if scene.clutter.count > 0 {
        draw_clutter(scene, area, background_fraction, &mut layer);
    }
    layer
}

/// The value-noise texture of mean `mean_level`, `contrast` and feature size `scale_px` at the pixels of the area
/// where the background shows (`background_fraction` above 0), `mean_level` elsewhere.
fn texture_layer(
    seed: u64,
    area: &Area,
    background_fraction: &[f64],
    (mean_level, contrast, scale_px): (f64, f64, f64),
) -> Vec<f64> {
    let n = area.width * area.height;
    let mut layer = vec![mean_level; n];
    let octaves: Vec<NoiseOctave> = (0..4)
        .map(|o| NoiseOctave::new(seed ^ TEXTURE_SALT, o, scale_px, area))
        .collect();
    let norm: f64 = octaves.iter().map(|o| o.amplitude).sum();
    for j in 0..area.height {
        for i in 0..area.width {
            let k = j * area.width + i;
            if background_fraction[k] > 0.0 {
                let sum: f64 = octaves.iter().map(|o| o.at(i, j)).sum();
                // Value noise rarely reaches its extremes: stretch it, then clip.
                let noise = (2.0 * sum / norm).clamp(-1.0, 1.0);
                layer[k] = (mean_level + contrast * noise).clamp(0.0, 1.0);
            }
        }
    }
    layer
}

/// One octave of the background's fractal value noise over the area: random values (-1..1) on a lattice of
/// `scale_px / 2^octave` pixels (amplitude `2^-octave`), smoothly interpolated; the lattice cell and weights of every
/// column and row are computed once.
struct NoiseOctave {
    amplitude: f64,
    /// Lattice column (from the first) and smoothed weight of each area column; the same for rows.
    cols: Vec<(usize, f64)>,
    rows: Vec<(usize, f64)>,
    pub(super) nx: usize,
    values: Vec<f64>,
}

impl NoiseOctave {
    pub(super) fn new(seed: u64, octave: u32, scale_px: f64, area: &Area) -> Self {
        let frequency = f64::from(1u32 << octave) / scale_px;
        let cells = |n: usize| -> (i64, Vec<(usize, f64)>) {
            let raw: Vec<(i64, f64)> = (0..n)
                .map(|i| {
                    let x = area.raw(i) * frequency;
                    let f = x.floor();
                    let t = x - f;
                    (f as i64, t * t * (3.0 - 2.0 * t))
                })
                .collect();
            let first = raw[0].0;
            (
                first,
                raw.into_iter()
                    .map(|(c, s)| ((c - first) as usize, s))
                    .collect(),
            )
        };
        let (ix0, cols) = cells(area.width);
        let (iy0, rows) = cells(area.height);
        let nx = cols.last().map_or(0, |c| c.0) + 2;
        let ny = rows.last().map_or(0, |r| r.0) + 2;
        let octave_seed = seed.wrapping_add(u64::from(octave));
        let values = (0..ny as i64)
            .flat_map(|y| (0..nx as i64).map(move |x| (x, y)))
            .map(|(x, y)| lattice_value(octave_seed, ix0 + x, iy0 + y))
            .collect();
        Self {
            amplitude: 0.5f64.powi(octave as i32),
            cols,
            rows,
            nx,
            values,
        }
    }

    /// The octave's contribution (amplitude included) at area pixel (i, j).
    #[inline]
    fn at(&self, i: usize, j: usize) -> f64 {
        let (x, sx) = self.cols[i];
        let (y, sy) = self.rows[j];
        let k = y * self.nx + x;
        let v = &self.values;
        let top = v[k] + (v[k + 1] - v[k]) * sx;
        let bottom = v[k + self.nx] + (v[k + self.nx + 1] - v[k + self.nx]) * sx;
        self.amplitude * (top + (bottom - top) * sy)
    }
}

fn lattice_value(seed: u64, i: i64, j: i64) -> f64 {
    let mut z = seed
        ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    // splitmix64's finaliser.
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}
