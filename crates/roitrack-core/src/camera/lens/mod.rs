//! Lens models: how the normalised image point `(x, y) = (X/Z, Y/Z)` of a point `(X, Y, Z)` in the camera frame is
//! moved before the intrinsics turn it into pixels, in OpenCV's conventions.
//!
//! - `none` ([`Distortion::None`]): the pinhole camera.
//! - `plumb_bob` ([`PlumbBob`], 4 or 5 coefficients `k1 k2 p1 p2 [k3]`): radial `1 + k1 r² + k2 r⁴ + k3 r⁶` and
//!   tangential `p1 p2` terms, OpenCV's default model (`cv::projectPoints` with 4 or 5 coefficients).
//! - `rational_polynomial` ([`RationalPolynomial`], 8 coefficients `k1 k2 p1 p2 k3 k4 k5 k6`): the radial factor is
//!   `(1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)`, OpenCV's `CALIB_RATIONAL_MODEL`.
//! - `equidistant` ([`Equidistant`], 4 coefficients `k1 k2 k3 k4`): the fisheye model of `cv::fisheye`, where the
//!   angle `θ = atan(r)` of the ray to the optical axis becomes `θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)` and the
//!   point is scaled by `θd / r`. Skew is `fx α` in OpenCV's fisheye terms.
//!
//! Each model is a file of this folder implementing [`LensModel`] (its name, its coefficients, the map and its
//! Jacobian, the inverse, example lenses), listed once in the `lens_models!` list below. From that list follow the
//! [`Distortion`] enum, [`Distortion::from_model`] (the one mapping from a model's name and coefficient list to a
//! lens, which every file reader, the ROS bag reader and the Python package use) and the tests of every model's
//! examples (Jacobian against central differences, inverse round trip).

use nalgebra::{Matrix2, Vector2};

use super::CameraError;

mod equidistant;
mod plumb_bob;
mod rational_polynomial;

pub use equidistant::Equidistant;
pub use plumb_bob::PlumbBob;
pub use rational_polynomial::RationalPolynomial;

/// A lens model: one struct per model, one file per struct. What [`Distortion`] asks of each.
pub trait LensModel: Copy + PartialEq + Into<Distortion> {
    /// The model's name as ROS camera_info and roitrack's files write it (`distortion_model`).
    const NAME: &'static str;
    /// The coefficients' names, in the order of [`Self::coefficient_list`] (ROS's and OpenCV's).
    const COEFFICIENT_NAMES: &'static [&'static str];
    /// How many coefficients a file gives, as messages say it (`4 or 5`).
    const COUNTS: &'static str;
    /// Whether the model's normalised plane ends at 90° off the axis (the equidistant one's does), so that an image
    /// may extend beyond it (a fisheye's dark corners): [`super::check_lens`] then does not ask the lens to reach the
    /// image's farthest corner.
    const ENDS_AT_90_DEGREES: bool = false;

    /// The lens of a file's coefficient list (in the order of [`Self::COEFFICIENT_NAMES`]), or why the list is not
    /// one of this model (its length); the values were checked finite by [`Distortion::from_model`].
    fn from_list(coefficients: &[f64]) -> Result<Self, String>;

    /// The coefficients as the model's struct holds them, an array in the order of [`Self::COEFFICIENT_NAMES`].
    type Coefficients: AsRef<[f64]>;

    /// The coefficients, every one of them, in the order of [`Self::COEFFICIENT_NAMES`] (the struct's
    /// `coefficients()`).
    fn coefficient_array(&self) -> Self::Coefficients;

    /// The coefficients as a list.
    fn coefficient_list(&self) -> Vec<f64> {
        self.coefficient_array().as_ref().to_vec()
    }

    /// Whether the map is the identity, every point its own distorted point: by default, whether all coefficients
    /// are zero (a model whose zero coefficients still map, as the equidistant lens's `θd = θ`, says otherwise).
    /// Allocation-free: the renderer asks it for every ROI, and skips the map when it is the identity.
    fn is_identity(&self) -> bool {
        self.coefficient_array().as_ref().iter().all(|&c| c == 0.0)
    }

    /// Distorted normalised point of an undistorted one, and the 2x2 Jacobian of that map.
    fn distort_with_jacobian(&self, n: &Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>);

    /// Distorted normalised point of an undistorted one.
    #[inline]
    fn distort(&self, n: &Vector2<f64>) -> Vector2<f64> {
        self.distort_with_jacobian(n).0
    }

    /// The undistorted normalised point whose distortion is `distorted`, by iteration (to about 1e-14 in normalised
    /// units); `None` if it does not converge or the point is outside the model's range.
    fn undistort(&self, distorted: &Vector2<f64>) -> Option<Vector2<f64>>;

    /// Checks that every coefficient is finite.
    fn validate(&self) -> Result<(), CameraError> {
        check_finite(Self::COEFFICIENT_NAMES, &self.coefficient_list())
    }

    /// Realistic lenses of this model, each with the normalised radius within which it is invertible: they drive the
    /// tests every model passes (its Jacobian against central differences, its inverse).
    fn examples() -> Vec<LensExample>;
}

