//! The cameras placed one by one against those placed: their pairs of poses, the offset, the mount and clock fitted.

use nalgebra::{DMatrix, Matrix3, Matrix6, SMatrix, Vector3};

use crate::rig::{CameraMount, ClockModel, MAX_DRIFT_PPM, RigCamera};
use roitrack_core::MotionState;

use super::fit::{
    Fit, Weights, apply_step, carried_from_partner, columns_of_unknowns, largest_distance_m,
    mean_mount, mean_square_residual, normal_equations,
};
use super::{CameraCalibration, RigCalibrationError, RigCalibrator};

/// A camera placed: its mount and clock, and the covariance of (translation, rotation, offset) in the rig's terms,
/// which a camera placed against it inherits.
#[derive(Debug, Clone)]
pub(super) struct Placed {
    pub(super) mount: CameraMount,
    pub(super) clock: ClockModel,
    /// Covariance of (translation (3), rotation (3), offset (1)): what a camera placed against it inherits.
    pub(super) inherited: SMatrix<f64, 7, 7>,
}

/// What is unknown about the camera being placed, as the columns of the least squares.
#[derive(Debug, Clone, Copy)]
pub(super) struct Unknowns {
    pub(super) mount: bool,
    pub(super) offset: bool,
    pub(super) drift: bool,
}

impl Unknowns {
    pub(super) fn count(&self) -> usize {
        6 * self.mount as usize + self.offset as usize + self.drift as usize
    }
}

/// One estimate of the camera being placed, matched with the placed camera's track.
pub(super) struct Pair {
    /// The camera's own time (s).
    pub(super) s: f64,
    /// The rig time (s) by the current clock.
    pub(super) rig_s: f64,
    /// The camera's state (camera_T_object and twist).
    pub(super) camera: MotionState,
    /// The camera's pose covariance (translation, rotation; its frame).
    pub(super) camera_covariance: Matrix6<f64>,
    /// The placed camera's state at the same rig time, carried into the rig's frame.
    pub(super) rig: MotionState,
    /// The placed camera's pose covariance, carried into the rig's frame.
    pub(super) rig_covariance: Matrix6<f64>,
    /// The placed camera's seconds per second of rig time, `1 + drift 1e-6`: its twist is per second of its clock.
    pub(super) rig_per_s: f64,
}

impl RigCalibrator {
    pub(super) fn no_overlap(
        &self,
        placed: &[Option<Placed>],
        camera: &RigCamera,
    ) -> RigCalibrationError {
        let names: Vec<&str> = self
            .rig
            .cameras()
            .iter()
            .zip(placed)
            .filter(|(_, p)| p.is_some())
            .map(|(c, _)| c.name.as_str())
            .collect();
        RigCalibrationError::NoOverlap {
            camera: camera.name.clone(),
            placed: names.join(", "),
            needed: self.config.min_samples,
            max_offset_s: self.config.max_offset_s,
        }
    }

    /// The next camera to place and its placed partners, the most overlapping first: the pair of an unplaced and a
    /// placed camera whose tracks share the longest stretch of rig time (by the clocks as first given, widened by
    /// the offset search).
    pub(super) fn next_to_place(&self, placed: &[Option<Placed>]) -> Option<(usize, Vec<usize>)> {
        let mut best: Option<(f64, usize)> = None;
        let mut candidates = Vec::new();
        for c in (0..placed.len()).filter(|&c| placed[c].is_none()) {
            let mut partners: Vec<(f64, usize)> = (0..placed.len())
                .filter_map(|p| {
                    let partner = placed[p].as_ref()?;
                    Some((self.shared_span_s(c, p, partner), p))
                })
                .collect();
            partners.sort_by(|a, b| b.0.total_cmp(&a.0));
            let top = partners.first().map_or(f64::NEG_INFINITY, |p| p.0);
            if best.is_none_or(|(b, _)| top > b) {
                best = Some((top, c));
            }
            candidates.push((c, partners.into_iter().map(|(_, p)| p).collect::<Vec<_>>()));
        }
        let (_, c) = best?;
        candidates.into_iter().find(|(k, _)| *k == c)
    }

