//! Connected components (8-connectivity) of the pixels above one threshold, from horizontal runs joined by
//! union-find, each with the sums its user needs ([`RunSums`]): binary moments up to second order and the shape
//! filters' figures for the photo detector ([`Component`]), grey-level first moments for the frame detector.

/// What is summed over a component, run by run.
pub(crate) trait RunSums: Copy {
    /// The sums of the run `start..end` of `row` (row `j` of a `width` x `height` image).
    fn of_run(row: &[u16], start: usize, end: usize, j: usize, width: usize, height: usize)
    -> Self;
    /// Adds another part of the same component.
    fn add(&mut self, other: &Self);
}

/// Binary moments and outline figures of one component (integer sums: exact).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Component {
    pub n: u64,
    pub sum_i: u64,
    pub sum_j: u64,
    pub sum_ii: u64,
    pub sum_jj: u64,
    pub sum_ij: u64,
    /// Horizontal runs: a convex shape has one per row.
    pub runs: u32,
    pub row_min: u32,
    pub row_max: u32,
    pub touches_border: bool,
}

impl RunSums for Component {
    fn of_run(
        _row: &[u16],
        start: usize,
        end: usize,
        j: usize,
        width: usize,
        height: usize,
    ) -> Self {
        let (s, e) = (start as u64, end as u64);
        let n = e - s;
        let jj = j as u64;
        // Sums of i and i² over s..e in closed form.
        let sum_i = (s + e - 1) * n / 2;
        let sq = |x: u64| x * (x + 1) * (2 * x + 1) / 6;
        let sum_ii = sq(e - 1) - if s > 0 { sq(s - 1) } else { 0 };
        Self {
            n,
            sum_i,
            sum_j: n * jj,
            sum_ii,
            sum_jj: n * jj * jj,
            sum_ij: sum_i * jj,
            runs: 1,
            row_min: j as u32,
            row_max: j as u32,
            touches_border: j == 0 || j + 1 == height || start == 0 || end == width,
        }
    }

    fn add(&mut self, o: &Component) {
        self.n += o.n;
        self.sum_i += o.sum_i;
        self.sum_j += o.sum_j;
        self.sum_ii += o.sum_ii;
        self.sum_jj += o.sum_jj;
        self.sum_ij += o.sum_ij;
        self.runs += o.runs;
        self.row_min = self.row_min.min(o.row_min);
        self.row_max = self.row_max.max(o.row_max);
        self.touches_border |= o.touches_border;
    }
}

impl Component {
    /// Centre of the pixels (px).
    pub fn centre(&self) -> (f64, f64) {
        let n = self.n as f64;
        (self.sum_i as f64 / n, self.sum_j as f64 / n)
    }

    /// Central second moments (px²): (μ_uu, μ_vv, μ_uv), each pixel counted as a unit square (+1/12).
    pub fn covariance(&self) -> (f64, f64, f64) {
        let n = self.n as f64;
        let (cu, cv) = self.centre();
        (
            self.sum_ii as f64 / n - cu * cu + 1.0 / 12.0,
            self.sum_jj as f64 / n - cv * cv + 1.0 / 12.0,
            self.sum_ij as f64 / n - cu * cv,
        )
    }
}

/// A run of pixels in one row (inclusive ends).
#[derive(Debug, Clone, Copy)]
struct Run {
    start: u32,
    end: u32,
    row: u32,
}

impl Run {
    /// Its sums, in `pixels` of a `width` x `height` image.
    #[inline]
    fn sums<S: RunSums>(&self, pixels: &[u16], width: usize, height: usize) -> S {
        let (start, end, j) = (
            self.start as usize,
            self.end as usize + 1,
            self.row as usize,
        );
        S::of_run(
            &pixels[j * width..(j + 1) * width],
            start,
            end,
            j,
            width,
            height,
        )
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let grand = parent[parent[x as usize] as usize];
        parent[x as usize] = grand;
        x = grand;
    }
    x
}

/// Buffers reused from one threshold to the next.
#[derive(Debug)]
pub(crate) struct Labeller<S> {
    runs: Vec<Run>,
    parent: Vec<u32>,
    /// Per run that is its component's root, the component's index in `totals`.
    slot: Vec<u32>,
    totals: Vec<S>,
    /// Per component (by its first run's order), its pixels so far and whether it is refused (it touches the image's
    /// border or has too many pixels): what decides whether its sums are wanted ([`Self::sum_admitted`]).
    extents: Vec<(u64, bool)>,
    /// Per component, its index in `totals`, or `u32::MAX` if it is not kept.
    summed: Vec<u32>,
    mask: Vec<u64>,
    /// Per row, a bit per 64-pixel word of the mask that had a pixel above the last threshold (64 words a `u64`).
    active: Vec<u64>,
}