/// An example lens of a model ([`LensModel::examples`]) and the normalised radius (undistorted, `tan` of the angle
/// off the axis) within which it is invertible.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LensExample {
    /// The example lens.
    pub lens: Distortion,
    /// The undistorted normalised radius (`tan` of the angle off the axis) within which the lens is invertible: the
    /// tests sample points inside it.
    pub max_radius: f64,
}

impl LensExample {
    /// An example of `lens`, invertible within the normalised radius `max_radius`.
    pub fn new(lens: impl Into<Distortion>, max_radius: f64) -> Self {
        Self {
            lens: lens.into(),
            max_radius,
        }
    }
}

/// Newton's method for the undistorted point `n` with `distort(n) = distorted`, to 1e-14 in normalised units.
/// `None` if it does not converge.
fn undistort_by_newton(
    distorted: &Vector2<f64>,
    distort_with_jacobian: impl Fn(&Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>),
) -> Option<Vector2<f64>> {
    let mut n = *distorted;
    for _ in 0..50 {
        let (d, j) = distort_with_jacobian(&n);
        let residual = d - distorted;
        if residual.norm() < 1e-14 {
            return Some(n);
        }
        n -= j.try_inverse()? * residual;
        if !n.x.is_finite() || !n.y.is_finite() {
            return None;
        }
    }
    let residual = (distort_with_jacobian(&n).0 - distorted).norm();
    (residual < 1e-11).then_some(n)
}

