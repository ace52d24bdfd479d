//! The second- and third-order moment sums of a component for the shape check ([`crate::symmetry`]), with SSE2, over
//! a window of up to 4 vectors (32 columns) holding the component, `v = value -sat threshold` a row at a time:
//!
//! - per row, the sums `P0 = Σ v` and `P1 = Σ v i` (`_mm_madd_epi16` against the columns' powers, into 32-bit lanes),
//!   and running sums of them (P0 four deep, P1 three), whence `Σ y^q P0` (q <= 3) and `Σ y^q P1` (q <= 2);
//! - per column, in 16-bit lanes, `A = Σ v` and its running sum `B` (one addition each a vector a row), whence
//!   `Σ i² A`, `Σ i³ A` and `Σ i² B` at the end: the sums of `v i²`, `v i³` and `v i² y`.
//!
//! All are folded into exact totals at the end of blocks of rows short enough for no lane to overflow. Where the CPU
//! has AVX2 and the window is 2 to 4 8-pixel vectors, the same in 16-pixel vectors (and an 8-pixel one). Integer sums:
//! the same as the portable ones to the bit, whichever instructions.

use std::arch::x86_64::*;

use crate::centroid::moments::ShapeSums;

/// Widest window (vectors of 8 columns): the cube of a column, below 32, fits a 16-bit lane.
pub(super) const MAX_VECTORS: usize = 4;

/// Column `i` to the power `p`, for the columns 0 to 31 of a window.
const fn powers(p: u32) -> [i16; 32] {
    let mut out = [0i16; 32];
    let mut i = 0;
    while i < 32 {
        out[i] = (i as i16).pow(p);
        i += 1;
    }
    out
}
static POWERS: [[i16; 32]; 4] = [powers(0), powers(1), powers(2), powers(3)];

/// Sum of `i^p` for `i` in `0..n` (`p <= 3`).
fn power_sum(n: u64, p: usize) -> u64 {
    let m = n.saturating_sub(1);
    match p {
        0 => n,
        1 => n * m / 2,
        2 => m * n * (2 * n - 1) / 6,
        _ => (n * m / 2) * (n * m / 2),
    }
}

/// `C(n + k - 1, k)` (`1 <= k <= 4`): the largest weight of a row in the `k`-th running sum over `n` rows.
fn running_weight(n: u64, k: usize) -> u64 {
    match k {
        1 => n,
        2 => n * (n + 1) / 2,
        3 => n * (n + 1) * (n + 2) / 6,
        _ => n * (n + 1) * (n + 2) * (n + 3) / 24,
    }
}

/// Rows of a block that no sum can overflow in: the largest `b <= rows` with the 32-bit totals below 2^32 and the
/// 16-bit column sums below 2^16, given `v <= vmax` in `vectors` vectors; 0 if not even one row fits.
fn block_rows(vmax: u64, vectors: usize, rows: u64) -> u64 {
    let lanes = 8 * vectors as u64;
    let row: [u64; 4] = std::array::from_fn(|p| vmax * power_sum(lanes, p));
    let fits = |b: u64| {
        let (once, twice) = (running_weight(b, 1), running_weight(b, 2));
        running_weight(b, 4) * row[0] < 1 << 32
            && running_weight(b, 3) * row[1] < 1 << 32
            && twice * vmax < 1 << 16
            && once * row[3] < 1 << 32
            && twice * row[2] < 1 << 32
    };
    if fits(rows) {
        return rows;
    }
    let (mut lo, mut hi) = (0, rows);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if fits(mid) { lo = mid } else { hi = mid }
    }
    lo
}

/// The sum of the four 32-bit lanes (kept below 2^32 by the blocks).
#[inline(always)]
fn hsum(v: __m128i) -> u32 {
    // SAFETY: SSE2 is part of the x86_64 baseline.
    unsafe {
        let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b01_00_11_10));
        let v = _mm_add_epi32(v, _mm_shuffle_epi32(v, 0b10_11_00_01));
        _mm_cvtsi128_si32(v) as u32
    }
}

/// `acc` plus the products of the unsigned 16-bit lanes of `a` and `w`, in 32-bit lanes.
#[inline(always)]
fn add_products(acc: __m128i, a: __m128i, w: __m128i) -> __m128i {
    // SAFETY: SSE2 is part of the x86_64 baseline.
    unsafe {
        let (lo, hi) = (_mm_mullo_epi16(a, w), _mm_mulhi_epu16(a, w));
        let products = _mm_add_epi32(_mm_unpacklo_epi16(lo, hi), _mm_unpackhi_epi16(lo, hi));
        _mm_add_epi32(acc, products)
    }
}

