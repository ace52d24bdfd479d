//! The connected component of the brightest pixel, from the rows' above-threshold masks (one `u64` a row): the
//! common convex case (every row a single run touching the next) checked directly, any other grown a whole row at a
//! time with bit operations (the run of set bits of `m` from a seed bit `s` towards the high bits is
//! `((m + s) ^ m) & m`).
//!
//! Bit operations on whole rows, no pixels: the masks come from [`super::kernels`], the moments from
//! [`super::moments`].

use super::MAX_ROI_HEIGHT;
use super::kernels::{self, Isa};
use super::moments::{Moments, moments};

/// The runs of `mask` containing a bit of `seeds` (one iteration per run: usually one).
#[inline]
fn run_fill(mask: u64, seeds: u64) -> u64 {
    let mut s = seeds & mask;
    let mut runs = 0;
    while s != 0 {
        let low = s & s.wrapping_neg();
        // From the lowest seed up to the run's end: the carry of `mask + low` runs through the run.
        let up = (mask.wrapping_add(low) ^ mask) & mask;
        // Below it, down to the mask's highest gap under it.
        let below = low - 1;
        let gaps = !mask & below;
        let down = below & !u64::MAX.checked_shr(gaps.leading_zeros()).unwrap_or(0);
        runs |= up | down;
        s &= !runs;
    }
    runs
}

/// The bits of `x` and their left and right neighbours.
#[inline]
pub(super) fn dilate(x: u64) -> u64 {
    x | (x << 1) | (x >> 1)
}

/// Whether `m` (non-zero) is a single run of set bits (adding its lowest bit carries through the run).
#[inline]
pub(super) fn single_run(m: u64) -> bool {
    m & m.wrapping_add(m & m.wrapping_neg()) == 0
}

/// The first and last rows of the seed's component when the non-empty rows of `mask` around the seed's (row
/// `seed_j`) are single runs each touching the next (a convex blob's, nearly always): that component is then these
/// rows' masks whole. `None` otherwise (then see [`grow_component`]).
pub(super) fn simple_rows(mask: &[u64], seed_j: usize) -> Option<(usize, usize)> {
    if !single_run(mask[seed_j]) {
        return None;
    }
    let mut hi = seed_j;
    for pair in mask[seed_j..].windows(2) {
        let (above, m) = (pair[0], pair[1]);
        if m == 0 {
            break;
        }
        if !single_run(m) || dilate(above) & m == 0 {
            return None;
        }
        hi += 1;
    }
    let mut lo = seed_j;
    for pair in mask[..=seed_j].windows(2).rev() {
        let (m, below) = (pair[0], pair[1]);
        if m == 0 {
            break;
        }
        if !single_run(m) || dilate(below) & m == 0 {
            return None;
        }
        lo -= 1;
    }
    Some((lo, hi))
}

/// The 8-connected component of `mask` (one `u64` per row) containing bit `seed_i` of row `seed_j`, into `comp`
/// (zeroed on entry). Returns its first and last rows.
pub(super) fn grow_component(
    mask: &[u64],
    seed_i: usize,
    seed_j: usize,
    comp: &mut [u64],
) -> (usize, usize) {
    let h = mask.len();
    comp[seed_j] = run_fill(mask[seed_j], 1u64 << seed_i);
    let (mut lo, mut hi) = (seed_j, seed_j);
    let (mut need_down, mut need_up) = (true, true);
    // The first upward sweep starts above the seed's row unless the first downward one found pixels below it
    // touching runs of their upper rows outside the component; later ones start at `hi`.
    let mut up_from = seed_j;
    while need_down || need_up {
        if need_down {
            need_down = false;
            for j in lo + 1..h {
                let new = run_fill(mask[j], comp[j] | dilate(comp[j - 1]));
                if new != comp[j] {
                    comp[j] = new;
                    // New pixels may reach runs of the row above that the last upward sweep missed.
                    if dilate(new) & mask[j - 1] & !comp[j - 1] != 0 {
                        need_up = true;
                        up_from = h;
                    }
                }
                if new != 0 {
                    hi = hi.max(j);
                } else if j > hi {
                    break;
                }
            }
        }
        if need_up {
            need_up = false;
            for j in (0..hi.min(up_from)).rev() {
                let new = run_fill(mask[j], comp[j] | dilate(comp[j + 1]));
                if new != comp[j] {
                    comp[j] = new;
                    need_down |= dilate(new) & mask[j + 1] & !comp[j + 1] != 0;
                }
                if new != 0 {
                    lo = lo.min(j);
                } else if j < lo {
                    break;
                }
            }
            up_from = h;
        }
    }
    (lo, hi)
}

