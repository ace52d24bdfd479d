//! The order in which ROIs visit the target's points.

/// How a camera cycles through the points, one ROI each.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RoiOrder {
    /// Bit-reversed index order (0 8 4 12 2 10 6 14 1 9 5 13 3 11 7 15 for 16 points): consecutive ROIs are spread
    /// over the target, which keeps the 12-dof window well conditioned (docs/model.md). The default.
    #[default]
    BitReversed,
    /// Index order 0, 1, ..., n-1. On a planar grid a one-cycle window is exactly singular (docs/model.md).
    RowMajor,
    /// A fresh random permutation every cycle.
    Random,
}

/// The bit-reversed permutation of `0..n`: indices of the next power of two in bit-reversed order, those `>= n`
/// skipped.
pub fn bit_reversed_indices(n: usize) -> Vec<usize> {
    if n <= 1 {
        return (0..n).collect();
    }
    let bits = usize::BITS - (n - 1).leading_zeros();
    (0..1usize << bits)
        .map(|i| i.reverse_bits() >> (usize::BITS - bits))
        .filter(|&i| i < n)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_reversed_sixteen_matches_the_spec() {
        assert_eq!(
            bit_reversed_indices(16),
            vec![0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15]
        );
    }

    #[test]
    fn bit_reversed_is_a_permutation_for_any_size() {
        for n in 0..40 {
            let mut order = bit_reversed_indices(n);
            order.sort_unstable();
            assert_eq!(order, (0..n).collect::<Vec<_>>());
        }
    }
}