/// The sums of `v = value -sat threshold` over the component (rows `lo..=hi`, within columns `s..s + 8 * vectors`),
/// times `x^p y^q` (p + q <= 3), x from column `s`, y from row `lo`. `comp`: the component's rows (bit i column i),
/// or `None` when every above-threshold pixel of those rows is the component's. `None` when the values or the window
/// are too large for 16-bit products (`vmax > 32767`, more than [`MAX_VECTORS`] vectors) or one row's sums for 32
/// bits. With `avx2` (only where the CPU has it), 16-pixel vectors (and an 8-pixel one where `vectors` is odd).
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn shape_sums(
    px: &[u16],
    w: usize,
    comp: Option<&[u64]>,
    rows: (usize, usize),
    s: usize,
    vectors: usize,
    threshold: u16,
    vmax: u16,
    avx2: bool,
) -> Option<ShapeSums> {
    if vectors > MAX_VECTORS || vmax > i16::MAX as u16 || s + 8 * vectors > w {
        return None;
    }
    let block = block_rows(u64::from(vmax), vectors, (rows.1 - rows.0 + 1) as u64) as usize;
    if block == 0 {
        return None;
    }
    if avx2 && vectors >= 2 {
        assert!(std::arch::is_x86_feature_detected!("avx2"));
        macro_rules! wide {
            ($m:literal, $half:literal) => {
                // SAFETY: the CPU has AVX2 (checked above).
                unsafe {
                    match comp {
                        Some(comp) => {
                            sums_in_avx2::<$m, $half, true>(px, w, comp, rows, s, threshold, block)
                        }
                        None => {
                            sums_in_avx2::<$m, $half, false>(px, w, &[], rows, s, threshold, block)
                        }
                    }
                }
            };
        }
        return Some(match vectors {
            2 => wide!(1, false),
            3 => wide!(1, true),
            _ => wide!(2, false),
        });
    }
    macro_rules! window {
        ($n:literal) => {
            match comp {
                Some(comp) => sums_in::<$n, true>(px, w, comp, rows, s, threshold, block),
                None => sums_in::<$n, false>(px, w, &[], rows, s, threshold, block),
            }
        };
    }
    Some(match vectors {
        1 => window!(1),
        2 => window!(2),
        3 => window!(3),
        _ => window!(4),
    })
}

