//! The kernels a pixel at a time (with a few word-parallel tricks): on CPUs without vector instructions the kernels
//! use, and the reference the vectorised kernels must agree with to the bit.

use crate::centroid::{MAX_ROI_HEIGHT, MAX_ROI_WIDTH};

/// The largest pixel and the index of its first occurrence (row-major).
pub(super) fn peak(pixels: &[u16]) -> (u16, usize) {
    let peak = pixels.iter().copied().fold(0, u16::max);
    (peak, first_equal(pixels, peak))
}

/// Minimum, maximum and sum of the border pixels of a row-major `w` x `h` image.
pub(super) fn border_min_max_sum(pixels: &[u16], w: usize, h: usize) -> (u16, u16, u64) {
    let (mut min, mut max, mut sum) = (u16::MAX, 0u16, 0u64);
    let mut add_row = |row: &[u16]| {
        min = row.iter().copied().fold(min, u16::min);
        max = row.iter().copied().fold(max, u16::max);
        sum += row.iter().map(|&p| u64::from(p)).sum::<u64>();
    };
    add_row(&pixels[..w]);
    if h > 1 {
        add_row(&pixels[(h - 1) * w..]);
    }
    for j in 1..h.saturating_sub(1) {
        add_row(&pixels[j * w..j * w + 1]);
        if w > 1 {
            add_row(&pixels[j * w + w - 1..j * w + w]);
        }
    }
    (min, max, sum)
}

/// `rows[j]` bit i set where pixel (i, j) of the row-major `w`-wide `pixels` is above `threshold`.
pub(super) fn row_masks(pixels: &[u16], w: usize, threshold: u16, rows: &mut [u64]) {
    let mut flat = [0u64; (MAX_ROI_WIDTH * MAX_ROI_HEIGHT / 64) as usize];
    flat_above(pixels, threshold, &mut flat);
    for (j, m) in rows.iter_mut().enumerate() {
        *m = bits_at(&flat, j * w, w);
    }
}

/// Bit i set where `pred(chunk[i])`: the comparisons vectorise into a byte per pixel, and a multiplication gathers
/// each 8 bytes' low bits into one byte (b_k * 2^(8k) times 0x0102040810204080 puts b_k at bit 56 + k, carry-free).
#[inline]
fn mask16(chunk: &[u16; 16], pred: impl Fn(u16) -> bool) -> u64 {
    const GATHER: u64 = 0x0102_0408_1020_4080;
    let bytes: [u8; 16] = std::array::from_fn(|i| u8::from(pred(chunk[i])));
    let lo = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
    let hi = u64::from_le_bytes(bytes[8..].try_into().expect("8 bytes"));
    (lo.wrapping_mul(GATHER) >> 56) | ((hi.wrapping_mul(GATHER) >> 56) << 8)
}

/// Index of the first pixel equal to `value` (0 if none), comparing 16 pixels at a time.
#[inline]
fn first_equal(pixels: &[u16], value: u16) -> usize {
    let mut chunks = pixels.chunks_exact(16);
    for (c, chunk) in chunks.by_ref().enumerate() {
        let bits = mask16(chunk.try_into().expect("16 pixels"), |p| p == value);
        if bits != 0 {
            return 16 * c + bits.trailing_zeros() as usize;
        }
    }
    let done = pixels.len() - chunks.remainder().len();
    chunks
        .remainder()
        .iter()
        .position(|&p| p == value)
        .map_or(0, |k| done + k)
}

/// Bit k of `flat` (word k / 64, bit k % 64) set where `pixels[k] > threshold`, 16 pixels at a time.
#[inline]
fn flat_above(pixels: &[u16], threshold: u16, flat: &mut [u64]) {
    let mut words = pixels.chunks_exact(64);
    for (word, chunk) in flat.iter_mut().zip(words.by_ref()) {
        *word = chunk
            .chunks_exact(16)
            .enumerate()
            .fold(0, |bits, (c, sixteen)| {
                bits | mask16(sixteen.try_into().expect("16 pixels"), |p| p > threshold) << (16 * c)
            });
    }
    let rest = words.remainder();
    if !rest.is_empty() {
        flat[pixels.len() / 64] = rest
            .iter()
            .enumerate()
            .fold(0, |acc, (i, &p)| acc | (u64::from(p > threshold) << i));
    }
}

/// The `w` bits (`w <= 64`) of `flat` from bit `start` on.
#[inline]
fn bits_at(flat: &[u64], start: usize, w: usize) -> u64 {
    let (word, shift) = (start / 64, start % 64);
    let mut bits = flat[word] >> shift;
    if shift + w > 64 {
        bits |= flat[word + 1] << (64 - shift);
    }
    bits & (u64::MAX >> (64 - w))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_masks_of_pixels() {
        let pixels: Vec<u16> = (0..150u16).map(|k| (k * 37) % 101).collect();
        let mut flat = [0u64; 3];
        flat_above(&pixels, 50, &mut flat);
        for (k, &p) in pixels.iter().enumerate() {
            assert_eq!((flat[k / 64] >> (k % 64)) & 1 == 1, p > 50, "pixel {k}");
        }
        for w in [1, 7, 24, 64] {
            for start in [0, 5, 40, 63, 64, 70] {
                if start + w <= 150 {
                    let expected = (0..w).fold(0u64, |acc, i| {
                        acc | (u64::from(pixels[start + i] > 50) << i)
                    });
                    assert_eq!(bits_at(&flat, start, w), expected);
                }
            }
        }
        assert_eq!(
            first_equal(&pixels, pixels[77]),
            pixels.iter().position(|&p| p == pixels[77]).unwrap()
        );
        assert_eq!(first_equal(&pixels, 1000), 0);
        assert_eq!(first_equal(&pixels[..20], pixels[19]), 19);
    }
}
