//! Sub-pixel blob centres from the outline: edge points where each ray from the centre crosses the level halfway
//! between the blob's inside and its local outside, and the centre of the ellipse fitted to them.
//!
//! Each ray has its own inside and outside levels, so light that changes across the blob (a shadow's edge, a
//! gradient, glare) moves each edge point by little, where it pulls grey-level moments towards the brighter side.
//! Blur moves every edge point inwards alike, which leaves the centre in place.

use nalgebra::{Matrix5, Vector2, Vector5};

use super::centre::Ellipse;

/// The value at (u, v) by bilinear interpolation, (u, v) in the image (0 <= u <= width - 1, 0 <= v <= height - 1).
fn sample_within(pixels: &[u16], width: usize, height: usize, u: f64, v: f64) -> f64 {
    // Non-negative: truncation is the floor (and much cheaper than a call to it). Through `i32` (an image is far
    // narrower than 2^31 px): the conversions to and from `usize` take several instructions each on x86_64, those of
    // `i32` one, and give the same integers.
    let (ui, vj) = ((u as i32).max(0), (v as i32).max(0));
    let (i, j) = (ui as usize, vj as usize);
    let (di, dj) = (
        usize::from(i + 1 < width),
        if j + 1 < height { width } else { 0 },
    );
    let (fu, fv) = (u - f64::from(ui), v - f64::from(vj));
    let k = j * width + i;
    let at = |k: usize| f64::from(pixels[k]);
    (1.0 - fv) * ((1.0 - fu) * at(k) + fu * at(k + di))
        + fv * ((1.0 - fu) * at(k + dj) + fu * at(k + dj + di))
}

/// Profile samples per unit of the ray's radius.
const STEPS: usize = 12;

/// The centre (px) of the ellipse fitted to the blob's edge points (blob brighter than its surroundings), starting
/// from `shape` centred on `centre`, and the blob's contrast (the median over the rays of inside minus outside);
/// `None` if too few rays find an edge or the fit is not an ellipse.
pub(crate) fn edge_centre(
    pixels: &[u16],
    width: usize,
    height: usize,
    shape: &Ellipse,
    centre: Vector2<f64>,
    edges: &mut Vec<Vector2<f64>>,
    contrasts: &mut Vec<f64>,
) -> Option<(Vector2<f64>, f64)> {
    // A ray every 2 px of outline (finer changed nothing on real photographs).
    let rays = ((std::f64::consts::TAU * shape.semi_major_px / 2.0).round() as usize).clamp(20, 64);
    let (sin, cos) = shape.angle_rad.sin_cos();
    edges.clear();
    contrasts.clear();
    let mut profile = [0.0f64; STEPS + 1];
    // The rays' angles by rotation: one sine and cosine in all.
    let (step_sin, step_cos) = (std::f64::consts::TAU / rays as f64).sin_cos();
    let (mut phi_cos, mut phi_sin) = (1.0f64, 0.0f64);
    let (u_max, v_max) = ((width - 1) as f64, (height - 1) as f64);
    for _ in 0..rays {
        let (x, y) = (shape.semi_major_px * phi_cos, shape.semi_minor_px * phi_sin);
        (phi_cos, phi_sin) = (
            phi_cos * step_cos - phi_sin * step_sin,
            phi_sin * step_cos + phi_cos * step_sin,
        );
        // The ray through the ellipse's point at phi, its length that of the radius there.
        let radius = Vector2::new(cos * x - sin * y, sin * x + cos * y);
        // From 0.5 to 1.5 radii, but no more than 3 px beyond the outline (neighbours in dense grids).
        let reach = 0.5f64.min(3.0 / radius.norm().max(1e-9)).max(0.2);
        let (s0, s1) = (0.6, 1.0 + reach);
        // Both ends in the image: so is the whole segment between them (the image is convex).
        let (first, last) = (centre + s0 * radius, centre + s1 * radius);
        let within = |p: Vector2<f64>| p.x >= 0.0 && p.y >= 0.0 && p.x <= u_max && p.y <= v_max;
        if !(within(first) && within(last)) {
            continue;
        }
        let step = (s1 - s0) / STEPS as f64 * radius;
        let sample = |n: usize| {
            let at = first + n as f64 * step;
            sample_within(pixels, width, height, at.x, at.y)
        };
        // The inside's and the outside's samples first; those between them only as far as the crossing, which the
        // search below reads in order (a ray's edge is about halfway along it: a third of the samples are never
        // needed).
        for n in (0..STEPS / 4).chain(STEPS - 3..=STEPS) {
            profile[n] = sample(n);
        }
        let inside = profile[..STEPS / 4].iter().sum::<f64>() / (STEPS / 4) as f64;
        let outside = profile[STEPS - 3..]
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        if inside - outside <= 0.0 {
            continue;
        }
        let mid = 0.5 * (inside + outside);
        // The first crossing of the mid level going outwards.
        let Some(n) = (1..=STEPS).find(|&n| {
            if (STEPS / 4..STEPS - 3).contains(&n) {
                profile[n] = sample(n);
            }
            profile[n] < mid
        }) else {
            continue;
        };
        let f = (profile[n - 1] - mid) / (profile[n - 1] - profile[n]);
        let s = s0 + (s1 - s0) * ((n - 1) as f64 + f) / STEPS as f64;
        edges.push(centre + s * radius);
        contrasts.push(inside - outside);
    }
    if edges.len() < 10 || edges.len() * 3 < rays * 2 {
        return None;
    }
    let middle = contrasts.len() / 2;
    let contrast = *contrasts.select_nth_unstable_by(middle, f64::total_cmp).1;
    Some((fit_ellipse_centre(edges, centre)?, contrast))
}

