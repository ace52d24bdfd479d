//! The minimal pose problem (P3P): every pose that puts three model points on three bearing rays, in front of the
//! camera. At most four.
//!
//! The method is Persson and Nordberg's "Lambda Twist" (ECCV 2018), derived here from its equations. With unit
//! bearings `y_i`, depths `λ_i > 0` and model points `x_i`, rigidity says `|λ_i y_i - λ_j y_j|² = |x_i - x_j|²`:
//!
//! ```text
//! Λᵀ M_ij Λ = a_ij,   M_12 = [[1, -b12, 0], [-b12, 1, 0], [0, 0, 0]] (and alike),   b_ij = y_i·y_j,   a_ij = |x_i - x_j|²
//! ```
//!
//! Eliminating the right-hand sides gives two homogeneous conics `D1 = a23 M12 - a12 M23`, `D2 = a23 M13 - a13 M23`,
//! whose (at most four) common points are the solutions up to scale. Their pencil `D1 + γ D2` holds a degenerate
//! conic (`det = 0`, a cubic in `γ`): a pair of lines through the solutions. Each line meets `D1` (or `D2`) in two
//! points; each point, scaled by `Λᵀ M12 Λ = a12` and polished by Gauss-Newton on the three equations, gives the
//! camera-frame points `λ_i y_i`, and the pose is the rigid motion between the two triangles.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// At most this many poses solve a P3P problem.
pub(crate) const MAX_P3P_SOLUTIONS: usize = 4;

/// The poses of one P3P problem (`cam_r_obj`, `cam_t_obj_m`), at most [`MAX_P3P_SOLUTIONS`].
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct P3pSolutions {
    poses: [(Rotation3<f64>, Vector3<f64>); MAX_P3P_SOLUTIONS],
    len: usize,
}

impl P3pSolutions {
    pub(crate) fn as_slice(&self) -> &[(Rotation3<f64>, Vector3<f64>)] {
        &self.poses[..self.len]
    }

    fn push(&mut self, pose: (Rotation3<f64>, Vector3<f64>)) {
        if self.len < MAX_P3P_SOLUTIONS {
            self.poses[self.len] = pose;
            self.len += 1;
        }
    }
}

/// Every pose `(R, t)` with `R x_i + t` on the ray of `bearings[i]` in front of the camera, for three model points
/// that are not collinear and three distinct bearings (any length, pointing towards the points). Empty when the
/// problem has no real solution or is degenerate.
pub(crate) fn p3p(bearings: &[Vector3<f64>; 3], points_m: &[Vector3<f64>; 3]) -> P3pSolutions {
    let mut solutions = P3pSolutions::default();
    let Some(y) = unit_bearings(bearings) else {
        return solutions;
    };
    // Work in units of the largest side, so that every quantity is of order one.
    let a_raw = [
        (points_m[0] - points_m[1]).norm_squared(),
        (points_m[0] - points_m[2]).norm_squared(),
        (points_m[1] - points_m[2]).norm_squared(),
    ];
    let scale2 = a_raw.iter().copied().fold(0.0, f64::max);
    if !(scale2 > 0.0 && scale2.is_finite()) {
        return solutions;
    }
    let [a12, a13, a23] = a_raw.map(|a| a / scale2);
    if a12.min(a13).min(a23) <= 1e-24 {
        return solutions;
    }
    let (b12, b13, b23) = (y[0].dot(&y[1]), y[0].dot(&y[2]), y[1].dot(&y[2]));
    let m12 = Matrix3::new(1.0, -b12, 0.0, -b12, 1.0, 0.0, 0.0, 0.0, 0.0);
    let m13 = Matrix3::new(1.0, 0.0, -b13, 0.0, 0.0, 0.0, -b13, 0.0, 1.0);
    let m23 = Matrix3::new(0.0, 0.0, 0.0, 0.0, 1.0, -b23, 0.0, -b23, 1.0);
    let d1 = a23 * m12 - a12 * m23;
    let d2 = a23 * m13 - a13 * m23;
    let Some(degenerate) = degenerate_member(&d1, &d2) else {
        return solutions;
    };
    let b = [b12, b13, b23];
    let a = [a12, a13, a23];
    let mut depths_found: [Vector3<f64>; MAX_P3P_SOLUTIONS] = [Vector3::zeros(); MAX_P3P_SOLUTIONS];
    let mut found = 0;
    for direction in line_points(&degenerate, &d1, &d2) {
        let Some(depths) = scaled_depths(&direction, &m12, a12) else {
            continue;
        };
        let depths = polish_depths(depths, &a, &b);
        if !depths.iter().all(|&l| l > 0.0 && l.is_finite()) {
            continue;
        }
        // A double root reached from both lines is one solution.
        if depths_found[..found]
            .iter()
            .any(|d| (d - depths).norm() <= 1e-9 * depths.norm())
        {
            continue;
        }
        if found < MAX_P3P_SOLUTIONS {
            depths_found[found] = depths;
            found += 1;
        }
    }
    let scale = scale2.sqrt();
    let points_scaled = points_m.map(|p| p / scale);
    for depths in &depths_found[..found] {
        let in_cam = [depths[0] * y[0], depths[1] * y[1], depths[2] * y[2]];
        if let Some((r, t)) = rigid_motion(&points_scaled, &in_cam) {
            solutions.push((r, t * scale));
        }
    }
    solutions
}