/// [`shape_sums`] over `N` vectors, of the pixels of `comp` (`COMP`) or of every above-threshold pixel, in blocks of
/// `block` rows.
// Indices, not iterators: a row's index picks its component row and its running position, a vector's its columns.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn sums_in<const N: usize, const COMP: bool>(
    px: &[u16],
    w: usize,
    comp: &[u64],
    (lo, hi): (usize, usize),
    s: usize,
    threshold: u16,
    block: usize,
) -> ShapeSums {
    // Order of `sums`: 00, 10, 01, 20, 11, 02, 30, 21, 12, 03.
    let mut sums = [0i64; 10];
    assert!(lo <= hi && (hi + 1) * w <= px.len() && s + 8 * N <= w);
    // SAFETY: SSE2 is part of the x86_64 baseline; every load reads 8 pixels of a row `lo..=hi` inside `px` (checked
    // above: columns `s..s + 8 N` within `w`) or 8 entries of a 32-entry column table (N <= 4).
    unsafe {
        let load = |a: &[i16], k: usize| _mm_loadu_si128(a[8 * k..8 * k + 8].as_ptr().cast());
        let cols: [[__m128i; N]; 4] =
            std::array::from_fn(|p| std::array::from_fn(|k| load(&POWERS[p], k)));
        let t = _mm_set1_epi16(threshold as i16);
        let lane_bit = _mm_setr_epi16(1, 2, 4, 8, 16, 32, 64, 128);
        let z = _mm_setzero_si128();
        // Running sums of P0 (four deep) and P1 (three deep); per column, A and B.
        let mut run = [z; 7];
        let (mut col_a, mut col_b) = ([z; N], [z; N]);
        let mut in_block = 0;
        let mut row = px.as_ptr().add(lo * w + s);
        for j in lo..=hi {
            let (mut p0, mut p1) = (z, z);
            for k in 0..N {
                let mut v = _mm_subs_epu16(_mm_loadu_si128(row.add(8 * k).cast()), t);
                if COMP {
                    let byte = _mm_set1_epi16(((comp[j] >> (s + 8 * k)) & 0xFF) as i16);
                    let keep = _mm_cmpeq_epi16(_mm_and_si128(byte, lane_bit), lane_bit);
                    v = _mm_and_si128(v, keep);
                }
                p0 = _mm_add_epi32(p0, _mm_madd_epi16(v, cols[0][k]));
                p1 = _mm_add_epi32(p1, _mm_madd_epi16(v, cols[1][k]));
                col_a[k] = _mm_add_epi16(col_a[k], v);
                col_b[k] = _mm_add_epi16(col_b[k], col_a[k]);
            }
            row = row.add(w);
            run[0] = _mm_add_epi32(run[0], p0);
            run[1] = _mm_add_epi32(run[1], run[0]);
            run[2] = _mm_add_epi32(run[2], run[1]);
            run[3] = _mm_add_epi32(run[3], run[2]);
            run[4] = _mm_add_epi32(run[4], p1);
            run[5] = _mm_add_epi32(run[5], run[4]);
            run[6] = _mm_add_epi32(run[6], run[5]);
            in_block += 1;
            if in_block == block || j == hi {
                // The columns' sums weighted by the columns' powers.
                let (mut a2, mut a3, mut b2) = (z, z, z);
                for k in 0..N {
                    a2 = add_products(a2, col_a[k], cols[2][k]);
                    a3 = add_products(a3, col_a[k], cols[3][k]);
                    b2 = add_products(b2, col_b[k], cols[2][k]);
                }
                let h: [i64; 7] = std::array::from_fn(|k| i64::from(hsum(run[k])));
                let (a2, a3, b2) = (hsum(a2), hsum(a3), hsum(b2));
                fold(
                    &mut sums,
                    h,
                    [a2, a3, b2].map(i64::from),
                    (j + 1 - lo) as i64,
                );
                run = [z; 7];
                col_a = [z; N];
                col_b = [z; N];
                in_block = 0;
            }
        }
    }
    ShapeSums::from_i64(sums)
}

