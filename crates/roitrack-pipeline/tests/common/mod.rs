//! What the stand-ins for users' footage share: cameras, and the camera files users have for them.
// Each test binary that includes this module uses a part of it.
#![allow(dead_code)]

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use roitrack_core::CameraModel;
use roitrack_core::camera::{PinholeIntrinsics, PlumbBob};

/// A camera of `width` x `height` px.
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
/// image is not invertible over it), as it refuses such a file.
pub fn nominal(truth: &CameraModel, rng: &mut ChaCha8Rng) -> CameraModel {
    let k = &truth.intrinsics;
    let roitrack_core::camera::Distortion::PlumbBob(d) = truth.distortion else {
        unreachable!()
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
