//! ROIs of any size for the tests that compare instruction sets: synthetic ones (disks, rings, diagonal lines, noise,
//! 8- to 16-bit pixels) and blobs as a camera sees them (perspective disks, motion and optical blur, a sloped
//! background, noise, 8 bits). In one place so that the kernel-level and the [`super::measure_blob`]-level comparisons
//! see the same kinds of images.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::roi::Roi;

/// A `w` x `h` ROI of background and noise holding 1 to 3 disks, rings or diagonal lines (by `kind % 4`, simple
/// components and not), anywhere in or just off it, in pixels of 8 to 16 bits (by `kind % 5`).
pub(super) fn synthetic(rng: &mut ChaCha8Rng, w: usize, h: usize, kind: usize) -> Vec<u16> {
    let max = f64::from((1u32 << [8, 8, 10, 12, 16][kind % 5]) - 1);
    let background = rng.random_range(0.0..0.2) * max;
    let noise = rng.random_range(0.0..0.02) * max;
    let mut image: Vec<f64> = (0..w * h)
        .map(|_| background + noise * rng.random_range(-1.0..1.0))
        .collect();
    for _ in 0..rng.random_range(1..4) {
        let r = rng.random_range(0.3..(w.min(h) as f64 / 2.0).max(0.6));
        let (cx, cy) = (
            rng.random_range(-1.0..w as f64 + 1.0),
            rng.random_range(-1.0..h as f64 + 1.0),
        );
        let amplitude = rng.random_range(0.05..1.0) * (max - background);
        for (k, p) in image.iter_mut().enumerate() {
            let (dx, dy) = ((k % w) as f64 - cx, (k / w) as f64 - cy);
            let d = dx.hypot(dy);
            *p += amplitude
                * match kind % 4 {
                    0 | 1 => (1.0 - (d / r).powi(2)).max(0.0),
                    2 => f64::from(u8::from((d - r).abs() < 1.0)),
                    _ => f64::from(u8::from((dx - dy).abs() < 0.8 && d < r)),
                };
        }
    }
    image
        .iter()
        .map(|&p| p.round().clamp(0.0, max) as u16)
        .collect()
}

/// Full well of the blobs' sensor (electrons), its 8-bit full scale: that of the simulator's default sensor.
const FULL_WELL_E: f64 = 10_000.0;
/// Read noise of the blobs' sensor (electrons, standard deviation).
const READ_NOISE_E: f64 = 10.0;
/// Sub-pixel samples per pixel side of a blob's coverage.
const SUBSAMPLES: usize = 4;