/// [`sums_in`] with AVX2, over `M` vectors of 16 pixels and, with `HALF`, one of 8 after them.
// Indices, not iterators: as `sums_in`.
#[allow(clippy::needless_range_loop)]
#[target_feature(enable = "avx2")]
fn sums_in_avx2<const M: usize, const HALF: bool, const COMP: bool>(
    px: &[u16],
    w: usize,
    comp: &[u64],
    (lo, hi): (usize, usize),
    s: usize,
    threshold: u16,
    block: usize,
) -> ShapeSums {
    let mut sums = [0i64; 10];
    let width = 16 * M + if HALF { 8 } else { 0 };
    assert!(lo <= hi && (hi + 1) * w <= px.len() && s + width <= w && width <= 32);
    let load = |a: &[i16], m: usize| {
        let a: &[i16; 16] = a[16 * m..16 * m + 16].try_into().expect("16 entries");
        // SAFETY: `a` is 32 readable bytes; `_mm256_loadu_si256` reads 32 bytes at any alignment.
        unsafe { _mm256_loadu_si256(a.as_ptr().cast()) }
    };
    // The 8-pixel vector's columns (unused without `HALF`, where they may be past the table).
    let half = if HALF { 16 * M } else { 0 };
    let load_half = |a: &[i16]| {
        let a: &[i16; 8] = a[half..half + 8].try_into().expect("8 entries");
        // SAFETY: `a` is 16 readable bytes; `_mm_loadu_si128` reads 16 bytes at any alignment.
        unsafe { _mm_loadu_si128(a.as_ptr().cast()) }
    };
    let cols: [[__m256i; M]; 4] =
        std::array::from_fn(|p| std::array::from_fn(|m| load(&POWERS[p], m)));
    let cols_half: [__m128i; 4] = std::array::from_fn(|p| load_half(&POWERS[p]));
    let t = _mm256_set1_epi16(threshold as i16);
    let t_half = _mm_set1_epi16(threshold as i16);
    let lane_bit = _mm256_setr_epi16(
        1,
        2,
        4,
        8,
        16,
        32,
        64,
        128,
        256,
        512,
        1024,
        2048,
        4096,
        8192,
        16384,
        i16::MIN,
    );
    let lane_bit_half = _mm_setr_epi16(1, 2, 4, 8, 16, 32, 64, 128);
    let z = _mm256_setzero_si256();
    let z_half = _mm_setzero_si128();
    let mut run = [z; 7];
    let (mut col_a, mut col_b) = ([z; M], [z; M]);
    let (mut half_a, mut half_b) = (z_half, z_half);
    let mut in_block = 0;
    for j in lo..=hi {
        let row: &[u16] = &px[j * w + s..j * w + s + width];
        let (mut p0, mut p1) = (z, z);
        for m in 0..M {
            // SAFETY: 16 pixels of `row` from 16 m (`width >= 16 M`): 32 readable bytes.
            let pixels = unsafe { _mm256_loadu_si256(row[16 * m..].as_ptr().cast()) };
            let mut v = _mm256_subs_epu16(pixels, t);
            if COMP {
                let bits = ((comp[j] >> (s + 16 * m)) & 0xFFFF) as u16 as i16;
                let bits = _mm256_set1_epi16(bits);
                let keep = _mm256_cmpeq_epi16(_mm256_and_si256(bits, lane_bit), lane_bit);
                v = _mm256_and_si256(v, keep);
            }
            p0 = _mm256_add_epi32(p0, _mm256_madd_epi16(v, cols[0][m]));
            p1 = _mm256_add_epi32(p1, _mm256_madd_epi16(v, cols[1][m]));
            col_a[m] = _mm256_add_epi16(col_a[m], v);
            col_b[m] = _mm256_add_epi16(col_b[m], col_a[m]);
        }
        if HALF {
            // SAFETY: the 8 pixels of `row` from 16 M (`width = 16 M + 8`): 16 readable bytes.
            let pixels = unsafe { _mm_loadu_si128(row[16 * M..].as_ptr().cast()) };
            let mut v = _mm_subs_epu16(pixels, t_half);
            if COMP {
                let bits = _mm_set1_epi16(((comp[j] >> (s + 16 * M)) & 0xFF) as i16);
                let keep = _mm_cmpeq_epi16(_mm_and_si128(bits, lane_bit_half), lane_bit_half);
                v = _mm_and_si128(v, keep);
            }
            let q0 = _mm_madd_epi16(v, cols_half[0]);
            let q1 = _mm_madd_epi16(v, cols_half[1]);
            p0 = _mm256_add_epi32(p0, _mm256_zextsi128_si256(q0));
            p1 = _mm256_add_epi32(p1, _mm256_zextsi128_si256(q1));
            half_a = _mm_add_epi16(half_a, v);
            half_b = _mm_add_epi16(half_b, half_a);
        }
        run[0] = _mm256_add_epi32(run[0], p0);
        run[1] = _mm256_add_epi32(run[1], run[0]);
        run[2] = _mm256_add_epi32(run[2], run[1]);
        run[3] = _mm256_add_epi32(run[3], run[2]);
        run[4] = _mm256_add_epi32(run[4], p1);
        run[5] = _mm256_add_epi32(run[5], run[4]);
        run[6] = _mm256_add_epi32(run[6], run[5]);
        in_block += 1;
        if in_block == block || j == hi {
            let products = |acc: __m256i, a: __m256i, w: __m256i| {
                let (lo, hi) = (_mm256_mullo_epi16(a, w), _mm256_mulhi_epu16(a, w));
                let p =
                    _mm256_add_epi32(_mm256_unpacklo_epi16(lo, hi), _mm256_unpackhi_epi16(lo, hi));
                _mm256_add_epi32(acc, p)
            };
            let (mut a2, mut a3, mut b2) = (z, z, z);
            for m in 0..M {
                a2 = products(a2, col_a[m], cols[2][m]);
                a3 = products(a3, col_a[m], cols[3][m]);
                b2 = products(b2, col_b[m], cols[2][m]);
            }
            let narrow = |v: __m256i| {
                _mm_add_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1))
            };
            let (mut a2, mut a3, mut b2) = (narrow(a2), narrow(a3), narrow(b2));
            if HALF {
                a2 = add_products(a2, half_a, cols_half[2]);
                a3 = add_products(a3, half_a, cols_half[3]);
                b2 = add_products(b2, half_b, cols_half[2]);
            }
            let h: [i64; 7] = std::array::from_fn(|k| i64::from(hsum(narrow(run[k]))));
            let cols_sums = [hsum(a2), hsum(a3), hsum(b2)].map(i64::from);
            fold(&mut sums, h, cols_sums, (j + 1 - lo) as i64);
            run = [z; 7];
            col_a = [z; M];
            col_b = [z; M];
            (half_a, half_b) = (z_half, z_half);
            in_block = 0;
        }
    }
    ShapeSums::from_i64(sums)
}