/// Sets bit `b` of `mask[w]` when `row[64 w + b] > threshold`.
#[cfg(test)]
fn row_mask(row: &[u16], threshold: u16, mask: &mut [u64]) {
    let mut active = vec![u64::MAX; mask.len().div_ceil(64)];
    row_mask_within(row, threshold, mask, &mut active);
}

/// [`row_mask`] for the words `w` whose bit `w % 64` of `active[w / 64]` is set (the others are cleared), and clears
/// that bit where the word has no pixel above the threshold. Only the active words are visited (their bits taken a
/// set bit at a time): past the first levels, most of a row's words are not, and the loop's own bookkeeping cost as
/// much as the comparisons.
fn row_mask_within(row: &[u16], threshold: u16, mask: &mut [u64], active: &mut [u64]) {
    mask.fill(0);
    for (a, flags) in active.iter_mut().enumerate() {
        let mut todo = *flags;
        while todo != 0 {
            let b = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            let w = 64 * a + b;
            let Some(word) = mask.get_mut(w) else {
                // Bits past the row's last word (set when the flags are reset) stand for nothing.
                break;
            };
            let chunk = &row[64 * w..row.len().min(64 * w + 64)];
            *word = match <&[u16; 64]>::try_from(chunk) {
                Ok(full) => mask_of_64(full, threshold),
                Err(_) => chunk
                    .iter()
                    .enumerate()
                    .fold(0, |bits, (b, &p)| bits | (u64::from(p > threshold) << b)),
            };
            if *word == 0 {
                *flags &= !(1u64 << b);
            }
        }
    }
}

