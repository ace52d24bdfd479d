//! Cameras of users' footage and the camera files users have for them: the stand-ins for footage that cannot be
//! committed draw their cameras here, with nominal files as a user writes them (a few percent off, not calibrated).

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::CameraModel;
use roitrack_core::camera::{PinholeIntrinsics, PlumbBob};

/// A camera of `width` x `height` px with a focal length `f_px`, its principal point at `c_px` and the radial
/// distortion `k1` (plumb_bob), no skew.
///
/// ```
/// let camera = roitrack_sim::user_cameras::camera(640, 480, 600.0, (320.0, 240.0), -0.05);
/// assert_eq!((camera.width_px, camera.intrinsics.fx_px), (640, 600.0));
/// ```
pub fn camera(width: u32, height: u32, f_px: f64, c_px: (f64, f64), k1: f64) -> CameraModel {
    CameraModel::new(
        "nominal",
        width,
        height,
        PinholeIntrinsics {
            fx_px: f_px,
            fy_px: f_px,
            skew_px: 0.0,
            cx_px: c_px.0,
            cy_px: c_px.1,
        },
        PlumbBob {
            k1,
            ..PlumbBob::default()
        },
    )
    .unwrap()
}

/// The camera file a user has for `truth`: each focal length and principal point coordinate off by up to 2 % (of
/// itself), k1 by up to 0.03. Drawn again if roitrack would refuse it (a k1 whose polynomial folds back inside the
/// image is not invertible over it), as it refuses such a file. `truth` has a plumb_bob lens ([`camera`]).
///
/// ```
/// use rand::SeedableRng;
/// use roitrack_sim::user_cameras::{camera, nominal};
///
/// let truth = camera(640, 480, 600.0, (320.0, 240.0), -0.05);
/// let file = nominal(&truth, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1));
/// assert!((file.intrinsics.fx_px / truth.intrinsics.fx_px - 1.0).abs() <= 0.02);
/// ```
///
/// # Panics
/// If `truth`'s lens is not plumb_bob.
pub fn nominal(truth: &CameraModel, rng: &mut ChaCha8Rng) -> CameraModel {
    let k = &truth.intrinsics;
    let roitrack_core::camera::Distortion::PlumbBob(d) = truth.distortion else {
        panic!("nominal: the true camera's lens must be plumb_bob")
    };
    loop {
        let mut off = |x: f64| x * (1.0 + rng.random_range(-0.02..0.02));
        let intrinsics = PinholeIntrinsics {
            fx_px: off(k.fx_px),
            fy_px: off(k.fy_px),
            skew_px: 0.0,
            cx_px: off(k.cx_px),
            cy_px: off(k.cy_px),
        };
        let distortion = PlumbBob {
            k1: d.k1 + rng.random_range(-0.03..0.03),
            ..d
        };
        if let Ok(camera) = CameraModel::new(
            "nominal",
            truth.width_px,
            truth.height_px,
            intrinsics,
            distortion,
        ) {
            return camera;
        }
    }
}

/// A photograph's camera drawn from `rng`: 640 x 480 or 800 x 600, a focal length of 0.8-1.6 image widths, the
/// principal point within 15 px of the centre, k1 from -0.25 to 0; and the camera file a user has for it
/// ([`nominal`]). Returns (the truth, the file, the true focal length in px).
///
/// ```
/// use rand::SeedableRng;
///
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
/// let (truth, file, f_px) = roitrack_sim::user_cameras::random_photo_camera(&mut rng);
/// assert_eq!((truth.width_px, truth.height_px), (file.width_px, file.height_px));
/// assert_eq!(truth.intrinsics.fx_px, f_px);
/// ```
pub fn random_photo_camera(rng: &mut ChaCha8Rng) -> (CameraModel, CameraModel, f64) {
    let (width, height) = if rng.random_bool(0.5) {
        (640, 480)
    } else {
        (800, 600)
    };
    let f_px = rng.random_range(0.8..1.6) * f64::from(width);
    let c_px = (
        0.5 * f64::from(width) + rng.random_range(-15.0..15.0),
        0.5 * f64::from(height) + rng.random_range(-15.0..15.0),
    );
    let truth = camera(width, height, f_px, c_px, rng.random_range(-0.25..0.0));
    let camera_file = nominal(&truth, rng);
    (truth, camera_file, f_px)
}
