//! What identification needs of a target that depends on the target alone, computed once per target and thread.

use nalgebra::{Vector2, Vector3};
use roitrack_core::Target;

use super::lattice::TargetLattice;

/// A target thinner than this fraction of its width (its spreads across and along its best plane) is identified as a
/// planar one, on its best plane ([`Target::best_plane`]): the in-plane predictions of the lattice and triple searches
/// miss a point standing off the plane by at most its height times the view's tilt, and the pose that verifies
/// every hypothesis is solved in 3-D.
const NEARLY_PLANAR: f64 = 0.1;

/// Points of a planar or nearly planar target in its best plane and its front normal (object frame); `None` for a
/// target spread in depth.
fn plane_and_front(target: &Target) -> Option<(Vec<Vector2<f64>>, Vector3<f64>)> {
    let [widest, _, thinnest] = target.principal_spreads_m();
    if thinnest > NEARLY_PLANAR * widest {
        return None;
    }
    let plane = target.best_plane();
    let normal: Vector3<f64> = plane.obj_r_plane.column(2).into_owned();
    // The front is the side of negative z in the object frame (a board's printed side faces the camera that sees
    // its x axis to the right and y axis down).
    let front = if normal.z > 0.0 { -normal } else { normal };
    Some((plane.points_in_plane_m.clone(), front))
}

/// What identification needs of a target that depends on the target alone: its plane, lattice and each point's
/// nearest neighbour (the last two cost the square of the points: a quarter of the time of identifying a 336-point
/// grid). Kept for the last target identified on each thread, as a tracker identifies one target frame after frame.
#[derive(Debug)]
pub(super) struct TargetFacts {
    target: Target,
    /// [`plane_and_front`].
    pub(super) planar: Option<(Vec<Vector2<f64>>, Vector3<f64>)>,
    /// The lattice of a planar target's points, if they are on one.
    pub(super) lattice: Option<TargetLattice>,
    /// For each point, its nearest other point (the first of equally near ones).
    pub(super) nearest_point: Vec<usize>,
    /// The centroid of the points (object frame, m).
    pub(super) centre_m: Vector3<f64>,
}

impl TargetFacts {
    /// The facts of `target`: computed, or those kept if they are of the same target.
    pub(super) fn of(target: &Target) -> std::rc::Rc<Self> {
        thread_local! {
            static LAST: std::cell::RefCell<Option<std::rc::Rc<TargetFacts>>> =
                const { std::cell::RefCell::new(None) };
        }
        LAST.with(|last| {
            let mut last = last.borrow_mut();
            if let Some(facts) = last.as_ref().filter(|f| f.target == *target) {
                return facts.clone();
            }
            let facts = std::rc::Rc::new(Self::compute(target));
            *last = Some(facts.clone());
            facts
        })
    }

    fn compute(target: &Target) -> Self {
        let points = target.points();
        let n = points.len();
        let nearest_point: Vec<usize> = (0..n)
            .map(|i| {
                (0..n)
                    .filter(|&j| j != i)
                    .min_by(|&a, &b| {
                        (points[a].point_in_obj_m - points[i].point_in_obj_m)
                            .norm()
                            .total_cmp(
                                &(points[b].point_in_obj_m - points[i].point_in_obj_m).norm(),
                            )
                    })
                    .unwrap_or(0)
            })
            .collect();
        let centre_m = points
            .iter()
            .map(|p| p.point_in_obj_m)
            .sum::<Vector3<f64>>()
            / n.max(1) as f64;
        let planar = plane_and_front(target);
        let lattice = planar
            .as_ref()
            .and_then(|(plane, _)| TargetLattice::of(plane));
        Self {
            target: target.clone(),
            planar,
            lattice,
            nearest_point,
            centre_m,
        }
    }
}