/// The component of the seed pixel `(seed_i, seed_j)` (its moments, first and last rows and union of columns) from
/// the threshold mask of every row; `true` last when it is not simple (not every above-threshold pixel of its rows is
/// its own: see [`component_rows`]).
#[inline]
pub(super) fn component_moments(
    isa: Isa,
    pixels: &[u16],
    (w, h): (usize, usize),
    (seed_i, seed_j): (usize, usize),
    levels: (u16, u16),
) -> (Moments, (usize, usize), u64, bool) {
    let mut mask_rows = [0u64; MAX_ROI_HEIGHT as usize];
    kernels::row_masks(isa, pixels, w, levels.0, &mut mask_rows[..h]);
    let mask = &mask_rows[..h];
    let mut comp_rows = [0u64; MAX_ROI_HEIGHT as usize];
    let (comp, lo, hi, grown) = match simple_rows(mask, seed_j) {
        Some((lo, hi)) => (mask, lo, hi, false),
        None => {
            let (lo, hi) = grow_component(mask, seed_i, seed_j, &mut comp_rows[..h]);
            (&comp_rows[..h], lo, hi, true)
        }
    };
    let cols = comp[lo..=hi].iter().fold(0, |acc, &c| acc | c);
    (
        moments(isa, pixels, w, comp, mask, (lo, hi), cols, levels),
        (lo, hi),
        cols,
        grown,
    )
}

/// The rows of the component of the seed pixel (bit i column i) into `comp` (`h` rows, zeroed on entry).
pub(super) fn component_rows(
    isa: Isa,
    pixels: &[u16],
    (w, h): (usize, usize),
    (seed_i, seed_j): (usize, usize),
    threshold: u16,
    comp: &mut [u64],
) {
    let mut mask_rows = [0u64; MAX_ROI_HEIGHT as usize];
    kernels::row_masks(isa, pixels, w, threshold, &mut mask_rows[..h]);
    grow_component(&mask_rows[..h], seed_i, seed_j, comp);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_fill_finds_runs_through_seeds() {
        let mask = 0b0111_0110_1100u64;
        assert_eq!(run_fill(mask, 0b0000_0010_0000), 0b0000_0110_0000);
        assert_eq!(run_fill(mask, 0b0100_0000_1000), 0b0111_0000_1100);
        assert_eq!(run_fill(mask, 0b1000_0001_0000), 0);
        assert_eq!(run_fill(u64::MAX, 1 << 40), u64::MAX);
        assert_eq!(run_fill(u64::MAX << 60, 1 << 63), u64::MAX << 60);
        // Several seeds in one run.
        assert_eq!(run_fill(0b0111_1110, 0b0101_0110), 0b0111_1110);
        assert_eq!(run_fill(0b1111, 0b1111), 0b1111);
        assert_eq!(run_fill(u64::MAX, u64::MAX), u64::MAX);
    }

    /// The 8-connected component of `seed` by a plain flood fill.
    fn naive_component(mask: &[u64], w: usize, seed: (usize, usize)) -> Vec<u64> {
        let h = mask.len();
        let mut comp = vec![0u64; h];
        let mut stack = vec![seed];
        while let Some((i, j)) = stack.pop() {
            if (mask[j] >> i) & 1 == 0 || (comp[j] >> i) & 1 == 1 {
                continue;
            }
            comp[j] |= 1 << i;
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    let (ni, nj) = (i as i64 + di, j as i64 + dj);
                    if ni >= 0 && nj >= 0 && (ni as usize) < w && (nj as usize) < h {
                        stack.push((ni as usize, nj as usize));
                    }
                }
            }
        }
        comp
    }

    #[test]
    fn bit_parallel_component_matches_a_flood_fill() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for case in 0..3000 {
            let w = rng.random_range(1..=64usize);
            let h = rng.random_range(1..=64usize);
            let density = rng.random_range(0.2..0.7);
            let width_mask = u64::MAX >> (64 - w);
            let mask: Vec<u64> = (0..h)
                .map(|_| {
                    (0..w).fold(0u64, |m, i| m | (u64::from(rng.random_bool(density)) << i))
                        & width_mask
                })
                .collect();
            let (i, j) = (rng.random_range(0..w), rng.random_range(0..h));
            if (mask[j] >> i) & 1 == 0 {
                continue;
            }
            let mut comp = vec![0u64; h];
            let (lo, hi) = grow_component(&mask, i, j, &mut comp);
            let expected = naive_component(&mask, w, (i, j));
            assert_eq!(comp, expected, "case {case}: {w}x{h}");
            assert_eq!(lo, expected.iter().position(|&c| c != 0).unwrap());
            assert_eq!(hi, expected.iter().rposition(|&c| c != 0).unwrap());
        }
    }
}