fn unit_bearings(bearings: &[Vector3<f64>; 3]) -> Option<[Vector3<f64>; 3]> {
    let y = [
        bearings[0].try_normalize(0.0)?,
        bearings[1].try_normalize(0.0)?,
        bearings[2].try_normalize(0.0)?,
    ];
    y.iter()
        .all(|v| v.iter().all(|c| c.is_finite()))
        .then_some(y)
}

/// The adjugate of a 3 x 3 matrix (`adj(A) A = det(A) I`).
fn adjugate(m: &Matrix3<f64>) -> Matrix3<f64> {
    let c = |r0: usize, r1: usize, c0: usize, c1: usize| {
        m[(r0, c0)] * m[(r1, c1)] - m[(r0, c1)] * m[(r1, c0)]
    };
    Matrix3::new(
        c(1, 2, 1, 2),
        -c(0, 2, 1, 2),
        c(0, 1, 1, 2),
        -c(1, 2, 0, 2),
        c(0, 2, 0, 2),
        -c(0, 1, 0, 2),
        c(1, 2, 0, 1),
        -c(0, 2, 0, 1),
        c(0, 1, 0, 1),
    )
}

/// A degenerate conic of the pencil `D1 + γ D2` that is a real pair of lines (indefinite, rank 2), as its
/// eigen-decomposition: eigenvalues `(σ1, σ2)` of opposite signs with their eigenvectors and the null vector (the
/// lines' meeting point). Of several, the one whose two eigenvalues are most alike in size (best conditioned).
/// Eigenvectors by cross products of rows: the depths are polished afterwards, so their accuracy need not be the
/// last bit's.
struct LinePair {
    sigma: [f64; 2],
    e: [Vector3<f64>; 2],
    vertex: Vector3<f64>,
}

fn degenerate_member(d1: &Matrix3<f64>, d2: &Matrix3<f64>) -> Option<LinePair> {
    // det(D1 + γ D2) = det D1 + γ tr(adj(D1) D2) + γ² tr(adj(D2) D1) + γ³ det D2.
    let c0 = d1.determinant();
    let c1 = (adjugate(d1) * d2).trace();
    let c2 = (adjugate(d2) * d1).trace();
    let c3 = d2.determinant();
    let mut members: [Option<Matrix3<f64>>; 4] = [None; 4];
    let roots = real_cubic_roots(c3, c2, c1, c0);
    for (slot, gamma) in members.iter_mut().zip(roots.iter().flatten()) {
        *slot = Some(d1 + *gamma * d2);
    }
    // γ = ∞: D2 itself, when its determinant vanishes (the cubic's leading coefficient).
    let size = c0.abs() + c1.abs() + c2.abs() + c3.abs();
    if c3.abs() <= 1e-12 * size {
        members[3] = Some(*d2);
    }
    // The best conditioned member: the eigenvalues besides the (near) zero one are the roots of
    // σ² - tr σ + m2 = 0 (m2 the sum of the principal 2 x 2 minors); real lines need them of opposite signs (m2 < 0).
    let mut best: Option<(f64, Matrix3<f64>)> = None;
    for member in members.iter().flatten() {
        let Some(sigma) = nonzero_eigenvalues(member) else {
            continue;
        };
        let quality = sigma[0].abs().min(sigma[1].abs()) / sigma[0].abs().max(sigma[1].abs());
        if best.as_ref().is_none_or(|(q, _)| quality > *q) {
            best = Some((quality, *member));
        }
    }
    let (_, conic) = best?;
    let sigma = nonzero_eigenvalues(&conic)?;
    let vertex = null_vector(&conic)?;
    let e = [
        null_vector(&(conic - Matrix3::from_diagonal_element(sigma[0])))?,
        null_vector(&(conic - Matrix3::from_diagonal_element(sigma[1])))?,
    ];
    Some(LinePair { sigma, e, vertex })
}