fn check_finite(names: &[&'static str], values: &[f64]) -> Result<(), CameraError> {
    for (&field, &value) in names.iter().zip(values) {
        if !value.is_finite() {
            return Err(CameraError::NotFinite { field, value });
        }
    }
    Ok(())
}

/// The registry: every lens model, by its struct. A new model is a file of this folder, its `mod` and `pub use`
/// above, and its name here.
macro_rules! lens_models {
    ($($model:ident),+ $(,)?) => {
        /// A lens distortion model: how the normalised image point of a ray is moved before the intrinsics apply.
        ///
        /// Each model maps an undistorted normalised point to a distorted one ([`Self::distort_with_jacobian`]) and
        /// back ([`Self::undistort`], by iteration). `From` the model structs, so `CameraModel::new` takes any of
        /// them; [`Self::from_model`] makes one from a file's model name and coefficients.
        ///
        /// ```
        /// use nalgebra::Vector2;
        /// use roitrack_core::camera::{Distortion, Equidistant, PlumbBob};
        ///
        /// let fisheye = Distortion::from(Equidistant::from_coefficients([0.05, -0.01, 0.0, 0.0]));
        /// assert_eq!(fisheye.model_name(), "equidistant");
        /// assert_eq!(Distortion::from(PlumbBob::default()).model_name(), "plumb_bob");
        /// assert!(Distortion::None.is_identity());
        /// let n = Vector2::new(0.3, 0.2);
        /// assert!((fisheye.undistort(&fisheye.distort(&n)).unwrap() - n).norm() < 1e-13);
        /// ```
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub enum Distortion {
            /// No distortion: the pinhole camera.
            None,
            $(
                #[doc = concat!("[`", stringify!($model), "`]")]
                $model($model),
            )+
        }

        $(
            impl From<$model> for Distortion {
                fn from(d: $model) -> Self {
                    Self::$model(d)
                }
            }
        )+

        impl Distortion {
            /// Every model's name, `none` first.
            pub const MODEL_NAMES: &'static [&'static str] = &["none", $(<$model as LensModel>::NAME),+];

            /// The model named `name` with a file's `coefficients`, checked finite, the count the model's.
            fn named(name: &str, coefficients: &[f64]) -> Option<Result<Self, String>> {
                $(
                    if name == <$model as LensModel>::NAME {
                        return Some($model::from_list(coefficients).map(Self::from));
                    }
                )+
                None
            }

            /// `plumb_bob (4 or 5), rational_polynomial (8), ...`: the models and their coefficient counts, joined
            /// by commas and `last` before the last one.
            fn model_list(last: &str) -> String {
                let models = [$(format!("{} ({})", <$model as LensModel>::NAME, <$model as LensModel>::COUNTS)),+];
                match models.split_last() {
                    Some((tail, [])) => tail.clone(),
                    Some((tail, head)) => format!("{} {last} {tail}", head.join(", ")),
                    None => String::new(),
                }
            }

            /// Every model's example lenses ([`LensModel::examples`]).
            pub fn examples() -> Vec<LensExample> {
                let mut all = Vec::new();
                $(all.extend($model::examples());)+
                all
            }

            /// The model's name as ROS writes it: `none`, `plumb_bob`, `rational_polynomial`, `equidistant`.
            pub fn model_name(&self) -> &'static str {
                match self {
                    Self::None => "none",
                    $(Self::$model(_) => <$model as LensModel>::NAME,)+
                }
            }

            /// The coefficients in ROS's and OpenCV's order (none for `none`).
            pub fn coefficients(&self) -> Vec<f64> {
                match self {
                    Self::None => Vec::new(),
                    $(Self::$model(d) => d.coefficient_list(),)+
                }
            }

            /// The coefficients' names, in the order of [`Self::coefficients`].
            pub fn coefficient_names(&self) -> &'static [&'static str] {
                match self {
                    Self::None => &[],
                    $(Self::$model(_) => <$model as LensModel>::COEFFICIENT_NAMES,)+
                }
            }

            /// The same model with other coefficients (in the order of [`Self::coefficients`]; missing ones are 0,
            /// extra ones ignored).
            pub fn with_coefficients(&self, c: &[f64]) -> Self {
                match self {
                    Self::None => Self::None,
                    $(Self::$model(_) => {
                        let names = <$model as LensModel>::COEFFICIENT_NAMES;
                        let all: Vec<f64> = (0..names.len()).map(|i| c.get(i).copied().unwrap_or(0.0)).collect();
                        $model::from_list(&all).expect("a model takes all its coefficients").into()
                    })+
                }
            }

            /// Whether the model's normalised plane ends at 90° off the axis ([`LensModel::ENDS_AT_90_DEGREES`]).
            pub fn ends_at_90_degrees(&self) -> bool {
                match self {
                    Self::None => false,
                    $(Self::$model(_) => <$model as LensModel>::ENDS_AT_90_DEGREES,)+
                }
            }

            /// Whether the model leaves every point where it is (no model, or all coefficients zero). Allocation-free:
            /// the renderer asks it for every ROI.
            pub fn is_identity(&self) -> bool {
                match self {
                    Self::None => true,
                    $(Self::$model(d) => d.is_identity(),)+
                }
            }

            /// Checks that every coefficient is finite.
            pub fn validate(&self) -> Result<(), CameraError> {
                match self {
                    Self::None => Ok(()),
                    $(Self::$model(d) => d.validate(),)+
                }
            }

            /// Distorted normalised point of an undistorted one, and the 2x2 Jacobian of that map.
            #[inline]
            pub fn distort_with_jacobian(&self, n: &Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
                match self {
                    Self::None => (*n, Matrix2::identity()),
                    $(Self::$model(d) => d.distort_with_jacobian(n),)+
                }
            }

            /// Distorted normalised point of an undistorted one.
            #[inline]
            pub fn distort(&self, n: &Vector2<f64>) -> Vector2<f64> {
                match self {
                    Self::None => *n,
                    $(Self::$model(d) => d.distort(n),)+
                }
            }

            /// The undistorted normalised point whose distortion is `distorted`, by iteration (to about 1e-14 in
            /// normalised units); `None` if it does not converge.
            pub fn undistort(&self, distorted: &Vector2<f64>) -> Option<Vector2<f64>> {
                match self {
                    Self::None => Some(*distorted),
                    $(Self::$model(d) => d.undistort(distorted),)+
                }
            }
        }
    };
}