/// Centre of the conic `a x² + b xy + c y² + d x + e y = 1` fitted by least squares to `points` (relative to
/// `origin`), refitted once without the points farthest from it; `None` if the conic is not an ellipse.
fn fit_ellipse_centre(points: &[Vector2<f64>], origin: Vector2<f64>) -> Option<Vector2<f64>> {
    let scale = points
        .iter()
        .map(|p| (p - origin).norm())
        .fold(0.0, f64::max)
        .max(1e-9);
    let fit = |keep: &dyn Fn(usize) -> bool| -> Option<Vector5<f64>> {
        let mut ata = Matrix5::<f64>::zeros();
        let mut atb = Vector5::<f64>::zeros();
        for (k, p) in points.iter().enumerate() {
            if !keep(k) {
                continue;
            }
            let q = (p - origin) / scale;
            let row = Vector5::new(q.x * q.x, q.x * q.y, q.y * q.y, q.x, q.y);
            ata += row * row.transpose();
            atb += row;
        }
        ata.cholesky().map(|c| c.solve(&atb))
    };
    let residual = |conic: &Vector5<f64>, p: &Vector2<f64>| {
        let q = (p - origin) / scale;
        (conic[0] * q.x * q.x
            + conic[1] * q.x * q.y
            + conic[2] * q.y * q.y
            + conic[3] * q.x
            + conic[4] * q.y
            - 1.0)
            .abs()
    };
    let mut conic = fit(&|_| true)?;
    // On the stack for the rays of one blob (at most 64), else on the heap; the median by selection (the same
    // element as sorting would put there).
    let mut on_stack = [0.0f64; 64];
    let mut on_heap = Vec::new();
    let errors: &mut [f64] = if points.len() <= on_stack.len() {
        &mut on_stack[..points.len()]
    } else {
        on_heap.resize(points.len(), 0.0);
        &mut on_heap
    };
    for (e, p) in errors.iter_mut().zip(points) {
        *e = residual(&conic, p);
    }
    let mut sorted_on_stack = [0.0f64; 64];
    let mut sorted_on_heap = Vec::new();
    let sorted: &mut [f64] = if points.len() <= sorted_on_stack.len() {
        &mut sorted_on_stack[..points.len()]
    } else {
        sorted_on_heap.resize(points.len(), 0.0);
        &mut sorted_on_heap
    };
    sorted.copy_from_slice(errors);
    let middle = sorted.len() / 2;
    let cut = 3.0
        * sorted
            .select_nth_unstable_by(middle, f64::total_cmp)
            .1
            .max(1e-12);
    if errors.iter().any(|&e| e > cut) {
        let errors = &*errors;
        conic = fit(&|k| errors[k] <= cut)?;
    }
    let (a, b, c, d, e) = (conic[0], conic[1], conic[2], conic[3], conic[4]);
    let det = 4.0 * a * c - b * b;
    if det <= 0.0 {
        return None;
    }
    let x = (b * e - 2.0 * c * d) / det;
    let y = (b * d - 2.0 * a * e) / det;
    Some(origin + scale * Vector2::new(x, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_of_points_on_a_rotated_ellipse() {
        let (c, a, b, th) = (Vector2::new(12.3, -4.1), 7.0, 3.0, 0.6f64);
        let points: Vec<Vector2<f64>> = (0..40)
            .map(|k| {
                let phi = std::f64::consts::TAU * f64::from(k) / 40.0;
                let (x, y) = (a * phi.cos(), b * phi.sin());
                c + Vector2::new(th.cos() * x - th.sin() * y, th.sin() * x + th.cos() * y)
            })
            .collect();
        let found = fit_ellipse_centre(&points, c + Vector2::new(0.7, -0.4)).unwrap();
        assert!((found - c).norm() < 1e-9, "{found}");
    }
}
