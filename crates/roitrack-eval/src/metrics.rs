//! The accuracy figures of one evaluation, and their text and JSON renderings.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

/// Accuracy of an estimated trajectory against ground truth (docs/evaluation.md); every field carries its unit.
///
/// Errors are estimate minus truth, in the camera frame, at the estimate's times. The velocity fields are `None`
/// unless both the truth and the estimate have twists.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Number of estimates compared.
    pub count: usize,
    /// Time from the first to the last estimate (s).
    pub duration_s: f64,
    /// Median interval between consecutive estimates (ms); 0 for a single estimate.
    pub estimator_period_ms: f64,
    /// RMS of the position error's norm (mm).
    pub position_rmse_mm: f64,
    /// RMS of the position error along each camera axis x, y, z (mm).
    pub position_rmse_xyz_mm: [f64; 3],
    /// Largest position error norm (mm).
    pub max_position_error_mm: f64,
    /// RMS of the geodesic angle of `R_est⁻¹ R_true` (deg).
    pub rotation_rmse_deg: f64,
    /// RMS of the linear velocity error's norm (mm/s).
    pub velocity_rmse_mm_s: Option<f64>,
    /// RMS of the linear velocity error along each camera axis x, y, z (mm/s).
    pub velocity_rmse_xyz_mm_s: Option<[f64; 3]>,
    /// RMS of the angular velocity error's norm (deg/s).
    pub angular_velocity_rmse_deg_s: Option<f64>,
    /// Shift (estimator samples) maximising the cross-correlation of estimated and true linear velocity; positive
    /// when the estimate lags behind the truth (`est[k] ≈ truth[k - lag]`).
    pub velocity_lag_samples: Option<i64>,
    /// [`velocity_lag_samples`](Self::velocity_lag_samples) refined by a parabola through the correlation peak.
    pub velocity_lag_subsample: Option<f64>,
    /// `velocity_lag_samples × estimator_period_ms` (ms).
    pub velocity_lag_ms: Option<f64>,
    /// The clock offset added to the estimates' times before pairing them with the truth (s).
    #[serde(default)]
    pub time_offset_s: f64,
    /// The alignment of the estimates onto the truth's frame: `none`, `se3` or `sim3`.
    #[serde(default)]
    pub alignment: crate::Alignment,
    /// The alignment's scale (1 unless `sim3`).
    #[serde(default = "one")]
    pub alignment_scale: f64,
    /// The alignment's rotation angle (deg).
    #[serde(default)]
    pub alignment_rotation_deg: f64,
    /// The alignment's translation (mm, truth frame).
    #[serde(default)]
    pub alignment_translation_mm: [f64; 3],
    /// Estimates left out for lying outside the truth's time span (only when asked to skip them).
    #[serde(default)]
    pub skipped_outside_truth: usize,
    /// The relative pose error's interval (s); this and the three below are absent unless asked for.
    pub rpe_interval_s: Option<f64>,
    /// The number of estimate pairs the relative pose error was measured on.
    pub rpe_pairs: Option<usize>,
    /// The RMS of the relative pose error's translation (mm).
    pub rpe_translation_rmse_mm: Option<f64>,
    /// The RMS of the relative pose error's rotation (deg).
    pub rpe_rotation_rmse_deg: Option<f64>,
}

fn one() -> f64 {
    1.0
}

/// The errors of several evaluations pooled (several seeds of one case, say): each RMSE that of all their estimates
/// together (every evaluation's RMSE squared times its count is its sum of squares), the largest error the largest
/// of them all.
///
/// ```
/// use nalgebra::{Isometry3, Translation3, UnitQuaternion};
/// use roitrack_core::PoseSample;
/// use roitrack_eval::{EvalOptions, PooledErrors, evaluate};
///
/// let at = |t_s: f64, x_m: f64| PoseSample {
///     t_s,
///     cam_from_obj: Isometry3::from_parts(Translation3::new(x_m, 0.0, 0.6), UnitQuaternion::identity()),
/// };
/// let truth: Vec<_> = (0..4).map(|k| at(k as f64, 0.0)).collect();
/// // One run of 2 estimates 3 mm off, one of 4 estimates 1 mm off: sqrt((2 * 9 + 4 * 1) / 6) mm.
/// let run = |count: usize, off_m: f64| {
///     let estimates: Vec<_> = (0..count).map(|k| at(k as f64, off_m)).collect();
///     evaluate(&truth, None, &estimates, None, &EvalOptions::default()).unwrap()
/// };
/// let pooled = PooledErrors::of([&run(2, 0.003), &run(4, 0.001)]);
/// assert_eq!(pooled.count, 6);
/// assert!((pooled.position_rmse_mm - (22.0f64 / 6.0).sqrt()).abs() < 1e-9);
/// assert!((pooled.max_position_error_mm - 3.0).abs() < 1e-9);
/// assert!(pooled.velocity_rmse_mm_s.is_nan()); // no twists
/// assert!(PooledErrors::of([]).position_rmse_mm.is_nan());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PooledErrors {
    /// Estimates over all the evaluations.
    pub count: usize,
    /// RMS of the position error's norm over all of them (mm).
    pub position_rmse_mm: f64,
    /// RMS of the rotation error over all of them (deg).
    pub rotation_rmse_deg: f64,
    /// RMS of the linear velocity error's norm over all of them (mm/s); NaN if an evaluation had no velocity.
    pub velocity_rmse_mm_s: f64,
    /// Largest position error of any of them (mm).
    pub max_position_error_mm: f64,
}

