//! The hypotheses in groups, in the order the search verifies them: the lattices grown among the blobs and laid on
//! the target's, largest first; the seeds' extensions by size, in tiers of how many points they match.

use nalgebra::Vector2;

use super::index::PointIndex;
use super::judgement::whole_view_points;
use super::lattice::{self, TargetLattice, grow, placements};
use super::search::SMALL_LATTICE_POINTS;
#[cfg(doc)]
use super::sparse::TripleSearch;

/// Groups of hypotheses (lists of (target point, blob) pairs) in the order they are verified; a group is made only
/// when the search reaches it (a large target's search stops at the first group that gives an accepted fit).
pub(super) type HypothesisGroups<'a> = Box<dyn Iterator<Item = Vec<Vec<(usize, usize)>>> + 'a>;

/// Hypotheses grouped by how many points they match, most first: a group is verified only if the larger ones gave
/// no accepted fit (rivals as good as the best have as many points, so they are in its group).
fn by_size(mut hypotheses: Vec<Vec<(usize, usize)>>) -> HypothesisGroups<'static> {
    hypotheses.sort_by_key(|h| std::cmp::Reverse(h.len()));
    let mut groups: Vec<Vec<Vec<(usize, usize)>>> = Vec::new();
    for h in hypotheses {
        match groups.last_mut() {
            Some(group) if group[0].len() == h.len() => group.push(h),
            _ => groups.push(vec![h]),
        }
    }
    Box::new(groups.into_iter())
}

/// The hypotheses of a search by seeds (triples, quadruples) that covers at least `fewest` points each
/// (`make(fewest)`, asked for fewer points each time: what it made for more points before may be left out),
/// grouped by size ([`by_size`]), made in tiers for a target of more than [`SMALL_LATTICE_POINTS`]: with
/// `complete_first`, first only those that match every point; then, if none of these is accepted, those that match a
/// whole view's worth of points (as many as acceptance allows missing: 85 %); then the rest. Each seed's extension
/// gives up as soon as too many points miss for its tier, so a wrong seed among clutter costs a few predictions instead
/// of nearly one per target point (for the complete tier, one miss refuses it); the hypotheses and their order are
/// those of one search down to `min_matched`, since a larger target's search stops at the first group that gives an
/// accepted fit, the largest first. A labelling of every point, accepted, is thus never searched beyond: any rival
/// that could beat or tie it must explain every point too, and every such hypothesis is in the complete tier (an
/// extension that matches every point misses none, whatever its tier allows). The complete tier pays when a view has
/// a point hidden; the triple search resumes its work for the next tier ([`TripleSearch`]), the quadruple search,
/// whose cost of a view with a point hidden has not been measured, does not ask for it.
pub(super) fn in_tiers<'a>(
    n: usize,
    min_matched: usize,
    complete_first: bool,
    make: impl FnMut(usize) -> Vec<Vec<(usize, usize)>> + 'a,
) -> HypothesisGroups<'a> {
    let whole_view = whole_view_points(n);
    let make = std::rc::Rc::new(std::cell::RefCell::new(make));
    // The hypotheses of at least `fewest` points and fewer than `above`, grouped, made when the search reaches them.
    let tier = |fewest: usize, above: usize| {
        let make = std::rc::Rc::clone(&make);
        std::iter::once_with(move || {
            let mut made = (make.borrow_mut())(fewest);
            made.retain(|h| h.len() < above);
            by_size(made)
        })
        .flatten()
    };
    if n <= SMALL_LATTICE_POINTS || whole_view <= min_matched {
        return Box::new(tier(min_matched, n + 1));
    }
    if complete_first {
        Box::new(
            tier(n, n + 1)
                .chain(tier(whole_view, n))
                .chain(tier(min_matched, whole_view)),
        )
    } else {
        Box::new(tier(whole_view, n + 1).chain(tier(min_matched, whole_view)))
    }
}

/// The lattice hypotheses: growth from a few seeds (each blob in one grown lattice at most), each lattice laid on the
/// target's every way; one group of hypotheses per grown lattice, the largest first.
pub(super) fn lattice_hypotheses(
    lattice: TargetLattice,
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
) -> HypothesisGroups<'static> {
    let grown_sets = grown_lattices(ideal, areas_px, index, usize::MAX);
    // First the placements that put nearly every grown blob on the target; then, if none verifies, those that leave
    // up to half of them off it: stray blobs where the lattice goes on beyond the target (printed marks, clutter)
    // join the growth and stick out of the target.
    // Made as the search asks for them: the lenient ones are many, and seldom needed.
    let count = grown_sets.len();
    Box::new((0..2 * count).map(move |k| {
        let (min_fraction, slack) = if k < count { (0.9, 1) } else { (0.5, 3) };
        placements(&lattice, &grown_sets[k % count], min_fraction, slack)
    }))
}

/// The lattices grown among the blobs (at most 3, of 4 nodes or more), the largest first: growth from a few seeds,
/// each blob in one grown lattice at most; a growth stops at `enough` nodes and no seed is grown after it (the
/// largest is then that one, of `enough` nodes; before it, every growth is the whole growth).
pub(super) fn grown_lattices(
    ideal: &[Vector2<f64>],
    areas_px: &[f64],
    index: &PointIndex,
    enough: usize,
) -> Vec<lattice::GrownLattice> {
    const SEEDS: usize = 12;
    let mut grown_sets: Vec<lattice::GrownLattice> = Vec::new();
    let mut covered = vec![false; ideal.len()];
    // Seeds: blobs whose neighbours are alike in size, tried from the most regular; a blob already in a grown
    // lattice is not a new seed.
    let mut near = Vec::new();
    let mut order: Vec<(usize, f64)> = (0..ideal.len())
        .filter(|&b| ideal[b].x.is_finite())
        .filter_map(|b| {
            index.neighbours_into(b, 4, 1e6, &mut near);
            if near.len() < 2 {
                return None;
            }
            let alike = near
                .iter()
                .filter(|&&(o, _)| {
                    areas_px[o] < 1.5 * areas_px[b] && areas_px[o] > areas_px[b] / 1.5
                })
                .count();
            let spread = near[near.len() - 1].1 / near[0].1.max(1e-9);
            Some((b, alike as f64 - 0.5 * spread))
        })
        .collect();
    order.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut attempts = 0;
    for &(seed, _) in &order {
        if attempts >= SEEDS {
            break;
        }
        if covered[seed] {
            continue;
        }
        attempts += 1;
        let near = index.neighbours(seed, 6, 1e6);
        let Some(&(first, d1)) = near.first() else {
            continue;
        };
        let e1 = ideal[first] - ideal[seed];
        let second = near.iter().skip(1).find(|&&(o, d)| {
            let e2 = ideal[o] - ideal[seed];
            (e1.x * e2.y - e1.y * e2.x).abs() > 0.5 * d1 * d
        });
        let Some(&(second, _)) = second else { continue };
        if covered[first] || covered[second] {
            continue;
        }
        let grown = grow(
            ideal, areas_px, index, &covered, seed, first, second, enough,
        );
        for &(_, _, b) in &grown.nodes {
            covered[b] = true;
        }
        let done = grown.nodes.len() >= enough;
        grown_sets.push(grown);
        if done {
            break;
        }
    }
    grown_sets.sort_by_key(|g| std::cmp::Reverse(g.nodes.len()));
    grown_sets
        .into_iter()
        .take(3)
        .filter(|g| g.nodes.len() >= 4)
        .collect()
}
