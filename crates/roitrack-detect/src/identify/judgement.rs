//! The judgement of verified hypotheses: the noise and model error a residual is judged against, when one is
//! accepted and how they rank, their blob sizes against the target's diameters, and whether a rival as good is the
//! target's own symmetry.

use roitrack_core::Target;
use roitrack_core::stats::f_equal_dof_upper_quantile;

use super::verify::{Verified, Verifier};

/// The centroid noise (px per coordinate) a hypothesis is judged against: that of real photographs' centres, near
/// the top of their spread (measured in docs/results.md, "Design measurements behind the code").
pub(super) const IDENTIFY_NOISE_PX: f64 = 0.3;

/// The model error a hypothesis's residual is allowed (and a rival's advantage over the best), in standard
/// deviations of [`MODEL_UNCERTAINTY`]: the bounds users' camera and target files stay within.
///
/// [`MODEL_UNCERTAINTY`]: roitrack_estimators::MODEL_UNCERTAINTY
pub(super) const MODEL_BOUND_SIGMAS: f64 = 2.0;

/// How sure the residuals must make the best labelling against a rival on as many points for the rival to be
/// dismissed ([`f_equal_dof_upper_quantile`]).
const RIVAL_CONFIDENCE: f64 = 0.999;

/// The fraction of the target points a hypothesis predicts in view that must have a blob for it to be accepted:
/// a few may be hidden, cut by glare or merged with clutter.
const MIN_FOUND_FRACTION: f64 = 0.85;

/// The fewest points a hypothesis of a target of `n` points can match when the target is wholly in view and
/// accepted: all but the [`MIN_FOUND_FRACTION`] acceptance leaves missing.
pub(crate) fn whole_view_points(n: usize) -> usize {
    n - (n as f64 * (1.0 - MIN_FOUND_FRACTION)).floor() as usize
}

impl Verified {
    pub(super) fn accepted(&self, verifier: &Verifier, min_matched: usize) -> bool {
        let matched = self.pairs.len();
        matched >= min_matched
            && self.missing as f64 <= (1.0 - MIN_FOUND_FRACTION) * self.visible as f64
            && self.size_mismatches as f64 <= 0.1 * matched as f64
            && self.residual_px
                <= *self
                    .residual_bound_px
                    .get_or_init(|| verifier.residual_bound_px(&self.pairs, &self.state))
    }

    /// Better first: more points, fewer missing, fewer sizes wrong, smaller residual.
    pub(super) fn rank(&self, other: &Self) -> std::cmp::Ordering {
        other
            .pairs
            .len()
            .cmp(&self.pairs.len())
            .then(self.missing.cmp(&other.missing))
            .then(self.size_mismatches.cmp(&other.size_mismatches))
            .then(self.from_back.cmp(&other.from_back))
            .then(self.residual_px.total_cmp(&other.residual_px))
    }
}

/// How far a matched blob's area may be from what its point's diameter predicts, as a factor either way, once the
/// blobs' common scale is taken out: a threshold finds a disk's edge anywhere from its dark to its bright side, which
/// moves a small disk's area by up to about a factor 2.
pub(super) const BLOB_AREA_FACTOR: f64 = 2.0;

/// How far the common scale of the matched blobs' areas may be from the target file's diameters, as a factor either
/// way: nominal diameters may be off by up to 2x (a factor 4 in area) and the threshold adds its factor 2.
pub(crate) const NOMINAL_AREA_FACTOR: f64 = crate::photo::NOMINAL_DIAMETER_AREA * BLOB_AREA_FACTOR;

/// How far a labelling's blob sizes spread about their common scale: `Σ (ln rᵢ - ln r̃)²` over the matched blobs
/// whose points have a diameter (`rᵢ` a blob's area over the area its point's diameter predicts, `r̃` their median),
/// and the part of it that pixel quantisation alone makes: a thresholded disk of `A` px² gains or loses about a
/// uniform fraction of each pixel along its perimeter `2 √(π A)`, a variance of `2 √(π A) / 12` px² in its area,
/// `2 √(π A) / (12 A²)` in its logarithm.
///
/// Two labellings of the same blobs that tie on every count ([`size_mismatches`] allows a factor 2 in area, the
/// threshold's reach) may still differ in their sizes: a key dot 20-40 % larger than the rest is within that factor
/// of the others, yet a labelling that puts it on a small point leaves it, and the small blob put on the key point,
/// far off the common scale. The spreads are compared as two variances on as many blobs (`f_equal_dof_upper_quantile`):
/// relative sizes tell the labellings apart whatever the file's nominal diameters, which only move the common scale.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct SizeSpread {
    pub(super) sum_sq: f64,
    quantisation: f64,
    count: usize,
}

impl SizeSpread {
    /// The spread of `ratios`, sorted ([`size_mismatches`] sorts them), whose blobs' quantisation adds up to
    /// `quantisation`.
    pub(super) fn of_sorted(ratios: &[f64], quantisation: f64) -> Self {
        if ratios.len() < 3 {
            return Self::default();
        }
        let median = ratios[ratios.len() / 2].ln();
        Self {
            sum_sq: ratios.iter().map(|r| (r.ln() - median).powi(2)).sum(),
            quantisation,
            count: ratios.len(),
        }
    }