impl PooledErrors {
    /// Pools `parts`; with no estimate in them, every figure is NaN.
    pub fn of<'a>(parts: impl IntoIterator<Item = &'a Metrics>) -> Self {
        let (mut count, mut position_sq, mut rotation_sq, mut velocity_sq) = (0, 0.0, 0.0, 0.0);
        let mut max_position_error_mm = f64::NAN;
        for m in parts {
            let n = m.count as f64;
            count += m.count;
            position_sq += n * m.position_rmse_mm.powi(2);
            rotation_sq += n * m.rotation_rmse_deg.powi(2);
            velocity_sq += n * m.velocity_rmse_mm_s.unwrap_or(f64::NAN).powi(2);
            max_position_error_mm = max_position_error_mm.max(m.max_position_error_mm);
        }
        let rms = |sum_sq: f64| {
            if count == 0 {
                f64::NAN
            } else {
                (sum_sq / count as f64).sqrt()
            }
        };
        Self {
            count,
            position_rmse_mm: rms(position_sq),
            rotation_rmse_deg: rms(rotation_sq),
            velocity_rmse_mm_s: rms(velocity_sq),
            max_position_error_mm: if count == 0 {
                f64::NAN
            } else {
                max_position_error_mm
            },
        }
    }
}

impl Metrics {
    /// The metrics as one compact JSON object (the field names above, `null` for absent velocity figures).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("Metrics holds only numbers, which always serialize")
    }

    /// A readable table with aligned columns: metric, value, unit. Velocity rows appear only when present.
    pub fn to_table(&self) -> String {
        let mut rows: Vec<(&str, String, &str)> = vec![
            ("estimates", self.count.to_string(), ""),
            ("duration", number(self.duration_s), "s"),
            ("estimator period", number(self.estimator_period_ms), "ms"),
            ("position RMSE", number(self.position_rmse_mm), "mm"),
        ];
        for (name, value) in ["position RMSE x", "position RMSE y", "position RMSE z"]
            .into_iter()
            .zip(self.position_rmse_xyz_mm)
        {
            rows.push((name, number(value), "mm"));
        }
        rows.push((
            "max position error",
            number(self.max_position_error_mm),
            "mm",
        ));
        rows.push(("rotation RMSE", number(self.rotation_rmse_deg), "deg"));
        if let Some(v) = self.velocity_rmse_mm_s {
            rows.push(("velocity RMSE", number(v), "mm/s"));
        }
        if let Some(xyz) = self.velocity_rmse_xyz_mm_s {
            for (name, value) in ["velocity RMSE x", "velocity RMSE y", "velocity RMSE z"]
                .into_iter()
                .zip(xyz)
            {
                rows.push((name, number(value), "mm/s"));
            }
        }
        if let Some(w) = self.angular_velocity_rmse_deg_s {
            rows.push(("angular velocity RMSE", number(w), "deg/s"));
        }
        if let Some(lag) = self.velocity_lag_samples {
            rows.push(("velocity lag", lag.to_string(), "samples"));
        }
        if let Some(lag) = self.velocity_lag_subsample {
            rows.push(("velocity lag (subsample)", format!("{lag:.3}"), "samples"));
        }
        if let Some(lag) = self.velocity_lag_ms {
            rows.push(("velocity lag", number(lag), "ms"));
        }
        if self.time_offset_s != 0.0 {
            rows.push(("time offset", number(self.time_offset_s), "s"));
        }
        if self.alignment != crate::Alignment::None {
            rows.push(("alignment", self.alignment.name().to_string(), ""));
            rows.push((
                "alignment scale",
                format!("{:.6}", self.alignment_scale),
                "",
            ));
            rows.push((
                "alignment rotation",
                number(self.alignment_rotation_deg),
                "deg",
            ));
            let [x, y, z] = self.alignment_translation_mm;
            rows.push((
                "alignment translation",
                format!("{} {} {}", number(x), number(y), number(z)),
                "mm",
            ));
        }
        if self.skipped_outside_truth > 0 {
            rows.push((
                "skipped (outside truth)",
                self.skipped_outside_truth.to_string(),
                "",
            ));
        }
        if let (Some(interval), Some(pairs)) = (self.rpe_interval_s, self.rpe_pairs) {
            rows.push(("RPE interval", number(interval), "s"));
            rows.push(("RPE pairs", pairs.to_string(), ""));
        }
        if let Some(t) = self.rpe_translation_rmse_mm {
            rows.push(("RPE translation RMSE", number(t), "mm"));
        }
        if let Some(r) = self.rpe_rotation_rmse_deg {
            rows.push(("RPE rotation RMSE", number(r), "deg"));
        }

        let header = ("metric", "value", "unit");
        let name_width = rows
            .iter()
            .map(|r| r.0.len())
            .chain([header.0.len()])
            .max()
            .unwrap_or(0);
        let value_width = rows
            .iter()
            .map(|r| r.1.len())
            .chain([header.1.len()])
            .max()
            .unwrap_or(0);
        let mut table = String::new();
        let mut line = |name: &str, value: &str, unit: &str| {
            let text = format!("{name:<name_width$}  {value:>value_width$}  {unit}");
            // Writing to a String cannot fail.
            let _ = writeln!(table, "{}", text.trim_end());
        };
        line(header.0, header.1, header.2);
        for (name, value, unit) in &rows {
            line(name, value, unit);
        }
        table
    }
}

/// Four decimals, or scientific notation for magnitudes too small to show that way.
fn number(value: f64) -> String {
    if value != 0.0 && value.abs() < 1e-3 {
        format!("{value:.3e}")
    } else {
        format!("{value:.4}")
    }
}
