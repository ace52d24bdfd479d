//! The fused filter: an error-state Kalman filter of the rig's 12-dof state augmented by each unknown clock offset
//! and drift, started from a camera's own track, updated by every centroid at its own rig time through its
//! camera's projection, its process noise adapted as the single-camera filter's.

use nalgebra::{DMatrix, Matrix2, Vector2, Vector3};
use roitrack_core::{Matrix2x12, Measurement, MotionState, Vector12};

use super::RigTracker;
use super::estimate::CROSS_CHECK_SPAN_S;
use crate::rig::{RigProjection, rig_projection};
use crate::{KalmanTuning, Matrix12};

/// Gated measurements in a row, per target point, after which the fused track is lost.
const LOST_AFTER_GATED_CYCLES: usize = 4;
/// One camera's measurements rejected in a row, per target point, after which its clock is searched again (the first
/// camera's: the fused track is started again from its own).
const CAMERA_GATED_CYCLES: usize = 2;
/// The covariance is made exactly symmetric again after this many updates (as the single-camera filter's).
const SYMMETRISE_EVERY_UPDATES: u64 = 16;

/// How far back (s) a measurement may be behind the fused filter's time and still be used (it is predicted back).
const MAX_LATENESS_S: f64 = 0.05;

/// The process noise scales' rate of adaptation, range and trend spans: the single-camera filter's.
const PROCESS_ADAPTATION_RATE: f64 = 0.05;
const PROCESS_SCALE_RANGE: (f64, f64) = (1e-4, 1e4);
const TREND_MIN_UPDATES: f64 = 32.0;

/// The fused filter: the rig's state, the unknown clocks, their joint covariance.
#[derive(Debug, Clone)]
pub(super) struct Fused {
    /// The time the track started from: measurements before it are left out.
    start_s: f64,
    pub(super) t_s: f64,
    pub(super) state: MotionState,
    /// Covariance of (δ state (12), then the unknown clock parameters).
    pub(super) p: DMatrix<f64>,
    trend: Vector12,
    trend_rate: f64,
    last_dt_s: f64,
    process_log_scale: [f64; 2],
    pub(super) gated_in_a_row: usize,
    pub(super) newest_gated: bool,
    /// The newest update's normalised innovation squared, and the measurements gated since the last estimate.
    pub(super) newest_nis: f64,
    pub(super) gated_since_estimate: usize,
    pub(super) sum_squares_px2: f64,
    pub(super) count: usize,
    pub(super) estimates: usize,
    /// Updates applied (the covariance is symmetrised every [`SYMMETRISE_EVERY_UPDATES`]), and the scratch of `P Hᵀ`
    /// and of the gain, one row per state.
    updates: u64,
    ph_t: Vec<[f64; 2]>,
    gain: Vec<[f64; 2]>,
}

impl RigTracker {
    /// Starts the fused track from the newest vouched estimate of a synced camera's own tracker (the first camera's
    /// if it has one).
    pub(super) fn start_fused(&mut self) {
        let Some(start) = (0..self.rig.len())
            .filter(|&c| self.synced[c])
            .find_map(|c| self.newest_single[c])
        else {
            return;
        };
        let clock_count = self
            .clock_states
            .iter()
            .map(|(o, d)| usize::from(o.is_some()) + usize::from(d.is_some()))
            .sum::<usize>();
        let n = 12 + clock_count;
        let mut p = DMatrix::zeros(n, n);
        let pose = start.covariance.unwrap_or_else(broad_prior);
        p.view_mut((0, 0), (12, 12)).copy_from(&pose);
        for (c, &(offset, drift)) in self.clock_states.iter().enumerate() {
            if let Some(i) = offset {
                p[(i, i)] = if self.synced[c] {
                    self.offset_sigma_s[c].powi(2)
                } else {
                    0.0
                };
            }
            if let Some(j) = drift {
                p[(j, j)] = self.config.drift_prior_sigma_ppm.powi(2);
            }
        }
        let (process_log_scale, trend_rate) = self.fused.as_ref().map_or(
            (
                [0.0; 2],
                1.0 / (2.0 * self.target.len() as f64).max(TREND_MIN_UPDATES),
            ),
            |f| (f.process_log_scale, f.trend_rate),
        );
        self.fused = Some(Fused {
            start_s: start.t_ref_s,
            t_s: start.t_ref_s,
            state: start.state,
            p,
            trend: Vector12::zeros(),
            trend_rate,
            last_dt_s: 0.0,
            process_log_scale,
            gated_in_a_row: 0,
            newest_gated: false,
            newest_nis: 0.0,
            gated_since_estimate: 0,
            sum_squares_px2: 0.0,
            count: 0,
            estimates: 0,
            updates: 0,
            ph_t: Vec::with_capacity(n),
            gain: Vec::with_capacity(n),
        });
        self.since_estimate = 0;
        self.report.starts += 1;
    }