/// The two eigenvalues of a rank-2 symmetric matrix besides its zero one, larger magnitude first, if they have
/// opposite signs (a real pair of lines; equal signs: complex lines meeting in one real point, which a double root
/// reaches from a neighbouring member).
fn nonzero_eigenvalues(c: &Matrix3<f64>) -> Option<[f64; 2]> {
    let trace = c.trace();
    let minors = c[(0, 0)] * c[(1, 1)] - c[(0, 1)] * c[(1, 0)] + c[(0, 0)] * c[(2, 2)]
        - c[(0, 2)] * c[(2, 0)]
        + c[(1, 1)] * c[(2, 2)]
        - c[(1, 2)] * c[(2, 1)];
    if minors.is_nan() || minors >= 0.0 {
        return None;
    }
    let root = (trace * trace - 4.0 * minors).sqrt();
    let (a, b) = (0.5 * (trace + root), 0.5 * (trace - root));
    Some(if a.abs() >= b.abs() { [a, b] } else { [b, a] })
}

/// The unit null vector of a rank-2 matrix: the largest cross product of two of its rows.
fn null_vector(m: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let rows = [
        m.row(0).transpose(),
        m.row(1).transpose(),
        m.row(2).transpose(),
    ];
    [
        rows[0].cross(&rows[1]),
        rows[0].cross(&rows[2]),
        rows[1].cross(&rows[2]),
    ]
    .into_iter()
    .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?
    .try_normalize(0.0)
}

/// The real roots of `c3 x³ + c2 x² + c1 x + c0` (a lower degree when leading coefficients vanish), each polished by
/// Newton's method.
fn real_cubic_roots(c3: f64, c2: f64, c1: f64, c0: f64) -> [Option<f64>; 3] {
    let size = c0.abs() + c1.abs() + c2.abs() + c3.abs();
    let mut roots = [None; 3];
    if size.is_nan() || size <= 0.0 || !size.is_finite() {
        return roots;
    }
    if c3.abs() <= 1e-12 * size {
        // Quadratic (or lower).
        if c2.abs() <= 1e-12 * size {
            if c1 != 0.0 {
                roots[0] = Some(-c0 / c1);
            }
            return roots;
        }
        let disc = c1 * c1 - 4.0 * c2 * c0;
        if disc >= 0.0 {
            let q = -0.5 * (c1 + c1.signum() * disc.sqrt());
            roots[0] = Some(q / c2);
            if q != 0.0 {
                roots[1] = Some(c0 / q);
            }
        }
        return roots;
    }
    // Monic x³ + a x² + b x + c, depressed by x = z - a/3 to z³ + p z + q.
    let (a, b, c) = (c2 / c3, c1 / c3, c0 / c3);
    let p = b - a * a / 3.0;
    let q = 2.0 * a * a * a / 27.0 - a * b / 3.0 + c;
    let shift = -a / 3.0;
    let disc = (q / 2.0).powi(2) + (p / 3.0).powi(3);
    if disc > 0.0 {
        // One real root (Cardano).
        let s = disc.sqrt();
        let z = (-q / 2.0 + s).cbrt() + (-q / 2.0 - s).cbrt();
        roots[0] = Some(z + shift);
    } else {
        // Three real roots (trigonometric form); p <= 0 here.
        let r = (-p / 3.0).max(0.0).sqrt();
        if r == 0.0 {
            roots[0] = Some(shift);
        } else {
            let cos_arg = (-q / (2.0 * r * r * r)).clamp(-1.0, 1.0);
            let phi = cos_arg.acos() / 3.0;
            for (k, slot) in roots.iter_mut().enumerate() {
                *slot = Some(
                    2.0 * r * (phi - 2.0 * std::f64::consts::PI * k as f64 / 3.0).cos() + shift,
                );
            }
        }
    }
    for x in roots.iter_mut().flatten() {
        for _ in 0..3 {
            let f = ((x.mul_add(1.0, a) * *x + b) * *x) + c;
            let df = (3.0 * *x + 2.0 * a) * *x + b;
            if df == 0.0 {
                break;
            }
            let next = *x - f / df;
            if !next.is_finite() {
                break;
            }
            *x = next;
        }
    }
    roots
}