/// A `w` x `h` ROI of 8-bit pixels around a blob as a high-speed camera sees one, and where on a 1024 x 1024 sensor
/// it is: the image of a flat disk (an ellipse 7 to 22 px across, up to 1.35 times as long as wide, at any tilt),
/// smeared by up to 2 px of motion in any direction, blurred by an optical Gaussian of 0.4 to 1 px, on a background
/// sloping by up to 0.15 % of the full scale per pixel, with shot and read noise, quantised; its centre at a random
/// sub-pixel position up to 30 % of the ROI's size off the ROI's centre, as the scheduler's predictions leave it. One
/// in eight has a saturated core. Made here, not by roitrack-sim's renderer, which depends on this crate: these unit
/// tests cannot use it.
pub(super) fn blob(rng: &mut ChaCha8Rng, w: u32, h: u32, kind: usize) -> (Vec<u16>, Roi) {
    let (wf, hf) = (f64::from(w), f64::from(h));
    let diameter_px: f64 = rng.random_range(7.0..22.0);
    let (a, b) = (
        diameter_px / 2.0,
        diameter_px / 2.0 / rng.random_range(1.0..1.35),
    );
    let tilt = rng.random_range(0.0..std::f64::consts::PI);
    let centre = (
        (wf - 1.0) / 2.0 + rng.random_range(-0.3..0.3) * wf,
        (hf - 1.0) / 2.0 + rng.random_range(-0.3..0.3) * hf,
    );
    let smear_px: f64 = rng.random_range(0.0..2.0);
    let smear_angle = rng.random_range(0.0..std::f64::consts::TAU);
    let sigma_px: f64 = rng.random_range(0.4..1.0);
    let signal_e = if kind.is_multiple_of(8) {
        rng.random_range(11_000.0..16_000.0)
    } else {
        rng.random_range(5_000.0..9_000.0)
    };
    let background_e = rng.random_range(200.0..900.0);
    let slope_e = (rng.random_range(-15.0..15.0), rng.random_range(-15.0..15.0));

    // The disk's coverage of each pixel, averaged over the exposure (the disk at instants along the smear), on a
    // margin of 3 sigma around the ROI so that the blur sees what lies beyond its border.
    let margin = (3.0 * sigma_px).ceil() as usize;
    let (cw, ch) = (w as usize + 2 * margin, h as usize + 2 * margin);
    let instants = 1 + (smear_px / 0.25) as usize;
    let (cos, sin) = (tilt.cos(), tilt.sin());
    let mut coverage = vec![0.0; cw * ch];
    for k in 0..instants {
        let s = smear_px * ((k as f64 + 0.5) / instants as f64 - 0.5);
        let (cx, cy) = (
            centre.0 + s * smear_angle.cos() + margin as f64,
            centre.1 + s * smear_angle.sin() + margin as f64,
        );
        // Only the pixels the ellipse can reach.
        let reach = a + 1.0;
        let (i0, i1) = (
            (cx - reach).floor().max(0.0) as usize,
            ((cx + reach).ceil().max(0.0) as usize).min(cw),
        );
        let (j0, j1) = (
            (cy - reach).floor().max(0.0) as usize,
            ((cy + reach).ceil().max(0.0) as usize).min(ch),
        );
        for j in j0..j1 {
            for i in i0..i1 {
                let mut inside = 0;
                for sj in 0..SUBSAMPLES {
                    for si in 0..SUBSAMPLES {
                        // Pixel (i, j) covers [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5].
                        let x = i as f64 - 0.5 + (si as f64 + 0.5) / SUBSAMPLES as f64 - cx;
                        let y = j as f64 - 0.5 + (sj as f64 + 0.5) / SUBSAMPLES as f64 - cy;
                        let (p, q) = (x * cos + y * sin, -x * sin + y * cos);
                        inside += usize::from((p / a).powi(2) + (q / b).powi(2) <= 1.0);
                    }
                }
                coverage[j * cw + i] += inside as f64 / (SUBSAMPLES * SUBSAMPLES * instants) as f64;
            }
        }
    }

    // The optics' blur: a separable sampled Gaussian, rows then columns, keeping only the ROI.
    let kernel: Vec<f64> = {
        let taps: Vec<f64> = (0..=2 * margin)
            .map(|t| (-((t as f64 - margin as f64) / sigma_px).powi(2) / 2.0).exp())
            .collect();
        let sum: f64 = taps.iter().sum();
        taps.iter().map(|t| t / sum).collect()
    };
    let rows: Vec<f64> = (0..ch * w as usize)
        .map(|k| {
            let (i, j) = (k % w as usize, k / w as usize);
            kernel
                .iter()
                .enumerate()
                .map(|(t, g)| g * coverage[j * cw + i + t])
                .sum()
        })
        .collect();
    let pixels = (0..(w * h) as usize)
        .map(|k| {
            let (i, j) = (k % w as usize, k / w as usize);
            let blurred: f64 = kernel
                .iter()
                .enumerate()
                .map(|(t, g)| g * rows[(j + t) * w as usize + i])
                .sum();
            let background = background_e
                + slope_e.0 * (i as f64 - wf / 2.0)
                + slope_e.1 * (j as f64 - hf / 2.0);
            let electrons = (background + signal_e * blurred).max(0.0);
            // Shot noise (Gaussian of the Poisson's variance, the electrons many) and read noise.
            let noise = (electrons + READ_NOISE_E * READ_NOISE_E).sqrt();
            let noisy = electrons + noise * rng.sample::<f64, _>(StandardNormal);
            (noisy / FULL_WELL_E * 255.0).round().clamp(0.0, 255.0) as u16
        })
        .collect();
    // Anywhere on the sensor: the centroid's coordinates are the ROI's origin plus its own.
    let roi = Roi::new(
        rng.random_range(0..=1024 - w),
        rng.random_range(0..=1024 - h),
        w,
        h,
    );
    (pixels, roi)
}