    /// One update of the fused filter with a centroid of camera `c` (already checked by its own tracker): predicted
    /// to its rig time, projected through its camera, gated, and taken in.
    pub(super) fn fuse(&mut self, c: usize, m: &Measurement) {
        let camera = &self.rig.cameras()[c];
        let Some(point_index) = self.target.index_of(m.id) else {
            return;
        };
        let Ok(ideal_px) = camera.camera.undistort_pixel(&Vector2::new(m.u_px, m.v_px)) else {
            return;
        };
        let clock = self.clocks[c];
        let t_rig_s = clock.rig_time_s(m.t_s);
        let tuning = self.tuning;
        let (offset_index, drift_index) = self.clock_states[c];
        let Some(f) = self.fused.as_mut() else {
            return;
        };
        let dt = t_rig_s - f.t_s;
        if dt < -MAX_LATENESS_S || t_rig_s < f.start_s {
            return;
        }
        f.predict(dt, &tuning);
        let point = self.target.points()[point_index].point_in_obj_m;
        let Some(projected) = rig_projection(
            &self.models[c],
            &camera.mount,
            &clock,
            &f.state,
            &point,
            m.t_s,
            f.t_s,
        ) else {
            return;
        };
        let hph_t = f.load_ph_t(&projected, offset_index, drift_index);
        let innovation = ideal_px - projected.pixel;
        let noise2 = self.noise_px[c] * self.noise_px[c];
        let Some(s_inv) = innovation_inverse(&hph_t, noise2) else {
            return;
        };
        let nis = (innovation.transpose() * s_inv * innovation)[0];
        if !nis.is_finite() {
            return;
        }
        f.sum_squares_px2 += innovation.norm_squared();
        f.count += 1;
        f.newest_nis = nis;
        self.report.fused += 1;
        self.since_estimate += 1;
        let persistence = f.persistence(&projected.jacobian, &innovation, &s_inv);
        let settling = self.restarts[c].settling(m.t_s, self.target.len());
        let accepted = nis <= tuning.gate_sigma * tuning.gate_sigma;
        self.restarts[c].judged(accepted);
        if !accepted {
            self.rejected(c, t_rig_s, settling);
            return;
        }
        f.gated_in_a_row = 0;
        f.newest_gated = false;
        if !settling {
            self.agreed_at_rig_s[c] = t_rig_s;
        }
        self.camera_counts[c].fused += 1;
        self.camera_counts[c].gated_in_a_row = 0;
        // Huber: beyond `huber_sigma`, the noise is inflated in proportion to the distance.
        let distance = nis.sqrt();
        let s_inv = if distance > tuning.huber_sigma {
            match innovation_inverse(&hph_t, noise2 * distance / tuning.huber_sigma) {
                Some(inverse) => inverse,
                None => return,
            }
        } else {
            s_inv
        };
        let Some((delta, clock_corrections)) =
            f.correct(&innovation, &s_inv, offset_index, drift_index)
        else {
            return;
        };
        self.clocks[c].offset_s += clock_corrections[0];
        self.clocks[c].drift_ppm += clock_corrections[1];
        f.adapt(&tuning, persistence, &delta);
    }

    /// A centroid of camera `c` at `t_rig_s` that the fused filter's gate rejected. A settling camera's rejection,
    /// while another camera's centroids agree with the track, tells against that camera (`RigTracker::restarts`);
    /// any other counts against the track: a run of them loses it, and a run from one camera searches its clock
    /// again (the first camera's: the fused track is started again from its own).
    fn rejected(&mut self, c: usize, t_rig_s: f64, settling: bool) {
        self.report.gated += 1;
        self.camera_counts[c].gated += 1;
        let others_agree = (0..self.rig.len())
            .any(|k| k != c && t_rig_s - self.agreed_at_rig_s[k] <= CROSS_CHECK_SPAN_S);
        if settling && others_agree {
            return;
        }
        let Some(f) = self.fused.as_mut() else {
            return;
        };
        f.gated_since_estimate += 1;
        f.gated_in_a_row += 1;
        f.newest_gated = true;
        self.camera_counts[c].gated_in_a_row += 1;
        let n = self.target.len();
        if f.gated_in_a_row >= LOST_AFTER_GATED_CYCLES * n {
            self.fused = None;
        } else if self.camera_counts[c].gated_in_a_row >= CAMERA_GATED_CYCLES * n {
            self.camera_counts[c].gated_in_a_row = 0;
            if c == 0 {
                // The first camera, which holds the rig's clock, no longer agrees with the fused track: the other
                // clocks have carried it away. Started again from the first camera's own track, every clock kept
                // but as uncertain as after its search.
                self.fused = None;
                self.start_fused();
            } else {
                self.resync(c);
            }
        }
    }
}