    fn shared_span_s(&self, c: usize, p: usize, partner: &Placed) -> f64 {
        let (Some((a0, a1)), Some((b0, b1))) = (self.tracks[c].span_s(), self.tracks[p].span_s())
        else {
            return f64::NEG_INFINITY;
        };
        let clock = self.rig.cameras()[c].clock;
        let (a0, a1) = (clock.rig_time_s(a0), clock.rig_time_s(a1));
        let (b0, b1) = (partner.clock.rig_time_s(b0), partner.clock.rig_time_s(b1));
        a1.min(b1) - a0.max(b0) + 2.0 * self.config.max_offset_s
    }

    /// Camera `c`'s estimates matched with placed camera `p`'s track through `clock`, thinned to at most `most`.
    fn pairs(
        &self,
        c: usize,
        p: usize,
        partner: &Placed,
        clock: ClockModel,
        most: usize,
    ) -> Vec<Pair> {
        let samples = &self.tracks[c].samples;
        let stride = samples.len().div_ceil(most.max(1)).max(1);
        samples
            .iter()
            .step_by(stride)
            .filter_map(|sample| {
                let rig_s = clock.rig_time_s(sample.t_s);
                let (placed, covariance) = self.tracks[p]
                    .state_at(partner.clock.camera_time_s(rig_s), self.config.max_gap_s)?;
                let rig_r_camera = partner.mount.camera_r_rig.inverse();
                let mut turn = Matrix6::zeros();
                turn.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(rig_r_camera.matrix());
                turn.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(rig_r_camera.matrix());
                Some(Pair {
                    s: sample.t_s,
                    rig_s,
                    camera: sample.state,
                    camera_covariance: sample.pose_covariance,
                    rig: partner.mount.rig_state(&placed),
                    rig_covariance: turn * covariance * turn.transpose(),
                    rig_per_s: 1.0 + partner.clock.drift_ppm * 1e-6,
                })
            })
            .collect()
    }

    /// The model points the residuals are taken at: the target's points, thinned to at most 16 spread over it.
    fn points(&self) -> Vec<Vector3<f64>> {
        let all = self.target.points();
        let stride = all.len().div_ceil(16).max(1);
        all.iter()
            .step_by(stride)
            .map(|p| p.point_in_obj_m)
            .collect()
    }

    /// Places camera `c` against placed camera `p`.
    pub(super) fn place(
        &self,
        c: usize,
        p: usize,
        partner: &Placed,
    ) -> Result<(CameraCalibration, SMatrix<f64, 7, 7>), RigCalibrationError> {
        let camera = &self.rig.cameras()[c];
        let unknowns = Unknowns {
            mount: !camera.mount_known,
            offset: !camera.offset_known,
            drift: !camera.drift_known,
        };
        let points = self.points();
        let mut clock = camera.clock;
        let mut mount = camera.mount;
        let needed = self.config.min_samples;
        if unknowns.offset {
            (clock.offset_s, mount) =
                self.search_offset((c, p), partner, unknowns, (mount, clock), &points)?;
        } else if unknowns.mount {
            let pairs = self.pairs(c, p, partner, clock, 400);
            if pairs.len() < needed {
                return Err(self.no_overlap_with(c, p));
            }
            mount = mean_mount(&pairs, &points);
        }
        let pairs = self.pairs(c, p, partner, clock, 4000);
        if pairs.len() < needed {
            return Err(self.no_overlap_with(c, p));
        }
        if unknowns.offset || unknowns.drift {
            let moved_m = largest_distance_m(&pairs);
            if moved_m < self.config.min_motion_m {
                let (camera, partner) = self.names(c, p);
                return Err(RigCalibrationError::StillTarget {
                    camera,
                    partner,
                    moved_mm: moved_m * 1e3,
                    needed_mm: self.config.min_motion_m * 1e3,
                });
            }
        }
        let fit = self.fit_mount_then_clock((c, p), partner, unknowns, (mount, clock), &points);
        let (mount, clock) = (fit.mount, fit.clock);
        let inherited_from_partner = carried_from_partner(&mount, partner);
        let index = columns_of_unknowns(unknowns);
        let mut own = SMatrix::<f64, 7, 7>::zeros();
        for i in 0..7 {
            for j in 0..7 {
                if let (Some(a), Some(b)) = (index[i], index[j]) {
                    own[(i, j)] = fit.covariance[(a, b)];
                }
            }
        }
        let total = own + inherited_from_partner;
        let sigma = |i: usize| total[(i, i)].max(0.0).sqrt();
        let drift_sigma_ppm = index[7].map_or(0.0, |a| fit.covariance[(a, a)].max(0.0).sqrt());
        let result = CameraCalibration {
            mount,
            mount_sigma_m: Vector3::new(sigma(0), sigma(1), sigma(2)),
            mount_sigma_rad: Vector3::new(sigma(3), sigma(4), sigma(5)),
            clock,
            offset_sigma_s: sigma(6),
            drift_sigma_ppm,
            placed_against: Some(p),
            samples: fit.samples,
            rms_residual_m: fit.rms_residual_m,
            covariance: fit.covariance,
        };
        Ok((result, total))
    }

