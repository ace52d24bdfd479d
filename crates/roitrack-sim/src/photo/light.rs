//! The light on the scene: a gradient, vignetting, a soft-edged shadow and a glare spot ([`Illumination`]), and
//! its value at each pixel.

use nalgebra::Vector2;

use super::PhotoError;
use super::scene::{check, unit};

/// A shadow: light multiplied by `light_factor` inside a polygon of the image, with a soft edge.
///
/// ```
/// use nalgebra::Vector2;
/// use roitrack_sim::photo::Shadow;
/// // The left half of a 640 px wide image in shadow, 20 px penumbra.
/// let shadow = Shadow::half_plane(Vector2::new(320.0, 0.0), Vector2::new(-1.0, 0.0), 0.4, 20.0);
/// assert_eq!(shadow.polygon_px.len(), 4);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Shadow {
    /// Vertices (raw pixels) of a simple polygon, in either order.
    pub polygon_px: Vec<Vector2<f64>>,
    /// Light inside the shadow relative to outside (0..1).
    pub light_factor: f64,
    /// Width of the penumbra across the polygon's edge (px; under 1 px, a 1 px ramp).
    pub softness_px: f64,
}

impl Shadow {
    /// The half-plane on the side `into_shadow` points to of the line through `point_px` normal to it.
    pub fn half_plane(
        point_px: Vector2<f64>,
        into_shadow: Vector2<f64>,
        light_factor: f64,
        softness_px: f64,
    ) -> Self {
        let n = into_shadow.try_normalize(0.0).unwrap_or(Vector2::x());
        let t = Vector2::new(-n.y, n.x);
        let far = 1e6;
        Self {
            polygon_px: vec![
                point_px - far * t,
                point_px + far * t,
                point_px + far * t + far * n,
                point_px - far * t + far * n,
            ],
            light_factor,
            softness_px,
        }
    }

    /// Light factor at raw pixel `p`, with the polygon's edges from [`polygon_edges`].
    #[inline]
    fn factor_at(&self, edges: &[Edge], p: Vector2<f64>) -> f64 {
        let d = signed_distance_to_polygon(edges, p);
        let t = (0.5 - d / self.softness_px.max(1.0)).clamp(0.0, 1.0);
        let t = t * t * (3.0 - 2.0 * t);
        1.0 - (1.0 - self.light_factor) * t
    }
}

/// A glare spot: light added (a Gaussian of `radius_px` sigma, `level` of full scale at its centre) on top of the
/// reflected light, saturating what it crosses.
///
/// ```
/// use nalgebra::Vector2;
/// use roitrack_sim::photo::Glare;
/// let glare = Glare { centre_px: Vector2::new(400.0, 120.0), radius_px: 40.0, level: 0.3 };
/// assert!(glare.level > 0.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Glare {
    /// The spot's centre (raw pixel).
    pub centre_px: Vector2<f64>,
    /// The Gaussian's standard deviation (px).
    pub radius_px: f64,
    /// Light added at the centre (fraction of full scale).
    pub level: f64,
}

/// How the scene is lit. The default is uniform unit light (an image level is then the reflectance).
///
/// ```
/// use roitrack_sim::photo::Illumination;
/// let uneven = Illumination { gradient_min: 0.6, vignetting: 0.3, ..Illumination::default() };
/// assert!(uneven.shadow.is_none());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Illumination {
    /// Light on the dim side of a linear gradient across the image relative to the bright side (0..1; 1: no
    /// gradient).
    pub gradient_min: f64,
    /// Direction in the image along which the light grows (rad: 0 towards +u, π/2 towards +v).
    pub gradient_angle_rad: f64,
    /// Vignetting strength (0..1): light times `1 - s + s cos⁴θ`, θ the ray's angle off the optical axis.
    pub vignetting: f64,
    /// A soft-edged shadow over part of the image; `None`: none.
    pub shadow: Option<Shadow>,
    /// A glare spot added on top of the reflected light; `None`: none.
    pub glare: Option<Glare>,
}

impl Default for Illumination {
    fn default() -> Self {
        Self {
            gradient_min: 1.0,
            gradient_angle_rad: 0.0,
            vignetting: 0.0,
            shadow: None,
            glare: None,
        }
    }
}

impl Illumination {
    /// The gradient and vignetting within 0..1, a shadow polygon of finite vertices, a glare spot of positive size.
    pub(super) fn check(&self) -> Result<(), PhotoError> {
        unit("illumination.gradient_min", self.gradient_min)?;
        unit("illumination.vignetting", self.vignetting)?;
        if let Some(shadow) = &self.shadow {
            unit("shadow light_factor", shadow.light_factor)?;
            let s = shadow.softness_px;
            check(
                "shadow softness_px",
                s,
                (0.0..1e9).contains(&s),
                "0 or more",
            )?;
            let n = shadow.polygon_px.len() as f64;
            check("shadow polygon vertices", n, n >= 3.0, "3 or more")?;
            for p in &shadow.polygon_px {
                for value in [p.x, p.y] {
                    check("shadow polygon vertex", value, value.is_finite(), "finite")?;
                }
            }
        }
        if let Some(glare) = &self.glare {
            let g = glare;
            check(
                "glare radius_px",
                g.radius_px,
                g.radius_px > 0.0 && g.radius_px.is_finite(),
                "positive",
            )?;
            check(
                "glare level",
                g.level,
                (0.0..1e3).contains(&g.level),
                "0 or more",
            )?;
            for value in [g.centre_px.x, g.centre_px.y] {
                check("glare centre_px", value, value.is_finite(), "finite")?;
            }
        }
        Ok(())
    }
}

