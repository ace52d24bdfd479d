//! The sensor: photometry, noise and quantisation of the simulated camera.

use rand::Rng;
use rand_distr::{Distribution, Poisson, StandardNormal};
use thiserror::Error;

/// Why a [`SensorModel`] is unusable.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SensorError {
    /// A field is NaN or infinite.
    #[error("{field} must be a finite number, got {value}")]
    NotFinite {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A field that must be positive is not.
    #[error("{field} must be positive, got {value}")]
    NotPositive {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A field that must not be negative is.
    #[error("{field} must not be negative, got {value}")]
    Negative {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The bit depth is out of 1-16.
    #[error("bit depth must be 1 to 16 (typically 8, 10 or 12), got {bits}")]
    BitDepth {
        /// The depth given.
        bits: u32,
    },
    /// A count is 0.
    #[error("{field} must be at least 1, got 0")]
    Zero {
        /// The field.
        field: &'static str,
    },
    /// Too many sub-rows.
    #[error("supersampling must be at most {max} sub-rows, got {value}")]
    Supersampling {
        /// The sub-rows asked for.
        value: u32,
        /// The most supported.
        max: u32,
    },
    /// The camera's time model is invalid.
    #[error("the camera's time model: {0}")]
    TimeModel(#[from] roitrack_core::time::TimeModelError),
}

/// Below this expected count (electrons) shot noise is drawn from a Poisson law; above it from the normal
/// approximation (relative error of the variance's shape < 1 % there, and 10x faster).
pub const POISSON_NORMAL_SWITCH_E: f64 = 50.0;

/// Largest supported supersampling (sub-rows per edge pixel).
pub const MAX_SUPERSAMPLING: u32 = 32;

/// The simulated camera's sensor, optics blur and rendering resolution.
///
/// [`Default`] models a global-shutter high-speed CMOS camera of the kind the paper used (a Photonfocus-like sensor
/// read in 8-bit mode, one small ROI at 4 kHz) watching bright (e.g. retro-reflective, LED-lit) blobs. Signals are
/// given *per exposure* (electrons collected during the exposure, whose duration is the camera's
/// [`roitrack_core::TimeModel::exposure_s`], 100 µs by default: short enough for 4 kHz ROIs and < 0.25 px of blur at
/// 1 m/s): changing the exposure changes the motion blur only, as if the illumination were adjusted to keep the same
/// brightness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorModel {
    /// Full-well capacity (electrons); the top of the ADC range. Default 10,000 e-: typical of 8-12 µm global-shutter
    /// high-speed CMOS pixels.
    pub full_well_e: f64,
    /// Read noise (electrons RMS, Gaussian). Default 10 e-: typical of global-shutter CMOS (pipelined readout).
    pub read_noise_e: f64,
    /// Whether photon shot noise (Poisson) is drawn. Default `true`: it is the dominant noise of bright blobs.
    pub shot_noise: bool,
    /// Electrons collected during the exposure by a pixel entirely inside a blob, above the background, before the
    /// optical blur. Default 8,500 e-: with the background, 90 % of full well (230 DN of 255 at 8 bits), so the peak
    /// plus 5 sigma of shot noise (9,480 e-) still does not saturate.
    pub blob_signal_e: f64,
    /// Background (stray light, black-level offset) per pixel per exposure (electrons). Default 500 e- = 5 % of full
    /// scale: keeps the read noise of dark pixels above zero so it is not clipped.
    pub background_e: f64,
    /// Standard deviation of the Gaussian optical blur (pixels). Default 0.6 px: a sharp lens as focused on a real
    /// bench (residual defocus and aberrations), which spreads each blob edge over about two pixels.
    pub blur_sigma_px: f64,
    /// ADC bit depth (bits, 1 to 16; cameras offer 8, 10 or 12). Default 8: the high-speed mode of such cameras.
    pub bit_depth: u32,
    /// Sub-rows per pixel crossed by a blob's edge: the pixel is cut into this many horizontal strips and the centre
    /// line of each is intersected exactly with the blob's ellipse (exact across, midpoint rule down: coverage error
    /// O(1/supersampling²) per edge pixel). Default 4: nearly as accurate noiseless centroids as 8, at half the cost,
    /// and several times more accurate than 1 (measured in docs/results.md, "Design measurements behind the code").
    pub supersampling: u32,
    /// Largest number of instants the exposure is sampled at (motion blur). Default 16: steps of 0.1 px up to 1.6 px
    /// of motion during the exposure (6 m/s at the bench distance); faster motion gets coarser steps.
    pub max_time_samples: u32,
    /// Largest image motion between two time samples (pixels): the exposure is sampled at
    /// `ceil(motion during the exposure / motion_step_px)` instants (at most `max_time_samples`, one for a static
    /// blob). Default 0.1 px: the optical blur (0.6 px) smooths the steps, the brightness profile differing from that
    /// of continuous motion by about (step / sigma)² / 24 = 0.1 %, symmetrically (the centroid is unaffected).
    pub motion_step_px: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        Self {
            full_well_e: 10_000.0,
            read_noise_e: 10.0,
            shot_noise: true,
            blob_signal_e: 8_500.0,
            background_e: 500.0,
            blur_sigma_px: 0.6,
            bit_depth: 8,
            supersampling: 4,
            max_time_samples: 16,
            motion_step_px: 0.1,
        }
    }
}

impl SensorModel {
    /// The default sensor without shot or read noise: images are a deterministic function of the pose (quantisation
    /// remains).
    pub fn noiseless() -> Self {
        Self {
            shot_noise: false,
            read_noise_e: 0.0,
            ..Self::default()
        }
    }

    /// The default sensor with another bit depth (the full well maps to the top of the range, so the image looks the
    /// same at any depth, with finer quantisation).
    pub fn with_bit_depth(bit_depth: u32) -> Self {
        Self {
            bit_depth,
            ..Self::default()
        }
    }

    /// Largest output value (DN): 2^bit_depth - 1.
    pub fn max_dn(&self) -> u16 {
        ((1u32 << self.bit_depth) - 1) as u16
    }

    /// Conversion gain (DN per electron): the full well maps to the largest value.
    pub fn gain_dn_per_e(&self) -> f64 {
        f64::from(self.max_dn()) / self.full_well_e
    }

    /// Expected background level (DN) of a pixel away from the blobs.
    pub fn background_dn(&self) -> f64 {
        self.background_e * self.gain_dn_per_e()
    }

    /// Checks every field: finite, positive where needed, bit depth 1 to 16.
    pub fn validate(&self) -> Result<(), SensorError> {
        for (field, value) in [
            ("full_well_e", self.full_well_e),
            ("read_noise_e", self.read_noise_e),
            ("blob_signal_e", self.blob_signal_e),
            ("background_e", self.background_e),
            ("blur_sigma_px", self.blur_sigma_px),
            ("motion_step_px", self.motion_step_px),
        ] {
            if !value.is_finite() {
                return Err(SensorError::NotFinite { field, value });
            }
        }
        for (field, value) in [
            ("full_well_e", self.full_well_e),
            ("motion_step_px", self.motion_step_px),
        ] {
            if value <= 0.0 {
                return Err(SensorError::NotPositive { field, value });
            }
        }
        for (field, value) in [
            ("read_noise_e", self.read_noise_e),
            ("blob_signal_e", self.blob_signal_e),
            ("background_e", self.background_e),
            ("blur_sigma_px", self.blur_sigma_px),
        ] {
            if value < 0.0 {
                return Err(SensorError::Negative { field, value });
            }
        }
        if !(1..=16).contains(&self.bit_depth) {
            return Err(SensorError::BitDepth {
                bits: self.bit_depth,
            });
        }
        if self.supersampling == 0 {
            return Err(SensorError::Zero {
                field: "supersampling",
            });
        }
        if self.supersampling > MAX_SUPERSAMPLING {
            return Err(SensorError::Supersampling {
                value: self.supersampling,
                max: MAX_SUPERSAMPLING,
            });
        }
        if self.max_time_samples == 0 {
            return Err(SensorError::Zero {
                field: "max_time_samples",
            });
        }
        Ok(())
    }

    /// Electrons read from a pixel whose expected count is `mean_e`: shot noise (Poisson, normal above
    /// [`POISSON_NORMAL_SWITCH_E`]) plus Gaussian read noise. Deterministic when both are off.
    #[inline]
    pub fn sample_electrons(&self, mean_e: f64, rng: &mut impl Rng) -> f64 {
        let read_var = self.read_noise_e * self.read_noise_e;
        if self.shot_noise && mean_e > 0.0 {
            if mean_e > POISSON_NORMAL_SWITCH_E {
                // Sum of two independent normals: one draw.
                let n: f64 = rng.sample(StandardNormal);
                return mean_e + (mean_e + read_var).sqrt() * n;
            }
            let shot = Poisson::new(mean_e).map_or(0.0, |p| p.sample(rng));
            if self.read_noise_e > 0.0 {
                let n: f64 = rng.sample(StandardNormal);
                return shot + self.read_noise_e * n;
            }
            return shot;
        }
        if self.read_noise_e > 0.0 {
            let n: f64 = rng.sample(StandardNormal);
            mean_e + self.read_noise_e * n
        } else {
            mean_e
        }
    }

    /// The digital value (DN) of `electrons`: conversion gain, rounding to the nearest integer, clamping to the range
    /// (saturation at the full well, no negative values).
    #[inline]
    pub fn quantise(&self, electrons: f64) -> u16 {
        // Round half up by truncation of a non-negative value (`as` saturates, NaN gives 0).
        let dn = (electrons * self.gain_dn_per_e()).max(0.0) + 0.5;
        (dn as u32).min(u32::from(self.max_dn())) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn defaults_are_valid_and_do_not_saturate() {
        let s = SensorModel::default();
        s.validate().unwrap();
        assert_eq!(s.max_dn(), 255);
        let peak_e = s.background_e + s.blob_signal_e;
        assert!(peak_e + 5.0 * (peak_e + s.read_noise_e.powi(2)).sqrt() < s.full_well_e);
        assert!((s.background_dn() - 12.75).abs() < 1e-12);
        assert_eq!(SensorModel::with_bit_depth(12).max_dn(), 4095);
    }

    #[test]
    fn refuses_bad_values() {
        let bad = [
            SensorModel {
                bit_depth: 17,
                ..Default::default()
            },
            SensorModel {
                full_well_e: 0.0,
                ..Default::default()
            },
            SensorModel {
                blur_sigma_px: f64::NAN,
                ..Default::default()
            },
            SensorModel {
                supersampling: 0,
                ..Default::default()
            },
            SensorModel {
                read_noise_e: -1.0,
                ..Default::default()
            },
        ];
        for s in bad {
            assert!(s.validate().is_err(), "{s:?}");
        }
    }

    #[test]
    fn noise_has_the_right_variance() {
        let s = SensorModel::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for mean in [4.0, 30.0, 500.0, 5000.0] {
            let n = 20_000;
            let draws: Vec<f64> = (0..n).map(|_| s.sample_electrons(mean, &mut rng)).collect();
            let m = draws.iter().sum::<f64>() / n as f64;
            let var = draws.iter().map(|d| (d - m).powi(2)).sum::<f64>() / (n - 1) as f64;
            let expected_var = mean + s.read_noise_e.powi(2);
            assert!((m - mean).abs() < 5.0 * (expected_var / n as f64).sqrt());
            assert!((var / expected_var - 1.0).abs() < 0.05, "{mean}: {var}");
        }
        let quiet = SensorModel::noiseless();
        assert_eq!(quiet.sample_electrons(123.4, &mut rng), 123.4);
        assert_eq!(quiet.quantise(1e9), 255);
        assert_eq!(quiet.quantise(-50.0), 0);
    }
}
