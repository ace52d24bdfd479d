//! The kernels that scan pixels once each, written once over [`Lanes`]: the peak and its first position and the
//! border's minimum, maximum and sum (pass 1 of [`crate::centroid::measure_blob`]), and the rows' above-threshold
//! masks (for components that are not simple, and for the symmetry check's outline).
//!
//! Whole vectors first; the last pixels of a slice, fewer than a vector, as a [`Lanes::span`] whose lanes the
//! instruction set fills its own way (SSE2 reads the slice's last whole vector again, AVX-512 loads under a mask), so
//! every kernel here counts only the span's own lanes where others could matter (a sum, a minimum, a first position).
//! Each is `#[inline(always)]`: it is instantiated inside an instruction set's `#[target_feature]` entry point.

use super::lanes::Lanes;

/// The largest pixel of `px` and the index of its first occurrence (`px.len() >= L::MIN_PIXELS`): four vectors at a
/// time (independent maxima), then the first four vectors holding the peak, then the pixel.
#[inline(always)]
pub(super) fn peak<L: Lanes>(l: L, px: &[u16]) -> (u16, usize) {
    let width = L::WIDTH;
    let z = l.zero();
    let mut m = [z; 4];
    let mut quads = px.chunks_exact(4 * width);
    for quad in quads.by_ref() {
        for (k, m) in m.iter_mut().enumerate() {
            *m = l.max(*m, l.load(quad, k * width));
        }
    }
    let mut vectors = quads.remainder().chunks_exact(width);
    for v in vectors.by_ref() {
        m[0] = l.max(m[0], l.load(v, 0));
    }
    let rest = vectors.remainder().len();
    let tail = (rest > 0).then(|| l.span(px.len() - rest, px.len()));
    if let Some(tail) = tail {
        // Lanes outside the span hold 0 or pixels already seen: harmless for a maximum.
        m[1] = l.max(m[1], l.load_span(px, tail));
    }
    let peak = l.hmax(l.max(l.max(m[0], m[1]), l.max(m[2], m[3])));

    let s = l.splat(peak);
    let mut quads = px.chunks_exact(4 * width);
    for (c, quad) in quads.by_ref().enumerate() {
        let v: [L::V; 4] = std::array::from_fn(|k| l.load(quad, k * width));
        // Whether the four vectors hold the peak: whether their maximum is it.
        if l.eq_bits(l.max(l.max(v[0], v[1]), l.max(v[2], v[3])), s) != 0 {
            for (k, &v) in v.iter().enumerate() {
                let bits = l.eq_bits(v, s);
                if bits != 0 {
                    return (peak, (4 * c + k) * width + bits.trailing_zeros() as usize);
                }
            }
        }
    }
    let done = px.len() - quads.remainder().len();
    for (c, v) in quads.remainder().chunks_exact(width).enumerate() {
        let bits = l.eq_bits(l.load(v, 0), s);
        if bits != 0 {
            return (peak, done + c * width + bits.trailing_zeros() as usize);
        }
    }
    if let Some(tail) = tail {
        let bits = l.eq_bits(l.load_span(px, tail), s) & l.keep_bits(l.span_keep(tail));
        if bits != 0 {
            return (peak, l.span_offset(tail) + bits.trailing_zeros() as usize);
        }
    }
    // Not reached: the peak is one of the pixels.
    (peak, 0)
}

/// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image (`w - 1 >= L::MIN_PIXELS`,
/// `h >= 2`): the top row but its last pixel, the bottom row but its first, and the (last, first) pixel pairs of
/// consecutive rows, which are adjacent in memory.
#[inline(always)]
pub(super) fn border_min_max_sum<L: Lanes>(
    l: L,
    px: &[u16],
    w: usize,
    h: usize,
) -> (u16, u16, u64) {
    let mut acc = l.min_max_sum();
    for seg in [&px[..w - 1], &px[(h - 1) * w + 1..h * w]] {
        let mut vectors = seg.chunks_exact(L::WIDTH);
        for v in vectors.by_ref() {
            l.mms_add(&mut acc, l.load(v, 0));
        }
        let rest = vectors.remainder().len();
        if rest > 0 {
            let tail = l.span(seg.len() - rest, seg.len());
            l.mms_add_kept(
                &mut acc,
                l.load_span(seg, tail),
                l.span_keep(tail),
                rest as u64,
            );
        }
    }
    // Pair j (rows j and j + 1) at `j * w` in `pairs`, half a vector of pairs at a time.
    let pairs = &px[w - 1..(h - 1) * w + 1];
    let per_vector = L::WIDTH / 2;
    let mut first = 0;
    while first + per_vector < h {
        l.mms_add(&mut acc, l.pairs(pairs, w, first, per_vector));
        first += per_vector;
    }
    let n = h - 1 - first;
    if n > 0 {
        let v = l.pairs(pairs, w, first, n);
        l.mms_add_kept(&mut acc, v, l.first_lanes(2 * n), 2 * n as u64);
    }
    l.mms_finish(&acc)
}

/// `rows[j]` bit i set where pixel (i, j) of the row-major `w`-wide `pixels` is above `threshold`
/// (`L::MIN_PIXELS <= w <= 64`): two vectors a mask extraction, then the row's last pixels as a span.
#[inline(always)]
pub(super) fn row_masks<L: Lanes>(
    l: L,
    pixels: &[u16],
    w: usize,
    threshold: u16,
    rows: &mut [u64],
) {
    let width = L::WIDTH;
    let t = l.splat(threshold);
    let whole = w / width;
    let tail = (!w.is_multiple_of(width)).then(|| l.span(whole * width, w));
    for (m, row) in rows.iter_mut().zip(pixels.chunks_exact(w)) {
        let mut bits = 0;
        let mut pairs = row.chunks_exact(2 * width);
        for (c, pair) in pairs.by_ref().enumerate() {
            let (a, b) = (l.load(pair, 0), l.load(pair, width));
            bits |= l.nonzero_bits2(l.sub_sat(a, t), l.sub_sat(b, t)) << (2 * width * c);
        }
        if whole % 2 == 1 {
            let v = l.sub_sat(l.load(pairs.remainder(), 0), t);
            bits |= l.nonzero_bits(v) << ((whole - 1) * width);
        }
        if let Some(tail) = tail {
            bits |= l.nonzero_bits(l.excess_span(row, tail, t)) << l.span_offset(tail);
        }
        *m = bits;
    }
}