    /// What pixel quantisation makes of the variance of the logarithm of a blob's area of `area_px2`.
    pub(super) fn quantisation(area_px2: f64) -> f64 {
        2.0 * (std::f64::consts::PI * area_px2).sqrt() / (12.0 * area_px2 * area_px2)
    }

    /// The degrees of freedom of the spread (one scale taken out); `None` for too few blobs to compare.
    fn dof(&self) -> Option<f64> {
        (self.count >= 3).then(|| (self.count - 1) as f64)
    }

    /// Whether this labelling's sizes fit worse than `other`'s over as many blobs, by more than `quantile` gives
    /// for [`Self::dof`] (the upper quantile of the ratio of two variances of as many degrees of freedom, asked
    /// only when needed): `other`'s spread floored at what quantisation makes, so that two nearly exact fits are
    /// never told apart by their rounding.
    pub(super) fn worse_than(&self, other: &Self, quantile: impl FnOnce(f64) -> f64) -> bool {
        let floor = other.sum_sq.max(other.quantisation);
        match self.dof() {
            Some(dof) if self.count == other.count && self.sum_sq > floor => {
                self.sum_sq > quantile(dof) * floor
            }
            _ => false,
        }
    }
}

/// Matched blobs whose size disagrees with their points' diameters (`ratios`: each blob's area over the predicted
/// one; reordered). The diameters of a target file are nominal: a common scale (the median ratio) within
/// [`NOMINAL_AREA_FACTOR`] is taken out, and each blob must then be within [`BLOB_AREA_FACTOR`] of its prediction;
/// beyond that common scale every blob disagrees. Also returns the common scale (1 without diameters).
pub(super) fn size_mismatches(ratios: &mut [f64]) -> (usize, f64) {
    if ratios.is_empty() {
        return (0, 1.0);
    }
    ratios.sort_by(f64::total_cmp);
    let common = ratios[ratios.len() / 2];
    if !(1.0 / NOMINAL_AREA_FACTOR..=NOMINAL_AREA_FACTOR).contains(&common) {
        return (ratios.len(), common);
    }
    let mismatches = ratios
        .iter()
        .filter(|&&r| !(1.0 / BLOB_AREA_FACTOR..=BLOB_AREA_FACTOR).contains(&(r / common)))
        .count();
    (mismatches, common)
}

/// Do two hypotheses match the same blobs (to other points)?
pub(super) fn same_blobs(a: &Verified, b: &Verified) -> bool {
    let blobs = |v: &Verified| {
        let mut blobs: Vec<usize> = v.pairs.iter().map(|&(_, b)| b).collect();
        blobs.sort_unstable();
        blobs
    };
    blobs(a) == blobs(b)
}

/// Is `to` the same labelling as `from` up to a rigid motion of the target onto itself (points onto points of the
/// same diameter)?
pub(super) fn related_by_symmetry(target: &Target, from: &Verified, to: &Verified) -> bool {
    // The motion that takes each point of `from` to the point `to` gives the same blob: compose the two poses.
    let motion_r = to.state.cam_r_obj.inverse() * from.state.cam_r_obj;
    let motion_t = to.state.cam_r_obj.inverse() * (from.state.cam_t_obj_m - to.state.cam_t_obj_m);
    let points = target.points();
    let spread = target.principal_spreads_m()[0].max(1e-9);
    points.iter().all(|p| {
        let moved = motion_r * p.point_in_obj_m + motion_t;
        points.iter().any(|q| {
            (q.point_in_obj_m - moved).norm() < 0.02 * spread
                && match (p.diameter_m, q.diameter_m) {
                    (Some(a), Some(b)) => (a - b).abs() <= 1e-3 * a.max(b),
                    (None, None) => true,
                    _ => false,
                }
        })
    })
}

/// [`f_equal_dof_upper_quantile`] at [`RIVAL_CONFIDENCE`], kept per degrees of freedom on the thread: it sums a density
/// over 8,192 cells (longer than a small target's whole identification once its hypotheses are made; measured in
/// docs/results.md, "Design measurements behind the code"), and a photograph's or a video's identifications ask it
/// again and again for the same few counts of points. The same value as computed afresh: the function is deterministic.
pub(super) fn rival_quantile(dof: f64) -> f64 {
    thread_local! {
        static KEPT: std::cell::RefCell<Vec<(u64, f64)>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    KEPT.with(|kept| {
        let mut kept = kept.borrow_mut();
        if let Some(&(_, q)) = kept.iter().find(|(d, _)| *d == dof.to_bits()) {
            return q;
        }
        let q = f_equal_dof_upper_quantile(dof, RIVAL_CONFIDENCE);
        // A target has at most a few hundred points: the list stays short, but is bounded all the same.
        if kept.len() >= 64 {
            kept.clear();
        }
        kept.push((dof.to_bits(), q));
        q
    })
}