/// `S⁻¹` of a centroid's innovation, `S = H P Hᵀ + noise² I` (px²).
fn innovation_inverse(hph_t: &Matrix2<f64>, noise2_px2: f64) -> Option<Matrix2<f64>> {
    (hph_t + Matrix2::identity() * noise2_px2).try_inverse()
}

/// The broad prior of a track with no covariance: 1 cm, 0.1 rad, 1 m/s, 10 rad/s.
pub(super) fn broad_prior() -> Matrix12 {
    let sigmas = [
        1e-2, 1e-2, 1e-2, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0, 10.0, 10.0, 10.0,
    ];
    Matrix12::from_diagonal(&Vector12::from_fn(|i, _| sigmas[i] * sigmas[i]))
}

impl Fused {
    /// `P Hᵀ` into the filter's scratch for a centroid's projection (H: the state's 12 columns and the camera's clock
    /// columns, by those columns of P, no allocation per measurement); returns `H P Hᵀ`.
    fn load_ph_t(
        &mut self,
        projected: &RigProjection,
        offset_index: Option<usize>,
        drift_index: Option<usize>,
    ) -> Matrix2<f64> {
        let mut columns = [(0usize, Vector2::zeros()); 14];
        for (k, column) in columns.iter_mut().take(12).enumerate() {
            *column = (k, projected.jacobian.column(k).into_owned());
        }
        let mut used = 12;
        for (index, column) in [
            (offset_index, projected.image_velocity_pxps),
            (drift_index, projected.per_drift_px),
        ] {
            if let Some(i) = index {
                columns[used] = (i, column);
                used += 1;
            }
        }
        let columns = &columns[..used];
        self.ph_t.clear();
        self.ph_t.resize(self.p.nrows(), [0.0; 2]);
        for &(j, h) in columns {
            for (row, entry) in self.ph_t.iter_mut().zip(self.p.column(j).iter()) {
                row[0] += entry * h[0];
                row[1] += entry * h[1];
            }
        }
        let mut hph_t = Matrix2::zeros();
        for &(j, h) in columns {
            for r in 0..2 {
                hph_t[(0, r)] += h[0] * self.ph_t[j][r];
                hph_t[(1, r)] += h[1] * self.ph_t[j][r];
            }
        }
        hph_t
    }

    /// Persistence of the innovation along the displacement the recent corrections predict, translational and
    /// rotational (the single-camera filter's adaptation of the process noise).
    fn persistence(
        &self,
        h12: &Matrix2x12,
        innovation: &Vector2<f64>,
        s_inv: &Matrix2<f64>,
    ) -> [f64; 2] {
        let mut persistence = [0.0; 2];
        for (part, rows) in [(0, [0, 6]), (1, [3, 9])] {
            let expected: Vector2<f64> = rows
                .iter()
                .map(|&r| h12.fixed_columns::<3>(r) * self.trend.fixed_rows::<3>(r))
                .sum();
            let spread2 = (expected.transpose() * s_inv * expected)[0];
            persistence[part] = if spread2 > 0.0 {
                (innovation.transpose() * s_inv * expected)[0] / spread2.sqrt()
            } else {
                0.0
            };
        }
        persistence
    }

    /// Takes in an accepted centroid with the `P Hᵀ` of [`Self::load_ph_t`]: `K = P Hᵀ S⁻¹`, the state corrected by
    /// `K r`, and `P - K (P Hᵀ)ᵀ` as a rank-2 downdate in place. Returns the state's correction and the camera's clock
    /// corrections (offset in s, drift in ppm; 0 for a clock not estimated); `None`, and nothing changed, if the
    /// corrected state is not finite.
    fn correct(
        &mut self,
        innovation: &Vector2<f64>,
        s_inv: &Matrix2<f64>,
        offset_index: Option<usize>,
        drift_index: Option<usize>,
    ) -> Option<(Vector12, [f64; 2])> {
        let gain: &mut Vec<[f64; 2]> = &mut self.gain;
        gain.clear();
        gain.extend(self.ph_t.iter().map(|row| {
            [
                row[0] * s_inv[(0, 0)] + row[1] * s_inv[(1, 0)],
                row[0] * s_inv[(0, 1)] + row[1] * s_inv[(1, 1)],
            ]
        }));
        let correction = |i: usize| gain[i][0] * innovation[0] + gain[i][1] * innovation[1];
        let delta = Vector12::from_fn(|i, _| correction(i));
        let corrected = self.state.corrected(&delta);
        if !corrected.is_finite() {
            return None;
        }
        self.state = corrected;
        let clock_corrections = [offset_index, drift_index].map(|i| i.map_or(0.0, correction));
        for (j, mut column) in self.p.column_iter_mut().enumerate() {
            let (a, b) = (self.ph_t[j][0], self.ph_t[j][1]);
            for (entry, k) in column.iter_mut().zip(gain.iter()) {
                *entry -= k[0] * a + k[1] * b;
            }
        }
        self.updates += 1;
        if self.updates.is_multiple_of(SYMMETRISE_EVERY_UPDATES) {
            let n = self.p.nrows();
            for i in 0..n {
                for j in i + 1..n {
                    let mean = 0.5 * (self.p[(i, j)] + self.p[(j, i)]);
                    self.p[(i, j)] = mean;
                    self.p[(j, i)] = mean;
                }
            }
        }
        Some((delta, clock_corrections))
    }

