//! The ROS 2 messages roitrack writes, as serde structs in the field order of their `.msg` definitions (CDR follows
//! that order), and the definitions themselves, for the bag's `ros2msg` schemas.

use serde::ser::{Serialize, SerializeTuple, Serializer};

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds past `sec`, below 10⁹.
    pub nanosec: u32,
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Header<'a> {
    /// When the data was taken.
    pub stamp: Time,
    /// The frame the data is expressed in.
    pub frame_id: &'a str,
}

/// `geometry_msgs/msg/Vector3`, also `geometry_msgs/msg/Point` (same fields and layout).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Vector3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Quaternion {
    /// Vector part, x.
    pub x: f64,
    /// Vector part, y.
    pub y: f64,
    /// Vector part, z.
    pub z: f64,
    /// Scalar part.
    pub w: f64,
}

/// `geometry_msgs/msg/Pose` (and, with the same layout, `geometry_msgs/msg/Transform`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Pose {
    /// Position (m; for a transform, its translation).
    pub position: Vector3,
    /// Orientation as a unit quaternion (for a transform, its rotation).
    pub orientation: Quaternion,
}

/// A fixed-size array (`float64[N]`): CDR writes its elements without a length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fixed<const N: usize>(pub [f64; N]);

impl<const N: usize> Serialize for Fixed<N> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut tuple = serializer.serialize_tuple(N)?;
        for value in &self.0 {
            tuple.serialize_element(value)?;
        }
        tuple.end()
    }
}

/// A `uint8[]`: its length, then the bytes in one write.
#[derive(Debug, Clone, Copy)]
pub struct Bytes<'a>(pub &'a [u8]);

impl Serialize for Bytes<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(self.0)
    }
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6 x 6 covariance of (x, y, z, rotation about x, y, z) (m², rad²).
    pub covariance: Fixed<36>,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Twist {
    /// Linear velocity (m/s).
    pub linear: Vector3,
    /// Angular velocity (rad/s).
    pub angular: Vector3,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Row-major 6 x 6 covariance of (linear x, y, z, angular x, y, z) ((m/s)², (rad/s)²).
    pub covariance: Fixed<36>,
}