lens_models!(PlumbBob, RationalPolynomial, Equidistant);

impl Default for Distortion {
    /// plumb_bob with zero coefficients, as ROS and roitrack's own files write an undistorted camera.
    fn default() -> Self {
        Self::PlumbBob(PlumbBob::default())
    }
}

impl Distortion {
    /// The lens of a model `name` (as ROS camera_info and roitrack's files write it: [`Self::MODEL_NAMES`], or empty
    /// for a file that does not say) and its `coefficients` in ROS's and OpenCV's order: the one mapping from a name
    /// and a list to a lens, which every reader of a calibration uses. The rules:
    ///
    /// - an unknown name is refused, naming the models roitrack reads; so is a coefficient that is not finite;
    /// - **no coefficients is no distortion, [`Distortion::None`], whatever the name**: a file or a CameraInfo with
    ///   an empty list has no measured distortion (an uncalibrated driver's camera_info says `plumb_bob` and `[]`),
    ///   and `none` says so without claiming a model. It is also what roitrack's own camera YAML writes for
    ///   `none` (`plumb_bob` without coefficients), so that such a file reads back as the camera written; and an
    ///   `equidistant` model with no coefficients means a pinhole camera, not the f-θ lens its zeros would be;
    /// - `none` takes no coefficients;
    /// - an empty name with 4 or 5 coefficients is plumb_bob (ROS's default model), with all of them zero no
    ///   distortion, with others refused as ambiguous;
    /// - a named model takes the counts its [`LensModel::from_list`] takes (plumb_bob 4 or 5, rational_polynomial
    ///   8, or OpenCV's 12 or 14 with the extra terms zero, equidistant 4).
    ///
    /// ```
    /// use roitrack_core::camera::Distortion;
    ///
    /// assert_eq!(Distortion::from_model("plumb_bob", &[0.1, 0.0, 0.0, 0.0]).unwrap().coefficients().len(), 5);
    /// assert_eq!(Distortion::from_model("plumb_bob", &[]), Ok(Distortion::None));
    /// assert!(Distortion::from_model("equidistant", &[0.1, 0.0, 0.0, 0.0, 0.0]).unwrap_err().contains("4 numbers"));
    /// assert!(Distortion::from_model("kannala_brandt", &[0.0; 4]).unwrap_err().contains("kannala_brandt"));
    /// ```
    pub fn from_model(name: &str, coefficients: &[f64]) -> Result<Self, String> {
        Self::check_model_name(name)?;
        if let Some(i) = coefficients.iter().position(|c| !c.is_finite()) {
            return Err(format!(
                "coefficient {i} must be a finite number, got {}",
                coefficients[i]
            ));
        }
        let c = coefficients;
        match (name, c.len()) {
            (_, 0) => Ok(Self::None),
            ("none", n) => Err(format!(
                "distortion model none takes no coefficients, got {n}"
            )),
            ("", 4 | 5) => PlumbBob::from_list(c).map(Self::from),
            ("", _) if c.iter().all(|&c| c == 0.0) => Ok(Self::None),
            ("", n) => Err(format!(
                "{n} coefficients without a distortion model: set distortion_model to {}",
                Self::model_list("or")
            )),
            _ => Self::named(name, c).expect("a known model name"),
        }
    }

