//! The triples of points the hypotheses are drawn from: the best-conditioned first, then further ones.

use nalgebra::Vector2;

use crate::Observation;

/// Triples of points tried at most (each gives up to four hypotheses), beyond [`FEW_POINTS`] points.
const MAX_TRIPLES: usize = 8;

/// Observations of at most this many points are tried with every triple of them.
pub(super) const FEW_POINTS: usize = 6;

/// Points the triples are drawn from: the best-spread few in the image.
const SPREAD_POINTS: usize = 6;

/// The triples of observations the hypotheses come from, best conditioned first: the largest image triangle (the
/// point farthest from the centroid, the point farthest from it, the point farthest from their line), then (made
/// only if asked for) the other triples of a few well-spread points by decreasing image area. Triples of one point
/// twice, or whose images are nearly on a line, are left out.
pub(super) struct Triples<'a> {
    obs: &'a [Observation],
    first: Option<[usize; 3]>,
    /// The other triples, best last (taken by `pop`); made at the first request after the first triple.
    others: Option<Vec<[usize; 3]>>,
    largest_area: f64,
}

pub(super) enum TriplesError {
    TooFewPoints,
    OnALine,
}

/// Twice the signed area of the image triangle `a, b, c`.
fn signed_area(image: &[Vector2<f64>], a: usize, b: usize, c: usize) -> f64 {
    let (e1, e2) = (image[b] - image[a], image[c] - image[a]);
    e1.x * e2.y - e1.y * e2.x
}

/// The observation that maximises `score` among those of points not in `skip`.
fn farthest(obs: &[Observation], score: impl Fn(usize) -> f64, skip: &[usize]) -> Option<usize> {
    (0..obs.len())
        .filter(|&k| {
            skip.iter()
                .all(|&s| obs[s].point_index != obs[k].point_index)
        })
        .max_by(|&a, &b| score(a).total_cmp(&score(b)))
}

impl<'a> Triples<'a> {
    pub(super) fn new(
        obs: &'a [Observation],
        image: &[Vector2<f64>],
    ) -> Result<Self, TriplesError> {
        let centroid = image.iter().sum::<Vector2<f64>>() / image.len() as f64;
        let i0 = farthest(obs, |k| (image[k] - centroid).norm_squared(), &[])
            .ok_or(TriplesError::TooFewPoints)?;
        let i1 = farthest(obs, |k| (image[k] - image[i0]).norm_squared(), &[i0])
            .ok_or(TriplesError::TooFewPoints)?;
        let i2 = farthest(obs, |k| signed_area(image, i0, i1, k).abs(), &[i0, i1])
            .ok_or(TriplesError::TooFewPoints)?;
        let largest_area = signed_area(image, i0, i1, i2).abs();
        // Nearly on a line: a triangle whose height is below a millionth of its base.
        if largest_area.is_nan() || largest_area <= 1e-6 * (image[i1] - image[i0]).norm_squared() {
            return Err(TriplesError::OnALine);
        }
        Ok(Self {
            obs,
            first: Some([i0, i1, i2]),
            others: None,
            largest_area,
        })
    }

    pub(super) fn next(&mut self, image: &[Vector2<f64>]) -> Option<[usize; 3]> {
        if let Some(first) = self.first.take() {
            return Some(first);
        }
        if self.others.is_none() {
            self.others = Some(self.make_others(image));
        }
        self.others.as_mut()?.pop()
    }

    /// The triples of the well-spread points (the first triple's and the farthest from the chosen ones, in turn)
    /// other than the first, best last.
    fn make_others(&self, image: &[Vector2<f64>]) -> Vec<[usize; 3]> {
        let mut spread: Vec<usize> = Vec::with_capacity(SPREAD_POINTS);
        // Rebuild the first triple (taken by now) from the same rule.
        let centroid = image.iter().sum::<Vector2<f64>>() / image.len() as f64;
        let obs = self.obs;
        for _ in 0..3 {
            let next = match spread.len() {
                0 => farthest(obs, |k| (image[k] - centroid).norm_squared(), &spread),
                1 => farthest(
                    obs,
                    |k| (image[k] - image[spread[0]]).norm_squared(),
                    &spread,
                ),
                _ => farthest(
                    obs,
                    |k| signed_area(image, spread[0], spread[1], k).abs(),
                    &spread,
                ),
            };
            spread.extend(next);
        }
        while spread.len() < SPREAD_POINTS {
            let nearest_chosen = |k: usize| {
                spread
                    .iter()
                    .map(|&s| (image[k] - image[s]).norm_squared())
                    .fold(f64::INFINITY, f64::min)
            };
            match farthest(obs, nearest_chosen, &spread) {
                Some(k) if nearest_chosen(k) > 0.0 => spread.push(k),
                _ => break,
            }
        }
        let mut others: Vec<([usize; 3], f64)> = Vec::new();
        for a in 0..spread.len() {
            for b in a + 1..spread.len() {
                for c in b + 1..spread.len() {
                    let area = signed_area(image, spread[a], spread[b], spread[c]).abs();
                    if (a, b, c) != (0, 1, 2) && area > 1e-3 * self.largest_area {
                        others.push(([spread[a], spread[b], spread[c]], area));
                    }
                }
            }
        }
        // Largest last: `pop` takes it first.
        others.sort_by(|x, y| x.1.total_cmp(&y.1));
        let skip = if self.obs.len() <= FEW_POINTS {
            0
        } else {
            others.len().saturating_sub(MAX_TRIPLES - 1)
        };
        others.into_iter().skip(skip).map(|(t, _)| t).collect()
    }
}
