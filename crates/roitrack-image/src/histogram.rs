//! Histograms of pixel values, for the percentiles that set a frame's levels.

/// Counts of each pixel value of an image.
#[derive(Debug, Clone)]
pub(crate) struct Histogram {
    counts: Vec<u32>,
    total: u64,
}

impl Histogram {
    /// The histogram of `pixels`, values above `top` counted as `top`.
    pub fn of(pixels: &[u16], top: u16) -> Self {
        // Four interleaved tables: neighbouring pixels mostly share a value, and one table would make each count
        // wait for the previous one's store.
        let bins = usize::from(top) + 1;
        let counts = if top <= 255 {
            // 8-bit images: tables indexed by a byte need no bounds checks.
            let mut lanes = [[0u32; 256]; 4];
            let (quads, rest) = pixels.as_chunks::<4>();
            for quad in quads {
                for (lane, &p) in lanes.iter_mut().zip(quad) {
                    lane[usize::from(p.min(top) as u8)] += 1;
                }
            }
            for &p in rest {
                lanes[0][usize::from(p.min(top) as u8)] += 1;
            }
            (0..bins)
                .map(|b| lanes[0][b] + lanes[1][b] + lanes[2][b] + lanes[3][b])
                .collect()
        } else {
            let mut lanes = vec![0u32; 4 * bins];
            let (quads, rest) = pixels.as_chunks::<4>();
            for quad in quads {
                for (lane, &p) in quad.iter().enumerate() {
                    lanes[lane * bins + usize::from(p.min(top))] += 1;
                }
            }
            for &p in rest {
                lanes[usize::from(p.min(top))] += 1;
            }
            (0..bins)
                .map(|b| lanes[b] + lanes[bins + b] + lanes[2 * bins + b] + lanes[3 * bins + b])
                .collect()
        };
        Self {
            counts,
            total: pixels.len() as u64,
        }
    }

    /// The smallest value with at least `fraction` of the pixels at or below it.
    pub fn percentile(&self, fraction: f64) -> u16 {
        self.counts
            .iter()
            .position(self.reaches(fraction))
            .unwrap_or(0) as u16
    }

    /// The largest value with at least `fraction` of the pixels at or above it: of the image `top - p` (the values
    /// above `top` counted as `top`), `top - self.percentile_from_top(fraction)` is the percentile.
    pub fn percentile_from_top(&self, fraction: f64) -> u16 {
        self.counts
            .iter()
            .rposition(self.reaches(fraction))
            .unwrap_or(self.counts.len() - 1) as u16
    }

    /// A test of the counts in the order they are given: true from the count that brings the pixels seen to
    /// `fraction` of them (at least one pixel) on.
    fn reaches(&self, fraction: f64) -> impl FnMut(&u32) -> bool {
        let rank = (fraction * self.total as f64).ceil().max(1.0) as u64;
        let mut seen = 0u64;
        move |&c| {
            seen += u64::from(c);
            seen >= rank
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_a_ramp() {
        let pixels: Vec<u16> = (0..100).collect();
        let h = Histogram::of(&pixels, 99);
        assert_eq!(h.percentile(0.5), 49);
        assert_eq!(h.percentile(0.01), 0);
        assert_eq!(h.percentile(1.0), 99);
        assert_eq!(Histogram::of(&pixels, 10).percentile(0.5), 10);
    }

    #[test]
    fn percentiles_from_the_top_are_those_of_the_inverted_image() {
        let mut state = 7u64;
        for top in [255u16, 1023, 4095, 65_535] {
            // Values above `top` too (counted as `top`), repeated ones, and the extremes.
            let pixels: Vec<u16> = (0..5000)
                .map(|k| {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    match k % 211 {
                        0 => 0,
                        1 => u16::MAX,
                        _ => ((state >> 40) % (u64::from(top) + 40)) as u16,
                    }
                })
                .collect();
            let inverted: Vec<u16> = pixels.iter().map(|&p| top.saturating_sub(p)).collect();
            let (h, hi) = (Histogram::of(&pixels, top), Histogram::of(&inverted, top));
            for fraction in [0.0, 0.0001, 0.01, 0.3, 0.5, 0.99, 1.0] {
                assert_eq!(
                    top - h.percentile_from_top(fraction),
                    hi.percentile(fraction),
                    "top {top}, fraction {fraction}"
                );
            }
        }
    }
}