/// Folds a block's totals into `sums`: `run` the running sums of P0 (four deep) and P1 (three deep), `cols` the sums
/// `Σ i² A`, `Σ i³ A` and `Σ i² B` of the columns' sums; `l` the row after the block's last, relative to the
/// component's first row. (Every term stays below 2^51: `l <= 64`, the totals below 2^32.)
#[inline(always)]
fn fold(sums: &mut [i64; 10], run: [i64; 7], [a2, a3, b2]: [i64; 3], l: i64) {
    // Running sums give Σ u^k P with u = last + 1 - y >= 1: Σ u P = b, Σ u² P = 2c - b, Σ u³ P = 6d - 6c + b; then
    // y = l - u.
    let moments = |a: i64, b: i64, c: i64, d: i64| {
        let (u1, u2, u3) = (b, 2 * c - b, 6 * d - 6 * c + b);
        (
            a,
            l * a - u1,
            l * l * a - 2 * l * u1 + u2,
            l * l * l * a - 3 * l * l * u1 + 3 * l * u2 - u3,
        )
    };
    let (s00, s01, s02, s03) = moments(run[0], run[1], run[2], run[3]);
    let (s10, s11, s12, _) = moments(run[4], run[5], run[6], 0);
    // B is the running sum of A down the block: Σ i² B = Σ u v i².
    let s21 = l * a2 - b2;
    let block = [s00, s10, s01, a2, s11, s02, a3, s21, s12, s03];
    for (total, x) in sums.iter_mut().zip(block) {
        *total += x;
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::centroid::component::grow_component;
    use crate::centroid::kernels::portable;
    use crate::centroid::moments::scalar_shape_sums;
    use crate::centroid::test_rois::synthetic;

    /// With SSE2 and with AVX2 (where the CPU has it), every window the component fits, the sums are the portable
    /// ones to the bit: synthetic ROIs of 8 to 64 columns, 8- to 16-bit pixels, thresholds from 0 to the peak, of the
    /// grown component and of the whole rows.
    #[test]
    fn sse2_and_avx2_sums_are_the_portable_ones() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(31);
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        let mut compared = [0usize; 2];
        for case in 0..4000 {
            let (w, h) = (rng.random_range(8..=64usize), rng.random_range(1..=64usize));
            let pixels = synthetic(&mut rng, w, h, case);
            let (peak, seed) = portable::peak(&pixels);
            if peak == 0 {
                continue;
            }
            let threshold = rng.random_range(0..peak);
            let mut mask = vec![0u64; h];
            portable::row_masks(&pixels, w, threshold, &mut mask);
            let mut comp = vec![0u64; h];
            let (lo, hi) = grow_component(&mask, seed % w, seed / w, &mut comp);
            let cols = comp.iter().fold(0, |acc, &c| acc | c);
            let (first, last) = (
                cols.trailing_zeros() as usize,
                63 - cols.leading_zeros() as usize,
            );
            let vectors = (last - first) / 8 + 1;
            if 8 * vectors > w {
                continue;
            }
            let s = first.min(w - 8 * vectors);
            let vmax = peak - threshold;
            for whole in [false, true] {
                // With `None`, every above-threshold pixel of the rows and the window's columns counts.
                let (component, span) = if whole {
                    (None, (s, s + 8 * vectors - 1))
                } else {
                    (Some(comp.as_slice()), (first, last))
                };
                let expected = scalar_shape_sums(
                    &pixels,
                    w,
                    component,
                    (lo, hi),
                    span,
                    s,
                    (threshold, u16::MAX),
                );
                for (k, wide) in [false, true].into_iter().enumerate() {
                    if wide && !avx2 {
                        continue;
                    }
                    let found = shape_sums(
                        &pixels,
                        w,
                        component,
                        (lo, hi),
                        s,
                        vectors,
                        threshold,
                        vmax,
                        wide,
                    );
                    if let Some(found) = found {
                        assert_eq!(
                            found, expected,
                            "{w}x{h} case {case} whole {whole} avx2 {wide}"
                        );
                        compared[k] += usize::from(!wide || vectors >= 2);
                    }
                }
            }
        }
        assert!(compared[0] > 2000, "{compared:?}");
        assert!(!avx2 || compared[1] > 1500, "{compared:?}");
    }
}