    /// After an update: the process noise's scales moved by the innovation's `persistence` (if adapted), and the
    /// trend of the corrections followed by `delta`.
    fn adapt(&mut self, tuning: &KalmanTuning, persistence: [f64; 2], delta: &Vector12) {
        if tuning.adapt_motion {
            for (scale, z) in self.process_log_scale.iter_mut().zip(persistence) {
                *scale = (*scale + PROCESS_ADAPTATION_RATE * z.clamp(-3.0, 3.0))
                    .clamp(PROCESS_SCALE_RANGE.0.ln(), PROCESS_SCALE_RANGE.1.ln());
            }
        }
        let rates = self.trend_rates();
        for (row, (trend, correction)) in self.trend.iter_mut().zip(delta).enumerate() {
            *trend += (correction - *trend) * rates[usize::from(row % 6 >= 3)];
        }
    }

    /// Moves the state `dt_s` ahead (or back) under its constant twist and grows the covariance.
    pub(super) fn predict(&mut self, dt_s: f64, tuning: &KalmanTuning) {
        if dt_s == 0.0 {
            return;
        }
        self.last_dt_s = dt_s.abs();
        // F = [I 0 dt·I 0; 0 E 0 B; 0 0 I 0; 0 0 0 I] (`MotionState::transition_jacobian`) applied by its blocks to
        // every column of P, then from the right to every row: F P Fᵀ, and F P on the clocks' cross-covariances
        // (the clocks do not move), in place.
        let f = self.state.transition_jacobian(dt_s);
        let e = f.fixed_view::<3, 3>(3, 3).into_owned();
        let b = f.fixed_view::<3, 3>(3, 9).into_owned();
        let apply = |v: &mut [f64]| {
            let (p, w, dv, dw) = (
                Vector3::new(v[0], v[1], v[2]),
                Vector3::new(v[3], v[4], v[5]),
                Vector3::new(v[6], v[7], v[8]),
                Vector3::new(v[9], v[10], v[11]),
            );
            let p = p + dv * dt_s;
            let w = e * w + b * dw;
            v[..3].copy_from_slice(p.as_slice());
            v[3..6].copy_from_slice(w.as_slice());
        };
        let n = self.p.nrows();
        for mut column in self.p.column_iter_mut() {
            apply(&mut column.as_mut_slice()[..12]);
        }
        let mut row = [0.0; 12];
        for r in 0..n {
            for (k, entry) in row.iter_mut().enumerate() {
                *entry = self.p[(r, k)];
            }
            apply(&mut row);
            for (k, entry) in row.iter().enumerate() {
                self.p[(r, k)] = *entry;
            }
        }
        let dt = dt_s.abs();
        let scale = self.process_log_scale.map(f64::exp);
        for (pos, vel, psd) in [
            (0, 6, tuning.linear_accel_psd * scale[0]),
            (3, 9, tuning.angular_accel_psd * scale[1]),
        ] {
            let (qpp, qpv, qvv) = (psd * dt * dt * dt / 3.0, psd * dt * dt / 2.0, psd * dt);
            for i in 0..3 {
                self.p[(pos + i, pos + i)] += qpp;
                self.p[(pos + i, vel + i)] += qpv;
                self.p[(vel + i, pos + i)] += qpv;
                self.p[(vel + i, vel + i)] += qvv;
            }
        }
        self.state = self.state.predicted(dt_s);
        self.t_s += dt_s;
    }

    /// The trend's weight per update (translational, rotational): as the single-camera filter's, the step over the
    /// filter's own time constant, at most [`Self::trend_rate`].
    fn trend_rates(&self) -> [f64; 2] {
        [0, 3].map(|first| {
            let pose: f64 = (first..first + 3).map(|i| self.p[(i, i)]).sum();
            let twist: f64 = (first + 6..first + 9).map(|i| self.p[(i, i)]).sum();
            let rate = self.last_dt_s / (pose / twist).sqrt();
            if rate.is_finite() && rate > 0.0 {
                rate.min(self.trend_rate)
            } else {
                self.trend_rate
            }
        })
    }
}