    /// Whether roitrack reads the distortion model `name` (one of [`Self::MODEL_NAMES`], or empty: not said), and
    /// if not, why.
    pub fn check_model_name(name: &str) -> Result<(), String> {
        if name.is_empty() || Self::MODEL_NAMES.contains(&name) {
            Ok(())
        } else {
            Err(format!(
                "unsupported distortion model {name:?}: roitrack supports none and, with their numbers of \
                 coefficients, {}",
                Self::model_list("and")
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of the normalised plane within `max_radius` of the axis: the axis itself, points near it, and a
    /// spiral out to the edge.
    fn points(max_radius: f64) -> Vec<Vector2<f64>> {
        let mut points = vec![
            Vector2::zeros(),
            Vector2::new(1e-7, -2e-7),
            Vector2::new(-1e-4, 3e-4),
        ];
        for i in 1..=40 {
            let r = max_radius * f64::from(i) / 40.0;
            let azimuth = 2.4 * f64::from(i);
            points.push(r * Vector2::new(azimuth.cos(), azimuth.sin()));
        }
        points
    }

    #[test]
    fn every_model_has_examples_and_its_name_and_coefficients_read_back() {
        for name in &Distortion::MODEL_NAMES[1..] {
            let examples: Vec<_> = Distortion::examples()
                .into_iter()
                .filter(|e| e.lens.model_name() == *name)
                .collect();
            assert!(!examples.is_empty(), "{name} has no examples");
            for e in examples {
                let d = e.lens;
                assert_eq!(d.coefficients().len(), d.coefficient_names().len());
                assert_eq!(
                    Distortion::from_model(d.model_name(), &d.coefficients()),
                    Ok(d)
                );
                assert_eq!(d.with_coefficients(&d.coefficients()), d);
                assert!(!d.is_identity() && d.validate().is_ok());
            }
        }
    }

    /// `is_identity` says the map is the identity, whatever the coefficients say: the renderer and the lens check
    /// skip the map when it does. An equidistant lens with zero coefficients is the f-θ lens, `θd = θ`: it maps
    /// a point at 45° (normalised radius 1) to π/4, not to 1.
    #[test]
    fn only_a_lens_that_maps_every_point_to_itself_is_the_identity() {
        let probe = Vector2::new(0.6, -0.8);
        for name in &Distortion::MODEL_NAMES[1..] {
            let count = Distortion::examples()
                .into_iter()
                .find(|e| e.lens.model_name() == *name)
                .unwrap()
                .lens
                .coefficients()
                .len();
            let zeros = Distortion::named(name, &vec![0.0; count]).unwrap().unwrap();
            let moves = (zeros.distort(&probe) - probe).norm() > 1e-12;
            assert_eq!(zeros.is_identity(), !moves, "{name} with zero coefficients");
        }
        assert!(Distortion::None.is_identity());
    }

    #[test]
    fn every_example_inverts_its_projection() {
        for e in Distortion::examples() {
            for n in points(e.max_radius) {
                let back = e.lens.undistort(&e.lens.distort(&n));
                let back = back.unwrap_or_else(|| panic!("{e:?}: {n:?} does not undistort"));
                assert!(
                    (back - n).norm() < 1e-12 * (1.0 + n.norm()),
                    "{e:?}: {n:?} -> {back:?}"
                );
            }
        }
    }

    #[test]
    fn every_example_jacobian_matches_central_differences() {
        use rand::Rng;
        for e in Distortion::examples() {
            roitrack_testkit::check_jacobian(
                &format!("{} {:?}", e.lens.model_name(), e.lens.coefficients()),
                Vector2::zeros(),
                |rng, spread| {
                    let (r, azimuth) = (
                        rng.random_range(0.0..e.max_radius),
                        rng.random_range(0.0..6.3),
                    );
                    spread * r * Vector2::new(f64::cos(azimuth), f64::sin(azimuth))
                },
                &Vector2::repeat(1.0),
                |n, delta| e.lens.distort(&(n + delta)),
                |n| e.lens.distort_with_jacobian(n).1,
            );
        }
    }

    /// The rules of [`Distortion::from_model`], one case each.
    #[test]
    fn names_and_lists_become_lenses_by_one_rule() {
        let plumb_bob = |c: [f64; 5]| Distortion::from(PlumbBob::from_coefficients(c));
        let ok = |name: &str, c: &[f64]| Distortion::from_model(name, c).unwrap();
        let err = |name: &str, c: &[f64]| Distortion::from_model(name, c).unwrap_err();
        // No coefficients: no distortion, whatever the (known) name.
        for name in Distortion::MODEL_NAMES.iter().chain([&""]) {
            assert_eq!(ok(name, &[]), Distortion::None, "{name}");
        }
        assert!(
            err("kannala_brandt", &[])
                .starts_with("unsupported distortion model \"kannala_brandt\"")
        );
        assert!(err("none", &[0.0]).contains("none takes no coefficients"));
        assert!(
            err("plumb_bob", &[0.1, f64::NAN, 0.0, 0.0])
                .contains("coefficient 1 must be a finite number")
        );
        // plumb_bob with 4 or 5, also without a name; zeros without a name are no distortion.
        assert_eq!(
            ok("plumb_bob", &[0.1, 0.2, 0.3, 0.4]),
            plumb_bob([0.1, 0.2, 0.3, 0.4, 0.0])
        );
        assert_eq!(
            ok("", &[0.1, 0.2, 0.3, 0.4, 0.5]),
            plumb_bob([0.1, 0.2, 0.3, 0.4, 0.5])
        );
        assert_eq!(ok("", &[0.0; 8]), Distortion::None);
        assert!(err("", &[0.1; 8]).starts_with("8 coefficients without a distortion model"));
        assert!(err("plumb_bob", &[0.1; 8]).starts_with("plumb_bob takes 4 or 5 numbers"));
        // rational_polynomial with 8, or OpenCV's 12 or 14 with the extra terms zero.
        let mut fourteen = vec![0.1, -0.2, 1e-3, -2e-3, 0.05, 0.3, -0.1, 0.02];
        let eight = ok("rational_polynomial", &fourteen);
        fourteen.extend([0.0; 6]);
        assert_eq!(ok("rational_polynomial", &fourteen), eight);
        assert_eq!(ok("rational_polynomial", &fourteen[..12]), eight);
        fourteen[10] = 0.1;
        assert!(
            err("rational_polynomial", &fourteen)
                .starts_with("rational_polynomial takes 8 numbers")
        );
        assert!(
            err("rational_polynomial", &fourteen[..9])
                .starts_with("rational_polynomial takes 8 numbers")
        );
        assert!(err("equidistant", &fourteen[..5]).starts_with("equidistant takes 4 numbers"));
        assert_eq!(
            ok("equidistant", &[0.1, 0.0, 0.0, 0.0]).model_name(),
            "equidistant"
        );
    }
}