/// Lighting of the image: gradient, vignetting, shadow, glare.
pub(super) struct Light<'a> {
    pub(super) illumination: &'a Illumination,
    direction: Vector2<f64>,
    s0: f64,
    s_range: f64,
    shadow_edges: Vec<Edge>,
}

impl<'a> Light<'a> {
    pub(super) fn new(illumination: &'a Illumination, w: usize, h: usize) -> Self {
        let direction = Vector2::new(
            illumination.gradient_angle_rad.cos(),
            illumination.gradient_angle_rad.sin(),
        );
        let (w, h) = (w as f64 - 0.5, h as f64 - 0.5);
        let s: Vec<f64> = [(-0.5, -0.5), (w, -0.5), (-0.5, h), (w, h)]
            .iter()
            .map(|&(u, v)| direction.dot(&Vector2::new(u, v)))
            .collect();
        let s0 = s.iter().copied().fold(f64::MAX, f64::min);
        let s1 = s.iter().copied().fold(f64::MIN, f64::max);
        Self {
            illumination,
            direction,
            s0,
            s_range: (s1 - s0).max(1e-9),
            shadow_edges: illumination
                .shadow
                .as_ref()
                .map_or_else(Vec::new, |shadow| polygon_edges(&shadow.polygon_px)),
        }
    }

    /// Light factor at raw pixel (u, v), whose ray is `ray` (normalised).
    #[inline]
    pub(super) fn factor(&self, u: f64, v: f64, ray: [f64; 2]) -> f64 {
        let light = self.illumination;
        let mut f = 1.0;
        if light.gradient_min < 1.0 {
            // 0..1 over the image (a little beyond in the blur margin).
            let s = (self.direction.x * u + self.direction.y * v - self.s0) / self.s_range;
            f *= light.gradient_min + (1.0 - light.gradient_min) * s;
        }
        if light.vignetting > 0.0 {
            let cos2 = 1.0 / (1.0 + ray[0] * ray[0] + ray[1] * ray[1]);
            f *= 1.0 - light.vignetting + light.vignetting * cos2 * cos2;
        }
        if let Some(shadow) = &light.shadow {
            f *= shadow.factor_at(&self.shadow_edges, Vector2::new(u, v));
        }
        f
    }

    #[inline]
    pub(super) fn glare(&self, u: f64, v: f64) -> f64 {
        self.illumination.glare.map_or(0.0, |g| {
            let x2 = (u - g.centre_px.x).powi(2) + (v - g.centre_px.y).powi(2);
            let x2 = x2 / (2.0 * g.radius_px * g.radius_px);
            // Beyond 6.5 sigma the glare is under 1e-9 of its level: none.
            if x2 > 21.0 {
                0.0
            } else {
                g.level * (-x2).exp()
            }
        })
    }
}

/// A polygon's edge from `a` to `a + ab`, with `1 / |ab|²`.
#[derive(Debug, Clone, Copy)]
struct Edge {
    a: Vector2<f64>,
    ab: Vector2<f64>,
    inv_len2: f64,
}

/// The edges of a closed polygon.
fn polygon_edges(polygon: &[Vector2<f64>]) -> Vec<Edge> {
    (0..polygon.len())
        .map(|k| {
            let (a, b) = (polygon[k], polygon[(k + 1) % polygon.len()]);
            let ab = b - a;
            Edge {
                a,
                ab,
                inv_len2: 1.0 / ab.norm_squared().max(1e-300),
            }
        })
        .collect()
}

/// Signed distance from `p` to a simple polygon's boundary: negative inside (even-odd rule).
fn signed_distance_to_polygon(edges: &[Edge], p: Vector2<f64>) -> f64 {
    let mut distance2 = f64::MAX;
    let mut inside = false;
    for e in edges {
        let ap = p - e.a;
        let t = (ap.dot(&e.ab) * e.inv_len2).clamp(0.0, 1.0);
        distance2 = distance2.min((ap - t * e.ab).norm_squared());
        let b_y = e.a.y + e.ab.y;
        if (e.a.y > p.y) != (b_y > p.y) && ap.x * e.ab.y.abs() < ap.y * e.ab.x * e.ab.y.signum() {
            inside = !inside;
        }
    }
    let d = distance2.sqrt();
    if inside { -d } else { d }
}

pub(super) fn segment_distance2(a: Vector2<f64>, b: Vector2<f64>, p: Vector2<f64>) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(&ab) / ab.norm_squared().max(1e-300)).clamp(0.0, 1.0);
    (a + t * ab - p).norm_squared()
}