/// The (at most four) directions where the two lines of `pair` meet the conic `D1` (or `D2` where `D1` vanishes on a
/// line: on each line the pencil's members are proportional).
fn line_points(
    pair: &LinePair,
    d1: &Matrix3<f64>,
    d2: &Matrix3<f64>,
) -> impl Iterator<Item = Vector3<f64>> {
    let s = (-pair.sigma[1] / pair.sigma[0]).max(0.0).sqrt();
    let mut points = [None; 4];
    for (k, sign) in [1.0, -1.0].into_iter().enumerate() {
        // σ1 (e1·Λ)² + σ2 (e2·Λ)² = 0 on the lines (e1 ∓ s e2)·Λ = 0; both pass through the vertex.
        let normal = pair.e[0] - sign * s * pair.e[1];
        let Some(along) = normal.cross(&pair.vertex).try_normalize(0.0) else {
            continue;
        };
        let basis = [pair.vertex, along];
        let restricted = |c: &Matrix3<f64>| {
            let g = |i: usize, j: usize| basis[i].dot(&(c * basis[j]));
            [g(0, 0), g(0, 1), g(1, 1)]
        };
        let (g1, g2) = (restricted(d1), restricted(d2));
        let norm = |g: &[f64; 3]| g[0].abs() + g[1].abs() + g[2].abs();
        let g = if norm(&g1) >= norm(&g2) { g1 } else { g2 };
        // g0 α² + 2 g1 α β + g2 β² = 0.
        let disc = g[1] * g[1] - g[0] * g[2];
        let scale = g[1] * g[1] + (g[0] * g[2]).abs();
        let disc = if disc < 0.0 && disc > -1e-12 * scale {
            0.0
        } else {
            disc
        };
        if disc < 0.0 || scale == 0.0 {
            continue;
        }
        let root = disc.sqrt();
        let pairs = if g[0].abs() >= g[2].abs() {
            [((-g[1] + root) / g[0], 1.0), ((-g[1] - root) / g[0], 1.0)]
        } else {
            [(1.0, (-g[1] + root) / g[2]), (1.0, (-g[1] - root) / g[2])]
        };
        for (j, (alpha, beta)) in pairs.into_iter().enumerate() {
            points[2 * k + j] = Some(alpha * basis[0] + beta * basis[1]);
        }
    }
    points.into_iter().flatten()
}

/// The depths along `direction` (either sign) scaled so that `Λᵀ M12 Λ = a12`, if all three have one sign.
fn scaled_depths(direction: &Vector3<f64>, m12: &Matrix3<f64>, a12: f64) -> Option<Vector3<f64>> {
    let d = if direction.sum() < 0.0 {
        -direction
    } else {
        *direction
    };
    if !d.iter().all(|&x| x > 0.0) {
        return None;
    }
    let q = d.dot(&(m12 * d));
    (q > 0.0).then(|| d * (a12 / q).sqrt())
}

/// Gauss-Newton on the three rigidity equations `λi² + λj² - 2 b_ij λi λj = a_ij` (pairs 12, 13, 23): a few steps
/// take the depths from the closed form's round-off to machine precision.
fn polish_depths(mut l: Vector3<f64>, a: &[f64; 3], b: &[f64; 3]) -> Vector3<f64> {
    const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];
    for _ in 0..5 {
        let mut f = Vector3::zeros();
        let mut jac = Matrix3::zeros();
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            f[k] = l[i] * l[i] + l[j] * l[j] - 2.0 * b[k] * l[i] * l[j] - a[k];
            jac[(k, i)] = 2.0 * l[i] - 2.0 * b[k] * l[j];
            jac[(k, j)] = 2.0 * l[j] - 2.0 * b[k] * l[i];
        }
        if f.norm() <= 1e-15 {
            break;
        }
        let det = jac.determinant();
        if det == 0.0 || !det.is_finite() {
            break;
        }
        let step = adjugate(&jac) * f / det;
        let next = l - step;
        if !next.iter().all(|x| x.is_finite()) {
            break;
        }
        l = next;
    }
    l
}