    /// The names of camera `c` and of its partner `p`, for an error.
    fn names(&self, c: usize, p: usize) -> (String, String) {
        let cameras = self.rig.cameras();
        (cameras[c].name.clone(), cameras[p].name.clone())
    }

    /// Camera `c` and its partner `p` see the target together too rarely, at any clock offset searched.
    fn no_overlap_with(&self, c: usize, p: usize) -> RigCalibrationError {
        let (camera, placed) = self.names(c, p);
        RigCalibrationError::NoOverlap {
            camera,
            placed,
            needed: self.config.min_samples,
            max_offset_s: self.config.max_offset_s,
        }
    }

    /// The clock offset (s) of camera `c`, and the mount found with it: a coarse grid (1 ms) over ± `max_offset_s`
    /// about `clock`'s, then a fine one (50 µs) about its best, each offset scored by how close its best mount (or
    /// `mount`, when known) lays the two tracks. Err when the tracks never overlap enough, or when the best lies at
    /// the search's edge (the offset is likely beyond it).
    fn search_offset(
        &self,
        (c, p): (usize, usize),
        partner: &Placed,
        unknowns: Unknowns,
        (mount, clock): (CameraMount, ClockModel),
        points: &[Vector3<f64>],
    ) -> Result<(f64, CameraMount), RigCalibrationError> {
        let needed = self.config.min_samples;
        let search = self.config.max_offset_s;
        let coarse_step_s = 1e-3;
        let steps = (search / coarse_step_s).ceil() as i64;
        let start = clock.offset_s;
        let score = |offset_s: f64| -> Option<(f64, CameraMount)> {
            let trial = ClockModel { offset_s, ..clock };
            let pairs = self.pairs(c, p, partner, trial, 400);
            if pairs.len() < needed {
                return None;
            }
            let m = if unknowns.mount {
                mean_mount(&pairs, points)
            } else {
                mount
            };
            Some((mean_square_residual(&pairs, points, &m), m))
        };
        // The offsets `centre_s + k step_s` for |k| <= reach, each kept in `best` if it scores lower (cost, offset,
        // mount).
        let scan =
            |best: &mut Option<(f64, f64, CameraMount)>, centre_s: f64, step_s: f64, reach: i64| {
                for k in -reach..=reach {
                    let offset_s = centre_s + k as f64 * step_s;
                    if let Some((cost, m)) = score(offset_s)
                        && best.is_none_or(|(b, _, _)| cost < b)
                    {
                        *best = Some((cost, offset_s, m));
                    }
                }
            };
        let mut best = None;
        scan(&mut best, start, coarse_step_s, steps);
        let (_, coarse_s, _) = best.ok_or_else(|| self.no_overlap_with(c, p))?;
        if (coarse_s - start).abs() > search - 1.5 * coarse_step_s {
            let (camera, partner) = self.names(c, p);
            return Err(RigCalibrationError::ClockBeyondSearch {
                camera,
                partner,
                max_offset_s: search,
            });
        }
        scan(&mut best, coarse_s, 5e-5, 20);
        let (_, offset_s, m) = best.expect("the coarse search found one");
        Ok((offset_s, m))
    }

