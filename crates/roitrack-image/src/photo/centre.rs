//! Sub-pixel blob centres from grey levels: background-corrected first-order moments in an elliptical window.
//!
//! The binary centre of a thresholded component moves by whole pixels as pixels cross the threshold, and the
//! threshold's place on a blurred edge depends on the light. The grey-level moments of `value - background` over a
//! window that holds the whole blurred blob do not: blur and the optics' point spread preserve the centroid of the
//! light, so the weighted centroid is the centroid of the disk's image (its area centroid), whatever the blur. The
//! background is measured in a ring around the window (a low percentile, so that a neighbouring circle reaching into
//! the ring does not raise it), and the window, an ellipse of the blob's own shape grown by a margin, can be
//! recentred on the estimate and the moments taken again, so that what it cuts of the blur's tails is cut
//! symmetrically (the photo detector takes one pass: the outline's ellipse refines it).

use crate::background::fit_plane;

/// The blob's shape as thresholding saw it: centre (px) and the semi-axes (px) and orientation of the ellipse with
/// its second moments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Ellipse {
    pub u_px: f64,
    pub v_px: f64,
    pub semi_major_px: f64,
    pub semi_minor_px: f64,
    /// Angle of the major axis from the u axis (rad).
    pub angle_rad: f64,
}

impl Ellipse {
    /// The ellipse with the central second moments (μ_uu, μ_vv, μ_uv) of a filled ellipse (a filled ellipse of
    /// semi-axes a, b has moments a²/4 and b²/4 along its axes).
    pub fn from_moments(u_px: f64, v_px: f64, (uu, vv, uv): (f64, f64, f64)) -> Self {
        let (l1, l2) = principal_moments((uu, vv, uv));
        let l2 = l2.max(0.0);
        Self {
            u_px,
            v_px,
            semi_major_px: 2.0 * l1.sqrt(),
            semi_minor_px: 2.0 * l2.sqrt(),
            angle_rad: 0.5 * (2.0 * uv).atan2(uu - vv),
        }
    }

    /// The area of the ellipse (px²).
    pub fn area_px(&self) -> f64 {
        std::f64::consts::PI * self.semi_major_px * self.semi_minor_px
    }

    /// The ellipse grown by `grow_px` on both axes, as a distance function.
    fn grown(&self, grow_px: f64) -> GrownEllipse {
        let (sin, cos) = self.angle_rad.sin_cos();
        let (a, b) = (self.semi_major_px + grow_px, self.semi_minor_px + grow_px);
        GrownEllipse {
            cos,
            sin,
            inv_a2: 1.0 / (a * a),
            inv_b2: 1.0 / (b * b),
        }
    }
}

/// An ellipse about the origin, to test points against.
#[derive(Debug, Clone, Copy)]
struct GrownEllipse {
    cos: f64,
    sin: f64,
    inv_a2: f64,
    inv_b2: f64,
}

impl GrownEllipse {
    /// The columns of row `j` inside the ellipse centred on (u0, v0), clamped to `0..width` (empty if none).
    fn columns(&self, u0: f64, v0: f64, j: usize, width: usize) -> std::ops::Range<usize> {
        // x²/a² + y²/b² <= 1 with (x, y) the rotated (du, dv) is p du² + 2 q dv du + r dv² <= 1.
        let (c, s) = (self.cos, self.sin);
        let p = c * c * self.inv_a2 + s * s * self.inv_b2;
        let q = c * s * (self.inv_a2 - self.inv_b2);
        let r = s * s * self.inv_a2 + c * c * self.inv_b2;
        let dv = j as f64 - v0;
        let disc = q * q * dv * dv - p * (r * dv * dv - 1.0);
        if disc < 0.0 {
            return 0..0;
        }
        let half = disc.sqrt() / p;
        let mid = u0 - q * dv / p;
        let lo = (mid - half).ceil().max(0.0);
        let hi = (mid + half).floor() + 1.0;
        if hi <= lo {
            return 0..0;
        }
        (lo as usize).min(width)..(hi as usize).min(width)
    }
}

/// The larger and smaller principal second moments (px²) of central moments (μ_uu, μ_vv, μ_uv).
pub(crate) fn principal_moments((uu, vv, uv): (f64, f64, f64)) -> (f64, f64) {
    let mean = 0.5 * (uu + vv);
    let spread = (0.25 * (uu - vv).powi(2) + uv * uv).sqrt();
    (mean + spread, mean - spread)
}