/// The rigid motion taking the triangle `from` onto `to` (equal side lengths): the rotation of the two triangles'
/// frames (two edges and their normal), pulled onto SO(3) against round-off, and the translation of the centroids.
fn rigid_motion(
    from: &[Vector3<f64>; 3],
    to: &[Vector3<f64>; 3],
) -> Option<(Rotation3<f64>, Vector3<f64>)> {
    let frame = |p: &[Vector3<f64>; 3]| {
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        Matrix3::from_columns(&[e1, e2, e1.cross(&e2)])
    };
    let from_frame = frame(from).try_inverse()?;
    let m = frame(to) * from_frame;
    // Polished depths make the triangles congruent to round-off: a Newton-Schulz step pulls the product onto SO(3);
    // anything farther off takes the polar decomposition.
    let departure = (m.transpose() * m - Matrix3::identity()).amax();
    let r = if departure < 1e-6 {
        roitrack_core::so3::orthonormalized(&Rotation3::from_matrix_unchecked(m))
    } else {
        super::nearest_rotation(&m)?
    };
    let centre = |p: &[Vector3<f64>; 3]| (p[0] + p[1] + p[2]) / 3.0;
    let t = centre(to) - r * centre(from);
    r.matrix().iter().all(|x| x.is_finite()).then_some((r, t))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_rotation(rng: &mut ChaCha8Rng) -> Rotation3<f64> {
        let axis = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        Rotation3::new(axis.normalize() * rng.random_range(0.0..std::f64::consts::PI))
    }

    #[test]
    fn cubic_roots_are_roots() {
        for (c3, c2, c1, c0, count) in [
            (1.0, -6.0, 11.0, -6.0, 3), // 1, 2, 3
            (2.0, 0.0, 0.0, -16.0, 1),  // 2
            (0.0, 1.0, -3.0, 2.0, 2),   // quadratic: 1, 2
            (1.0, 0.0, -3.0, 2.0, 3),   // 1 (double), -2
        ] {
            let roots = real_cubic_roots(c3, c2, c1, c0);
            assert_eq!(roots.iter().flatten().count(), count);
            for x in roots.iter().flatten() {
                let f = c3 * x * x * x + c2 * x * x + c1 * x + c0;
                assert!(f.abs() < 1e-9, "{x}: {f}");
            }
        }
    }

    /// Random triangles seen from random poses in front of the camera: the true pose is among the solutions to
    /// machine precision, and every solution puts the three points on their rays.
    #[test]
    fn the_true_pose_is_among_the_solutions() {
        let mut rng = ChaCha8Rng::seed_from_u64(34);
        let mut worst = 0.0f64;
        let mut counts = [0usize; 5];
        for _ in 0..20_000 {
            let size = 10f64.powf(rng.random_range(-2.0..0.0));
            let points: [Vector3<f64>; 3] = std::array::from_fn(|_| {
                Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                ) * size
            });
            let e1 = points[1] - points[0];
            let e2 = points[2] - points[0];
            if e1.cross(&e2).norm() < 0.05 * e1.norm() * e2.norm() {
                continue;
            }
            let r = random_rotation(&mut rng);
            let t = Vector3::new(
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
                rng.random_range(0.5..5.0),
            );
            let in_cam = points.map(|p| r * p + t);
            if in_cam.iter().any(|p| p.z <= 0.05) {
                continue;
            }
            let solutions = p3p(&in_cam, &points);
            counts[solutions.as_slice().len()] += 1;
            let error = solutions
                .as_slice()
                .iter()
                .map(|(rs, ts)| {
                    (ts - t).norm() / t.norm() + roitrack_core::so3::angle_between(rs, &r)
                })
                .fold(f64::INFINITY, f64::min);
            worst = worst.max(error);
            assert!(
                error < 1e-6,
                "no solution near the truth: error {error}, {} solutions",
                solutions.len
            );
            for (rs, ts) in solutions.as_slice() {
                for (p, y) in points.iter().zip(&in_cam) {
                    let q = rs * p + ts;
                    assert!(q.z > 0.0);
                    assert!(q.normalize().cross(&y.normalize()).norm() < 1e-6);
                }
            }
        }
        assert_eq!(counts[0], 0, "solution counts {counts:?}");
        eprintln!("worst {worst:.2e}, solution counts {counts:?}");
    }
}