    /// The mount with every point weighed alike; then the clock again, the mount held, each residual weighed by the
    /// covariance the two tracks state (see the module documentation for why the two differ). The covariance joins
    /// the first fit's of the mount to the second's of the clock.
    fn fit_mount_then_clock(
        &self,
        (c, p): (usize, usize),
        partner: &Placed,
        unknowns: Unknowns,
        (mount, clock): (CameraMount, ClockModel),
        points: &[Vector3<f64>],
    ) -> Fit {
        let joint = self.refine(
            (c, p),
            partner,
            unknowns,
            (mount, clock),
            points,
            &Weights::Common(Matrix3::identity()),
        );
        if !(unknowns.offset || unknowns.drift) {
            return joint;
        }
        let clock_only = Unknowns {
            mount: false,
            ..unknowns
        };
        let timed = self.refine(
            (c, p),
            partner,
            clock_only,
            (joint.mount, joint.clock),
            points,
            &Weights::Stated,
        );
        let n = unknowns.count();
        let m = 6 * unknowns.mount as usize;
        let mut covariance = DMatrix::zeros(n, n);
        covariance
            .view_mut((0, 0), (m, m))
            .copy_from(&joint.covariance.view((0, 0), (m, m)));
        covariance
            .view_mut((m, m), (n - m, n - m))
            .copy_from(&timed.covariance);
        Fit {
            covariance,
            ..timed
        }
    }

    /// Gauss-Newton with Huber weights on the unknown mount, offset and drift of camera `c`, from `mount` and `clock`.
    fn refine(
        &self,
        (c, p): (usize, usize),
        partner: &Placed,
        unknowns: Unknowns,
        (mut mount, mut clock): (CameraMount, ClockModel),
        points: &[Vector3<f64>],
        weights: &Weights,
    ) -> Fit {
        let n = unknowns.count();
        let mut pairs = self.pairs(c, p, partner, clock, 4000);
        let drift_prior = 1.0 / (MAX_DRIFT_PPM * MAX_DRIFT_PPM);
        for _ in 0..12 {
            let system = normal_equations(&pairs, points, &mount, &clock, unknowns, weights, None);
            let mut h = system.h.clone();
            let mut g = system.g.clone();
            if unknowns.drift {
                // A weak prior within the drifts a rig may have: only a track too short to tell a drift leans on it.
                let d = n - 1;
                h[(d, d)] += drift_prior * system.scale * system.scale;
                g[d] -= drift_prior * system.scale * system.scale * clock.drift_ppm;
            }
            let Some(step) = h.clone().cholesky().map(|ch| ch.solve(&g)) else {
                break;
            };
            let (new_mount, new_clock) = apply_step(&mount, &clock, &step, unknowns);
            mount = new_mount;
            clock = new_clock;
            pairs = self.pairs(c, p, partner, clock, 4000);
            let small = step
                .iter()
                .take(6 * unknowns.mount as usize)
                .all(|x| x.abs() < 1e-9)
                && (!unknowns.offset || step[6 * unknowns.mount as usize].abs() < 1e-9);
            if small {
                break;
            }
        }
        let system = normal_equations(
            &pairs,
            points,
            &mount,
            &clock,
            unknowns,
            weights,
            Some(self.config.batch_s),
        );
        let mut h = system.h.clone();
        if unknowns.drift {
            h[(n - 1, n - 1)] += drift_prior * system.scale * system.scale;
        }
        let covariance = match h.try_inverse() {
            Some(h_inv) => {
                let batches = system.batches as f64;
                let correction = if batches > n as f64 + 1.0 {
                    batches / (batches - n as f64)
                } else {
                    f64::INFINITY
                };
                &h_inv * &system.meat * &h_inv * correction
            }
            None => DMatrix::from_element(n, n, f64::INFINITY),
        };
        Fit {
            mount,
            clock,
            covariance,
            samples: pairs.len(),
            rms_residual_m: (mean_square_residual(&pairs, points, &mount) / 3.0).sqrt(),
        }
    }
}
