//! A simulated reflection: a second, compact bright spot in an ROI (a specular glint off the part, a lamp seen in a
//! shiny surface), for testing the centroid and the tracker against it.

use rand::Rng;

use roitrack_image::Roi;

/// A reflection in a fraction of the ROIs: a Gaussian spot at a random direction and distance from the ROI's centre
/// (where the scheduler expects the blob), as bright as a random multiple of the blob's peak. Brighter than the blob
/// and apart from it, it takes a plain centroid (an outlier of several pixels) unless it touches the ROI's border;
/// dimmer and apart, it is a separate component the centroid ignores; near the blob it merges with it and biases a
/// plain centroid by a fraction of a pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectionFault {
    /// Fraction of ROIs with a reflection, in [0, 1].
    pub fraction: f64,
    /// Distance of the spot from the ROI's centre (px), drawn uniformly in this range (clamped inside the ROI).
    pub distance_px: (f64, f64),
    /// Peak of the spot over the background, as a multiple of the blob's, drawn uniformly in this range.
    pub relative_peak: (f64, f64),
    /// Standard deviation of the spot's Gaussian profile (px).
    pub sigma_px: f64,
}

impl Default for ReflectionFault {
    fn default() -> Self {
        Self {
            fraction: 0.1,
            distance_px: (6.0, 10.0),
            relative_peak: (0.5, 1.5),
            sigma_px: 1.2,
        }
    }
}

impl ReflectionFault {
    /// Adds a spot to a rendered ROI (row-major `pixels`, values clipped at `max_dn`), its position and brightness
    /// drawn from `rng`. The spot's peak is relative to the ROI's contrast (maximum minus minimum). Draws the same
    /// number of values whatever the ROI holds.
    pub fn add_spot(&self, rng: &mut impl Rng, roi: &Roi, pixels: &mut [u16], max_dn: u16) {
        let (w, h) = (roi.width as usize, roi.height as usize);
        let angle = rng.random_range(0.0..std::f64::consts::TAU);
        let distance = rng.random_range(self.distance_px.0..=self.distance_px.1);
        let relative = rng.random_range(self.relative_peak.0..=self.relative_peak.1);
        let (Some(&peak), Some(&floor)) = (pixels.iter().max(), pixels.iter().min()) else {
            return;
        };
        let amplitude = f64::from(peak - floor) * relative;
        // Keep the spot's centre two pixels inside the ROI.
        let half = |n: usize| (n as f64 / 2.0 - 2.0).max(0.0);
        let cx = (w as f64 / 2.0 + distance * angle.cos())
            .clamp(w as f64 / 2.0 - half(w), w as f64 / 2.0 + half(w));
        let cy = (h as f64 / 2.0 + distance * angle.sin())
            .clamp(h as f64 / 2.0 - half(h), h as f64 / 2.0 + half(h));
        let inv_two_var = 1.0 / (2.0 * self.sigma_px * self.sigma_px);
        for (j, row) in pixels.chunks_exact_mut(w).enumerate() {
            let dy = j as f64 + 0.5 - cy;
            for (i, p) in row.iter_mut().enumerate() {
                let dx = i as f64 + 0.5 - cx;
                let add = amplitude * (-(dx * dx + dy * dy) * inv_two_var).exp();
                *p = (f64::from(*p) + add).round().min(f64::from(max_dn)) as u16;
            }
        }
    }
}