/// `geometry_msgs/msg/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct PoseWithCovarianceStamped<'a> {
    /// When, and the frame the pose is expressed in.
    pub header: Header<'a>,
    /// The pose and its covariance.
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/msg/TwistWithCovarianceStamped`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TwistWithCovarianceStamped<'a> {
    /// When, and the frame the twist is expressed in.
    pub header: Header<'a>,
    /// The twist and its covariance.
    pub twist: TwistWithCovariance,
}

/// `nav_msgs/msg/Odometry`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Odometry<'a> {
    /// When, and the frame of the pose (the parent frame).
    pub header: Header<'a>,
    /// The frame whose pose this is (the moving body).
    pub child_frame_id: &'a str,
    /// The child frame's pose in the header's frame, with covariance.
    pub pose: PoseWithCovariance,
    /// The twist, with covariance.
    pub twist: TwistWithCovariance,
}

/// `geometry_msgs/msg/TransformStamped` (its `Transform` has the layout of [`Pose`]: translation, rotation).
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TransformStamped<'a> {
    /// When, and the parent frame.
    pub header: Header<'a>,
    /// The frame the transform places in the parent frame.
    pub child_frame_id: &'a str,
    /// The child frame's pose in the parent frame (translation in m, rotation).
    pub transform: Pose,
}

/// A sequence of one element (`T[]` with a single entry), without a `Vec`.
#[derive(Debug, Clone, Copy)]
pub struct One<T>(pub T);

impl<T: Serialize> Serialize for One<T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = serializer.serialize_seq(Some(1))?;
        seq.serialize_element(&self.0)?;
        seq.end()
    }
}

/// `tf2_msgs/msg/TFMessage` with one transform.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TfMessage<'a> {
    /// The transform.
    pub transforms: One<TransformStamped<'a>>,
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct RegionOfInterest {
    /// Leftmost column of the region (px).
    pub x_offset: u32,
    /// Top row of the region (px).
    pub y_offset: u32,
    /// Height of the region (px); 0 with `width` 0: the full image.
    pub height: u32,
    /// Width of the region (px).
    pub width: u32,
    /// Whether the region is to be rectified.
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CameraInfo<'a> {
    /// When, and the camera's optical frame.
    pub header: Header<'a>,
    /// Image height (px).
    pub height: u32,
    /// Image width (px).
    pub width: u32,
    /// The distortion model's name (`plumb_bob`, `rational_polynomial`, `equidistant`).
    pub distortion_model: &'a str,
    /// The distortion coefficients, in the model's order.
    pub d: Vec<f64>,
    /// The intrinsic matrix, row-major 3 x 3 (px).
    pub k: Fixed<9>,
    /// The rectification rotation, row-major 3 x 3.
    pub r: Fixed<9>,
    /// The projection matrix, row-major 3 x 4 (px).
    pub p: Fixed<12>,
    /// Horizontal binning (0 or 1: none).
    pub binning_x: u32,
    /// Vertical binning (0 or 1: none).
    pub binning_y: u32,
    /// The part of the sensor the image comes from (all zero: the full image).
    pub roi: RegionOfInterest,
}

/// A sequence (`T[]`) borrowed from a slice.
#[derive(Debug, Clone, Copy)]
pub struct Seq<'a, T>(pub &'a [T]);

impl<T: Serialize> Serialize for Seq<'_, T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = serializer.serialize_seq(Some(self.0.len()))?;
        for element in self.0 {
            seq.serialize_element(element)?;
        }
        seq.end()
    }
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct KeyValue<'a> {
    /// The value's name.
    pub key: &'a str,
    /// The value, as text.
    pub value: &'a str,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct DiagnosticStatus<'a> {
    /// 0 OK, 1 warning, 2 error, 3 stale.
    pub level: u8,
    /// What is reported on.
    pub name: &'a str,
    /// The status in words.
    pub message: &'a str,
    /// The device reported on.
    pub hardware_id: &'a str,
    /// Named values of the status.
    pub values: Seq<'a, KeyValue<'a>>,
}

/// `diagnostic_msgs/msg/DiagnosticArray` with one status.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct DiagnosticArray<'a> {
    /// When.
    pub header: Header<'a>,
    /// The status.
    pub status: One<DiagnosticStatus<'a>>,
}

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Image<'a> {
    /// When the image was taken, and the camera's optical frame.
    pub header: Header<'a>,
    /// Rows (px).
    pub height: u32,
    /// Columns (px).
    pub width: u32,
    /// The pixels' encoding (`mono8`, `mono16`, ...).
    pub encoding: &'a str,
    /// 1 if multi-byte pixel values are big-endian.
    pub is_bigendian: u8,
    /// Bytes of a row.
    pub step: u32,
    /// The pixels, row after row.
    pub data: Bytes<'a>,
}

/// `foxglove_msgs/msg/Point2`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Point2 {
    /// Column (px).
    pub x: f64,
    /// Row (px).
    pub y: f64,
}

/// `foxglove_msgs/msg/Color`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Color {
    /// Red, 0..1.
    pub r: f64,
    /// Green, 0..1.
    pub g: f64,
    /// Blue, 0..1.
    pub b: f64,
    /// Opacity, 0..1.
    pub a: f64,
}

/// `foxglove_msgs/msg/CircleAnnotation`.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct CircleAnnotation {
    /// The image's time.
    pub timestamp: Time,
    /// The circle's centre (px).
    pub position: Point2,
    /// The circle's diameter (px).
    pub diameter: f64,
    /// The outline's width (px).
    pub thickness: f64,
    /// The inside's colour.
    pub fill_color: Color,
    /// The outline's colour.
    pub outline_color: Color,
}

/// `foxglove_msgs/msg/PointsAnnotation`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PointsAnnotation {
    /// The image's time.
    pub timestamp: Time,
    /// How the points are drawn: 1 points, 2 a closed loop, 3 a line strip, 4 line segments.
    pub r#type: u8,
    /// The points (px).
    pub points: Vec<Point2>,
    /// The colour of every point, unless `outline_colors` is given.
    pub outline_color: Color,
    /// One colour per point (empty: `outline_color` for all).
    pub outline_colors: Vec<Color>,
    /// The colour inside a closed loop.
    pub fill_color: Color,
    /// Width of the lines or size of the points (px).
    pub thickness: f64,
}

/// `foxglove_msgs/msg/TextAnnotation`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TextAnnotation {
    /// The image's time.
    pub timestamp: Time,
    /// Where the text starts: its bottom-left corner (px).
    pub position: Point2,
    /// The text.
    pub text: String,
    /// Font size (px).
    pub font_size: f64,
    /// The text's colour.
    pub text_color: Color,
    /// The colour behind the text.
    pub background_color: Color,
}

/// `foxglove_msgs/msg/ImageAnnotations`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ImageAnnotations {
    /// The circles drawn.
    pub circles: Vec<CircleAnnotation>,
    /// The point sets and lines drawn.
    pub points: Vec<PointsAnnotation>,
    /// The texts drawn.
    pub texts: Vec<TextAnnotation>,
}

/// `roitrack_msgs/msg/BlobMeasurements`: roitrack's own message, the blob centroids it measured (docs/ros2.md). The
/// arrays are parallel, one entry per centroid; `sigma_px` is empty when the centroids' noise is not known.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct BlobMeasurements<'a> {
    /// Stamped with the time of the first centroid; the camera's frame.
    pub header: Header<'a>,
    /// Each centroid's target point id.
    pub point_ids: Seq<'a, u32>,
    /// Each centroid's column (px, raw image).
    pub u_px: Seq<'a, f64>,
    /// Each centroid's row (px, raw image).
    pub v_px: Seq<'a, f64>,
    /// Each centroid's time less the header stamp (s).
    pub dt_s: Seq<'a, f64>,
    /// Each centroid's noise standard deviation (px); empty when not known.
    pub sigma_px: Seq<'a, f64>,
}

/// The full name of [`BlobMeasurements`].
pub const BLOB_MEASUREMENTS: &str = "roitrack_msgs/msg/BlobMeasurements";

/// The `.msg` text of every type roitrack writes, by full name (`pkg/msg/Type`), without comments.
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/msg/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    (
        "geometry_msgs/msg/Point",
        "float64 x\nfloat64 y\nfloat64 z\n",
    ),
    (
        "geometry_msgs/msg/Vector3",
        "float64 x\nfloat64 y\nfloat64 z\n",
    ),
    (
        "geometry_msgs/msg/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    (
        "geometry_msgs/msg/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    ),
    (
        "geometry_msgs/msg/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n",
    ),
    (
        "geometry_msgs/msg/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    ),
    (
        "geometry_msgs/msg/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/msg/TwistWithCovarianceStamped",
        "std_msgs/Header header\ngeometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "nav_msgs/msg/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "geometry_msgs/msg/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    ),
    (
        "geometry_msgs/msg/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    ),
    (
        "tf2_msgs/msg/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
    ),
    (
        "sensor_msgs/msg/RegionOfInterest",
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n",
    ),
    (
        "sensor_msgs/msg/CameraInfo",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n\
         float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n\
         sensor_msgs/RegionOfInterest roi\n",
    ),
    ("diagnostic_msgs/msg/KeyValue", "string key\nstring value\n"),
    (
        "diagnostic_msgs/msg/DiagnosticStatus",
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\nstring message\n\
         string hardware_id\ndiagnostic_msgs/KeyValue[] values\n",
    ),
    (
        "diagnostic_msgs/msg/DiagnosticArray",
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n",
    ),
    (
        "sensor_msgs/msg/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\n\
         uint8[] data\n",
    ),
    (
        "sensor_msgs/msg/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
    ),
    ("foxglove_msgs/msg/Point2", "float64 x\nfloat64 y\n"),
    (
        "foxglove_msgs/msg/Color",
        "float64 r\nfloat64 g\nfloat64 b\nfloat64 a\n",
    ),
    (
        "foxglove_msgs/msg/CircleAnnotation",
        "builtin_interfaces/Time timestamp\nfoxglove_msgs/Point2 position\nfloat64 diameter\nfloat64 thickness\n\
         foxglove_msgs/Color fill_color\nfoxglove_msgs/Color outline_color\n",
    ),
    (
        "foxglove_msgs/msg/PointsAnnotation",
        "builtin_interfaces/Time timestamp\nuint8 UNKNOWN=0\nuint8 POINTS=1\nuint8 LINE_LOOP=2\n\
         uint8 LINE_STRIP=3\nuint8 LINE_LIST=4\nuint8 type\nfoxglove_msgs/Point2[] points\n\
         foxglove_msgs/Color outline_color\nfoxglove_msgs/Color[] outline_colors\nfoxglove_msgs/Color fill_color\n\
         float64 thickness\n",
    ),
    (
        "foxglove_msgs/msg/TextAnnotation",
        "builtin_interfaces/Time timestamp\nfoxglove_msgs/Point2 position\nstring text\nfloat64 font_size\n\
         foxglove_msgs/Color text_color\nfoxglove_msgs/Color background_color\n",
    ),
    (
        "foxglove_msgs/msg/ImageAnnotations",
        "foxglove_msgs/CircleAnnotation[] circles\nfoxglove_msgs/PointsAnnotation[] points\n\
         foxglove_msgs/TextAnnotation[] texts\n",
    ),
    (
        BLOB_MEASUREMENTS,
        "std_msgs/Header header\nuint32[] point_ids\nfloat64[] u_px\nfloat64[] v_px\nfloat64[] dt_s\n\
         float64[] sigma_px\n",
    ),
];

fn definition(full_name: &str) -> Option<&'static str> {
    DEFINITIONS
        .iter()
        .find(|(name, _)| *name == full_name)
        .map(|(_, text)| *text)
}

/// The types a definition's fields name (`pkg/Type`, as `pkg/msg/Type`), in order of appearance.
fn field_types(text: &str) -> impl Iterator<Item = String> + '_ {
    text.lines().filter_map(|line| {
        let field_type = line.split_whitespace().next()?;
        let base = field_type.split('[').next()?;
        let (package, name) = base.split_once('/')?;
        Some(format!("{package}/msg/{name}"))
    })
}

/// The `ros2msg` schema of a type: its definition, then that of every type it uses (depth first, each once), each
/// after a line of 80 `=` and `MSG: pkg/Type`, as `ros2 bag record` writes them.
///
/// ```
/// let schema = roitrack_ros::msg::schema_text("geometry_msgs/msg/PoseWithCovarianceStamped").unwrap();
/// assert!(schema.starts_with("std_msgs/Header header\n"));
/// assert!(schema.contains("\nMSG: builtin_interfaces/Time\nint32 sec\n"));
/// ```
pub fn schema_text(full_name: &str) -> Option<String> {
    let mut text = definition(full_name)?.to_string();
    let mut done = vec![full_name.to_string()];
    let mut pending: Vec<String> = field_types(&text).collect();
    pending.reverse();
    while let Some(dependency) = pending.pop() {
        if done.contains(&dependency) {
            continue;
        }
        let dependency_text = definition(&dependency)?;
        text.push_str(&"=".repeat(80));
        text.push_str(&format!("\nMSG: {}\n", dependency.replace("/msg/", "/")));
        text.push_str(dependency_text);
        let mut nested: Vec<String> = field_types(dependency_text).collect();
        nested.reverse();
        pending.extend(nested);
        done.push(dependency);
    }
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_type_used_has_a_definition_and_appears_once() {
        for (name, _) in DEFINITIONS {
            let schema =
                schema_text(name).unwrap_or_else(|| panic!("{name}: a dependency is missing"));
            for (other, _) in DEFINITIONS {
                let header = format!("MSG: {}\n", other.replace("/msg/", "/"));
                assert!(
                    schema.matches(&header).count() <= 1,
                    "{name}: {other} twice"
                );
            }
        }
        let odometry = schema_text("nav_msgs/msg/Odometry").unwrap();
        for dependency in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
            "geometry_msgs/TwistWithCovariance",
            "geometry_msgs/Twist",
            "geometry_msgs/Vector3",
        ] {
            assert!(
                odometry.contains(&format!("MSG: {dependency}\n")),
                "{dependency}"
            );
        }
    }

    #[test]
    fn cdr_layout_of_a_header_is_that_of_ros2() {
        let header = Header {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: "ab",
        };
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&header, cdr::Infinite).unwrap();
        // Encapsulation (CDR little endian), sec, nanosec, string length with its NUL, "ab\0".
        assert_eq!(
            bytes,
            [
                0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0
            ]
        );
    }
}