/// Result of the grey-level measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GreyCentre {
    pub u_px: f64,
    pub v_px: f64,
    /// Background level (DN, in the polarity-corrected image).
    pub background: f64,
    /// The blob's contrast: the brightest window pixel above the background (DN).
    pub contrast: f64,
}

/// Percentile of the ring's values taken as the first estimate of the background.
const BACKGROUND_PERCENTILE: f64 = 0.35;

/// The background as a plane around the window's centre: `level + slope_u du + slope_v dv` (DN).
#[derive(Debug, Clone, Copy)]
struct Background {
    level: f64,
    slope_u: f64,
    slope_v: f64,
}

impl Background {
    fn at(&self, du: f64, dv: f64) -> f64 {
        self.level + self.slope_u * du + self.slope_v * dv
    }
}

/// The background plane from the ring's pixels `(du, dv, value)`: first a low percentile (a neighbouring blob
/// reaching into the ring must not raise it), then least-squares planes through the pixels not far above the
/// previous estimate, so that a gradient of light is followed and neighbours are left out.
fn fit_background(ring: &mut [(f64, f64, f64)]) -> Option<Background> {
    if ring.len() < 8 {
        return None;
    }
    let k = ((ring.len() - 1) as f64 * BACKGROUND_PERCENTILE).round() as usize;
    let (_, &mut (_, _, level), _) = ring.select_nth_unstable_by(k, |a, b| a.2.total_cmp(&b.2));
    // The spread of the values below the percentile: noise, the plane's tilt across the ring.
    let floor = ring[..k].iter().map(|p| level - p.2).fold(0.0, f64::max);
    let mut plane = Background {
        level,
        slope_u: 0.0,
        slope_v: 0.0,
    };
    for _ in 0..2 {
        let gate = 2.0 * floor + 2.0;
        let below_gate = |&(du, dv, value): &(f64, f64, f64)| value - plane.at(du, dv) <= gate;
        if ring.iter().filter(|p| below_gate(p)).count() < 8 {
            break;
        }
        let Some([level, slope_u, slope_v]) = fit_plane(ring.iter().copied().filter(below_gate))
        else {
            break;
        };
        plane = Background {
            level,
            slope_u,
            slope_v,
        };
    }
    Some(plane)
}