/// The mask of 64 pixels: SSE2 (every x86_64 CPU) compares 8 a time and packs the results into bits, about ten times
/// faster than the compiler's vectorisation of the scalar loop, which is where most of the detector's time went.
#[cfg(target_arch = "x86_64")]
fn mask_of_64(pixels: &[u16; 64], threshold: u16) -> u64 {
    use std::arch::x86_64::{
        __m128i, _mm_cmpgt_epi16, _mm_loadu_si128, _mm_movemask_epi8, _mm_packs_epi16,
        _mm_set1_epi16, _mm_xor_si128,
    };
    // SAFETY: SSE2 is part of the x86_64 baseline; the loads read 16 bytes at offsets 0..=112 of a 128-byte array.
    unsafe {
        // Unsigned comparison with the signed instruction: flip the sign bits of both sides.
        let bias = _mm_set1_epi16(i16::MIN);
        let limit = _mm_xor_si128(_mm_set1_epi16(threshold as i16), bias);
        let base = pixels.as_ptr().cast::<__m128i>();
        let mut bits = 0u64;
        for k in 0..4 {
            let low = _mm_xor_si128(_mm_loadu_si128(base.add(2 * k)), bias);
            let high = _mm_xor_si128(_mm_loadu_si128(base.add(2 * k + 1)), bias);
            let packed = _mm_packs_epi16(_mm_cmpgt_epi16(low, limit), _mm_cmpgt_epi16(high, limit));
            bits |= u64::from(_mm_movemask_epi8(packed) as u16) << (16 * k);
        }
        bits
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn mask_of_64(pixels: &[u16; 64], threshold: u16) -> u64 {
    pixels
        .iter()
        .enumerate()
        .fold(0, |bits, (b, &p)| bits | (u64::from(p > threshold) << b))
}

/// Calls `run(start, end)` (inclusive) for each run of set bits of the mask of a row of `width` pixels (the bits
/// past `width` clear), from the mask's edges a word at a time: a bit unlike the one before it starts a run (set)
/// or ends one (clear); a run that reaches the row's end ends there, or with the last word if the row fills it.
fn for_each_run(mask: &[u64], width: usize, mut run: impl FnMut(usize, usize)) {
    let mut carry = 0u64;
    let mut start = 0usize;
    for (w, &word) in mask.iter().enumerate() {
        let mut edges = word ^ ((word << 1) | carry);
        carry = word >> 63;
        while edges != 0 {
            let b = edges.trailing_zeros() as usize;
            edges &= edges - 1;
            if word >> b & 1 == 1 {
                start = w * 64 + b;
            } else {
                run(start, w * 64 + b - 1);
            }
        }
    }
    if carry == 1 {
        run(start, width - 1);
    }
}

impl<S> Default for Labeller<S> {
    fn default() -> Self {
        Self {
            runs: Vec::new(),
            parent: Vec::new(),
            slot: Vec::new(),
            totals: Vec::new(),
            extents: Vec::new(),
            summed: Vec::new(),
            mask: Vec::new(),
            active: Vec::new(),
        }
    }
}

impl<S: RunSums> Labeller<S> {
    /// The components of the pixels strictly above `threshold` in a row-major `width` x `height` image, each passed
    /// to `keep` (in the order of their first pixel).
    pub fn components(
        &mut self,
        pixels: &[u16],
        width: usize,
        height: usize,
        threshold: u16,
        keep: impl FnMut(&S),
    ) {
        self.label(pixels, width, height, threshold, false, None, keep);
    }

    /// [`Self::components`] at a threshold at least the one of the previous call on the same image (the pixels above
    /// it are among those above the previous one, so only the 64-pixel words that held some are read again), for the
    /// components that do not touch the image's border and whose pixel count is in `admitted`: the others are not
    /// passed to `keep`, and a component's runs are no longer summed once it touches the border or has too many
    /// pixels. A user that refuses such components anyway (the photo detector's shape filters) is spared most of
    /// their sums, a good part of a run's labelling, for the sheets of paper or sky that reach the border or exceed
    /// its largest area.
    pub fn components_above_previous_admitted(
        &mut self,
        pixels: &[u16],
        width: usize,
        height: usize,
        threshold: u16,
        admitted: std::ops::RangeInclusive<u64>,
        keep: impl FnMut(&S),
    ) {
        self.label(pixels, width, height, threshold, true, Some(admitted), keep);
    }

    /// Makes the next [`Self::components_above_previous_admitted`] read every pixel (call it before the first level of an
    /// image).
    pub fn forget_levels(&mut self) {
        self.active.clear();
    }

    #[allow(clippy::too_many_arguments)]
    fn label(
        &mut self,
        pixels: &[u16],
        width: usize,
        height: usize,
        threshold: u16,
        nested: bool,
        admitted: Option<std::ops::RangeInclusive<u64>>,
        mut keep: impl FnMut(&S),
    ) {
        self.runs.clear();
        self.parent.clear();
        let mut previous_row = 0..0;
        let words = width.div_ceil(64);
        let active_words = words.div_ceil(64);
        self.mask.resize(words, 0);
        let nested = nested && self.active.len() == active_words * height;
        if !nested {
            self.active.clear();
            self.active.resize(active_words * height, u64::MAX);
        }
        for (j, row) in pixels.chunks_exact(width.max(1)).take(height).enumerate() {
            let row_start = self.runs.len();
            // The row's above-threshold mask, 64 pixels a word; runs are then read from the words a run at a time,
            // not a pixel at a time. Words with nothing above a lower threshold have nothing above this one.
            let active = &mut self.active[j * active_words..(j + 1) * active_words];
            if active.iter().all(|&a| a == 0) {
                previous_row = row_start..row_start;
                continue;
            }
            row_mask_within(row, threshold, &mut self.mask, active);
            let runs = &mut self.runs;
            for_each_run(&self.mask, width, |start, end| {
                runs.push(Run {
                    start: start as u32,
                    end: end as u32,
                    row: j as u32,
                });
            });
            // Each new run its own set.
            self.parent.extend(row_start as u32..self.runs.len() as u32);
            // Join with the runs of the row above that overlap or touch diagonally. A set's root is its smallest run
            // (the larger root is linked under the smaller), so every run's parent comes before it. (The rows' runs
            // as slices: the bounds are checked once, not at each step of the scans.)
            let (before, current) = self.runs.split_at(row_start);
            let above = &before[previous_row.clone()];
            let mut p = 0;
            for (r, run) in (row_start..).zip(current) {
                while p < above.len() && above[p].end + 1 < run.start {
                    p += 1;
                }
                let mut root = r as u32;
                for (q, other_run) in (previous_row.start + p..).zip(&above[p..]) {
                    if other_run.start > run.end + 1 {
                        break;
                    }
                    let other = find(&mut self.parent, q as u32);
                    if other < root {
                        self.parent[root as usize] = other;
                        root = other;
                    } else if root < other {
                        self.parent[other as usize] = root;
                    }
                }
            }
            previous_row = row_start..self.runs.len();
        }
        // A component's root is its first run (joins keep the smaller index), so one pass in run order meets every
        // root before the other runs of its component, and the components come out in the order of their first pixel.
        self.totals.clear();
        self.slot.clear();
        self.slot.resize(self.runs.len(), 0);
        if let Some(admitted) = admitted {
            self.sum_admitted(pixels, width, height, &admitted);
            for &into in &self.summed {
                if into != u32::MAX {
                    keep(&self.totals[into as usize]);
                }
            }
            return;
        }
        for r in 0..self.runs.len() {
            let part: S = self.runs[r].sums(pixels, width, height);
            // The parent comes before the run, so its slot is already its root's.
            let parent = self.parent[r] as usize;
            if parent == r {
                self.slot[r] = self.totals.len() as u32;
                self.totals.push(part);
            } else {
                let slot = self.slot[parent];
                self.slot[r] = slot;
                self.totals[slot as usize].add(&part);
            }
        }
        for c in &self.totals {
            keep(c);
        }
    }

    /// The sums of the components (of `self.runs`, joined by `self.parent`) that do not touch the border and whose
    /// pixel count is in `admitted`, into `self.totals`, and those components' indices there (in the order of their
    /// first pixel) into `self.summed`. One pass in run order: each component's pixels are counted as its runs come,
    /// and once it touches the border or has more pixels than `admitted` allows, its later runs are not summed (it
    /// is refused whatever they add); too few pixels are known only at the end.
    fn sum_admitted(
        &mut self,
        pixels: &[u16],
        width: usize,
        height: usize,
        admitted: &std::ops::RangeInclusive<u64>,
    ) {
        self.extents.clear();
        self.summed.clear();
        let most = *admitted.end();
        for r in 0..self.runs.len() {
            let Run { start, end, row } = self.runs[r];
            // The parent comes before the run, so its slot is already its root's.
            let parent = self.parent[r] as usize;
            let slot = if parent == r {
                self.extents.push((0, false));
                self.summed.push(u32::MAX);
                self.extents.len() - 1
            } else {
                self.slot[parent] as usize
            };
            self.slot[r] = slot as u32;
            let extent = &mut self.extents[slot];
            if extent.1 {
                continue;
            }
            extent.0 += u64::from(end - start + 1);
            if extent.0 > most
                || row == 0
                || row as usize + 1 == height
                || start == 0
                || end as usize + 1 == width
            {
                extent.1 = true;
                continue;
            }
            let part: S = self.runs[r].sums(pixels, width, height);
            // A component's first run comes before its others (and is refused first): it starts the sums.
            let into = &mut self.summed[slot];
            if *into == u32::MAX {
                *into = self.totals.len() as u32;
                self.totals.push(part);
            } else {
                self.totals[*into as usize].add(&part);
            }
        }
        // The components kept: not refused, and with enough pixels.
        for (into, &(n, refused)) in self.summed.iter_mut().zip(&self.extents) {
            if refused || !admitted.contains(&n) {
                *into = u32::MAX;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first pixel at or after `from` whose mask bit is `set` (the mask of a row of `width` pixels).
    fn next_bit(mask: &[u64], from: usize, set: bool, width: usize) -> Option<usize> {
        let mut word = from / 64;
        if word >= mask.len() {
            return None;
        }
        let flip = if set { 0 } else { u64::MAX };
        let mut bits = (mask[word] ^ flip) & (u64::MAX << (from % 64));
        loop {
            if bits != 0 {
                let found = word * 64 + bits.trailing_zeros() as usize;
                return (found < width).then_some(found);
            }
            word += 1;
            if word >= mask.len() {
                return None;
            }
            bits = mask[word] ^ flip;
        }
    }

    #[test]
    fn runs_from_edges_are_those_found_bit_by_bit() {
        let mut state = 99u64;
        for width in [1usize, 5, 63, 64, 65, 127, 128, 129, 200, 640] {
            for density in [0.1, 0.5, 0.9, 1.0] {
                let row: Vec<u16> = (0..width)
                    .map(|_| {
                        state = state
                            .wrapping_mul(6_364_136_223_846_793_005)
                            .wrapping_add(1_442_695_040_888_963_407);
                        u16::from(((state >> 11) as f64 / (1u64 << 53) as f64) < density)
                    })
                    .collect();
                let mut mask = vec![0u64; width.div_ceil(64)];
                row_mask(&row, 0, &mut mask);
                let mut found = Vec::new();
                for_each_run(&mask, width, |start, end| found.push((start, end)));
                // The runs as they were first found: the next set bit, then the next clear one.
                let mut expected = Vec::new();
                let mut i = 0;
                while i < width {
                    let Some(start) = next_bit(&mask, i, true, width) else {
                        break;
                    };
                    let end = next_bit(&mask, start, false, width).unwrap_or(width);
                    i = end;
                    expected.push((start, end - 1));
                }
                assert_eq!(found, expected, "width {width}, density {density}");
            }
        }
    }

    #[test]
    fn row_masks_agree_with_a_pixel_at_a_time() {
        let row: Vec<u16> = (0..150u32).map(|k| ((k * 7919) % 65_536) as u16).collect();
        for threshold in [0u16, 1, 200, 32_767, 32_768, 40_000, 65_535] {
            let mut mask = vec![0u64; 3];
            row_mask(&row, threshold, &mut mask);
            for (k, &p) in row.iter().enumerate() {
                assert_eq!(
                    mask[k / 64] >> (k % 64) & 1 == 1,
                    p > threshold,
                    "pixel {k} threshold {threshold}"
                );
            }
        }
    }

    /// The components of rising thresholds, admitted by size and away from the border, are those labelled afresh at
    /// each threshold and filtered the same way, with the same sums, in the same order.
    #[test]
    fn admitted_components_are_the_filtered_components() {
        let (w, h) = (150usize, 70usize);
        let mut state = 7u64;
        // Blotches of every size (a smoothed random field), and noise: specks, blobs, sheets touching the border.
        let mut field = vec![0f64; w * h];
        for _ in 0..60 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let (cx, cy, r) = (
                (state >> 11) % w as u64,
                (state >> 27) % h as u64,
                1 + (state >> 43) % 9,
            );
            for j in 0..h {
                for i in 0..w {
                    let d2 = (i as f64 - cx as f64).powi(2) + (j as f64 - cy as f64).powi(2);
                    field[j * w + i] += 600.0 * (-d2 / (r * r) as f64).exp();
                }
            }
        }
        let img: Vec<u16> = field
            .iter()
            .map(|&v| {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                (v + ((state >> 33) % 100) as f64).min(65_535.0) as u16
            })
            .collect();
        let figures = |c: &Component| {
            (
                c.n,
                c.sum_i,
                c.sum_j,
                c.sum_ii,
                c.sum_jj,
                c.sum_ij,
                c.runs,
                c.row_min,
                c.row_max,
                c.touches_border,
            )
        };
        let admitted = 7..=2_000u64;
        let mut nested = Labeller::<Component>::default();
        nested.forget_levels();
        let (mut compared, mut refused) = (0, 0);
        for threshold in [60u16, 100, 150, 250, 400, 550] {
            let mut expected = Vec::new();
            Labeller::<Component>::default().components(&img, w, h, threshold, |c| {
                if !c.touches_border && admitted.contains(&c.n) {
                    expected.push(figures(c));
                } else {
                    refused += 1;
                }
            });
            let mut found = Vec::new();
            nested.components_above_previous_admitted(
                &img,
                w,
                h,
                threshold,
                admitted.clone(),
                |c| found.push(figures(c)),
            );
            assert_eq!(found, expected, "threshold {threshold}");
            compared += found.len();
        }
        assert!(
            compared > 20 && refused > 20,
            "{compared} components compared, {refused} refused"
        );
    }

    #[test]
    fn moments_of_a_rectangle_and_a_ring() {
        let (w, h) = (20usize, 16usize);
        let mut img = vec![0u16; w * h];
        for j in 3..7 {
            for i in 2..8 {
                img[j * w + i] = 100;
            }
        }
        // A ring: a 7 x 7 square with a 3 x 3 hole.
        for j in 6..13 {
            for i in 11..18 {
                if !(8..11).contains(&j) || !(13..16).contains(&i) {
                    img[j * w + i] = 100;
                }
            }
        }
        let mut found = Vec::new();
        Labeller::<Component>::default().components(&img, w, h, 50, |c| found.push(*c));
        assert_eq!(found.len(), 2);
        let rect = found[0];
        assert_eq!(rect.n, 24);
        let (cu, cv) = rect.centre();
        assert!((cu - 4.5).abs() < 1e-12 && (cv - 4.5).abs() < 1e-12);
        let (uu, vv, uv) = rect.covariance();
        // A uniform w x h rectangle: w²/12 and h²/12.
        assert!((uu - 36.0 / 12.0).abs() < 1e-12 && (vv - 16.0 / 12.0).abs() < 1e-12);
        assert!(uv.abs() < 1e-12);
        assert_eq!(rect.runs, 4);
        let ring = found[1];
        assert_eq!(ring.n, 40);
        assert_eq!(ring.runs, 7 + 3);
        assert_eq!((ring.row_min, ring.row_max), (6, 12));
        assert!(!ring.touches_border && !rect.touches_border);
    }
}