/// The grey-level centre of `shape` in a row-major image where blobs are bright (values above the background).
/// For dark blobs (inverted images) `light_full_scale` is the inversion's full scale: weights are then relative to
/// the local light. `scratch` holds the ring's pixels between calls. `None` if the window leaves the image or has no positive weight.
pub(crate) fn grey_centre(
    pixels: &[u16],
    width: usize,
    height: usize,
    shape: &Ellipse,
    light_full_scale: Option<u16>,
    passes: usize,
    scratch: &mut Vec<(f64, f64, f64)>,
) -> Option<GreyCentre> {
    // The window must take the blurred edge (a pixel or two) but stay clear of neighbours in dense grids, whose gap
    // can be a fraction of a radius.
    let margin_px = (0.25 * shape.semi_minor_px + 0.75).clamp(1.0, 3.0);
    let ring_px = (0.25 * shape.semi_minor_px).clamp(1.5, 3.0);
    let reach = shape.semi_major_px + margin_px + ring_px + 1.0;
    let window = shape.grown(margin_px);
    let outer = shape.grown(margin_px + ring_px);
    let mut centre = (shape.u_px, shape.v_px);
    let mut result = None;
    // The window on the threshold's centre, then `passes - 1` times recentred.
    for _ in 0..passes {
        let (u0, v0) = centre;
        let (i_lo, i_hi) = ((u0 - reach).floor(), (u0 + reach).ceil());
        let (j_lo, j_hi) = ((v0 - reach).floor(), (v0 + reach).ceil());
        if i_lo < 0.0 || j_lo < 0.0 || i_hi >= width as f64 || j_hi >= height as f64 {
            return None;
        }
        let (j_lo, j_hi) = (j_lo as usize, j_hi as usize);
        scratch.clear();
        for j in j_lo..=j_hi {
            let dv = j as f64 - v0;
            let row = &pixels[j * width..(j + 1) * width];
            let inner = window.columns(u0, v0, j, width);
            let ring = outer.columns(u0, v0, j, width);
            for i in ring.clone().filter(|i| !inner.contains(i)) {
                scratch.push((i as f64 - u0, dv, f64::from(row[i])));
            }
        }
        let background = fit_background(scratch)?;
        let (mut sw, mut su, mut sv, mut peak) = (0.0, 0.0, 0.0, f64::NEG_INFINITY);
        let full = light_full_scale.map(f64::from);
        for j in j_lo..=j_hi {
            let dv = j as f64 - v0;
            let row = &pixels[j * width..(j + 1) * width];
            let (mut rw, mut ru) = (0.0, 0.0);
            for i in window.columns(u0, v0, j, width) {
                let du = i as f64 - u0;
                let b = background.at(du, dv);
                let mut w = f64::from(row[i]) - b;
                peak = peak.max(w);
                if let Some(full) = full {
                    // Printed ink absorbs a fraction of the light that falls on it: divide by the local light so
                    // that a gradient of light across the blob does not pull its centre.
                    w /= (full - b).max(1.0);
                }
                rw += w;
                ru += w * du;
            }
            sw += rw;
            su += ru;
            sv += rw * dv;
        }
        if sw <= 0.0 || peak <= 0.0 {
            return None;
        }
        let next = (u0 + su / sw, v0 + sv / sw);
        let moved = (next.0 - u0).hypot(next.1 - v0);
        // The window may recentre by at most a pixel or so from the threshold's estimate; a larger jump means the
        // weights are not this blob's (a neighbour or a gradient dominates).
        if (next.0 - shape.u_px).hypot(next.1 - shape.v_px) > 0.5 * shape.semi_minor_px + 1.0 {
            return None;
        }
        centre = next;
        result = Some(GreyCentre {
            u_px: next.0,
            v_px: next.1,
            background: background.at(next.0 - u0, next.1 - v0),
            contrast: peak,
        });
        if moved < 1e-3 {
            break;
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disk of radius `r` at (cu, cv), value `hi` on `lo`, area coverage by 16 x 16 supersampling.
    fn disk(w: usize, h: usize, cu: f64, cv: f64, r: f64, lo: f64, hi: f64) -> Vec<u16> {
        let mut img = vec![0u16; w * h];
        for j in 0..h {
            for i in 0..w {
                let mut inside = 0;
                for sj in 0..16 {
                    for si in 0..16 {
                        let x = i as f64 - 0.5 + (si as f64 + 0.5) / 16.0;
                        let y = j as f64 - 0.5 + (sj as f64 + 0.5) / 16.0;
                        if (x - cu).powi(2) + (y - cv).powi(2) <= r * r {
                            inside += 1;
                        }
                    }
                }
                let c = f64::from(inside) / 256.0;
                img[j * w + i] = (lo + c * (hi - lo)).round() as u16;
            }
        }
        img
    }

    #[test]
    fn exact_on_a_sampled_disk_at_sub_pixel_positions() {
        let mut scratch = Vec::new();
        for (k, r) in [2.5, 4.0, 7.3, 12.0].into_iter().enumerate() {
            let (cu, cv) = (20.0 + 0.13 * k as f64, 21.0 - 0.37 * k as f64);
            let img = disk(44, 44, cu, cv, r, 40.0, 3000.0);
            // A threshold's estimate, off by a few tenths.
            let shape = Ellipse {
                u_px: cu.round(),
                v_px: cv.round() + 0.3,
                semi_major_px: r,
                semi_minor_px: r,
                angle_rad: 0.0,
            };
            let c = grey_centre(&img, 44, 44, &shape, None, 3, &mut scratch).unwrap();
            let err = (c.u_px - cu).hypot(c.v_px - cv);
            assert!(err < 0.01, "radius {r}: error {err} px");
            assert!((c.background - 40.0).abs() < 1e-9);
        }
    }

    #[test]
    fn ellipse_from_moments_of_a_rotated_ellipse() {
        let (a, b, th) = (6.0f64, 2.0f64, 0.4f64);
        let (c, s) = (th.cos(), th.sin());
        let (la, lb) = (a * a / 4.0, b * b / 4.0);
        let uu = c * c * la + s * s * lb;
        let vv = s * s * la + c * c * lb;
        let uv = c * s * (la - lb);
        let e = Ellipse::from_moments(1.0, 2.0, (uu, vv, uv));
        assert!((e.semi_major_px - a).abs() < 1e-12 && (e.semi_minor_px - b).abs() < 1e-12);
        assert!((e.angle_rad - th).abs() < 1e-12);
    }

    #[test]
    fn refuses_a_window_off_the_image() {
        let img = disk(20, 20, 3.0, 10.0, 3.0, 10.0, 200.0);
        let shape = Ellipse {
            u_px: 3.0,
            v_px: 10.0,
            semi_major_px: 3.0,
            semi_minor_px: 3.0,
            angle_rad: 0.0,
        };
        assert!(grey_centre(&img, 20, 20, &shape, None, 2, &mut Vec::new()).is_none());
    }
}
