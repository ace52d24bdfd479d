//! The camera made from what a file gives: K checked, the image size taken from the file or the options, and the
//! camera's own checks reported on the field at fault.

use std::path::Path;

use roitrack_core::{CameraModel, Distortion, PinholeIntrinsics};

use super::CameraFileOptions;
use super::fields::field_error;
use crate::FormatError;

/// The 9 numbers of K checked: its layout `[[fx, s, cx], [0, fy, cy], [0, 0, 1]]` and positive focal lengths.
pub(super) fn intrinsics_from_k(
    k: &[f64],
    path: &Path,
    field: &str,
) -> Result<PinholeIntrinsics, FormatError> {
    if k.len() != 9 {
        return Err(field_error(
            path,
            field,
            format!("the camera matrix needs 9 numbers (3 x 3), got {}", k.len()),
        ));
    }
    for (i, want) in [(3, 0.0), (6, 0.0), (7, 0.0), (8, 1.0)] {
        if k[i] != want {
            return Err(field_error(
                path,
                &format!("{field}[{i}]"),
                format!(
                    "must be {want} (K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]), got {}",
                    k[i]
                ),
            ));
        }
    }
    let intrinsics = PinholeIntrinsics {
        fx_px: k[0],
        fy_px: k[4],
        skew_px: k[1],
        cx_px: k[2],
        cy_px: k[5],
    };
    intrinsics.validate().map_err(|e| {
        let index = match &e {
            roitrack_core::CameraError::NotPositive { field: "fy", .. }
            | roitrack_core::CameraError::NotFinite { field: "fy", .. } => 4,
            _ => 0,
        };
        field_error(path, &format!("{field}[{index}]"), e.to_string())
    })?;
    Ok(intrinsics)
}

/// The camera, its image size taken from the file or, if the file has none, from the options.
pub(super) fn build(
    name: String,
    file_size: (Option<u32>, Option<u32>),
    intrinsics: PinholeIntrinsics,
    distortion: Distortion,
    options: &CameraFileOptions,
    path: &Path,
    size_fields: (&str, &str),
) -> Result<CameraModel, FormatError> {
    let (width_px, height_px) = match (file_size, options.image_size) {
        ((Some(w), Some(h)), Some((ow, oh))) if (w, h) != (ow, oh) => {
            return Err(field_error(
                path,
                size_fields.0,
                format!(
                    "the file says {w}x{h} px, --image-size says {ow}x{oh}: a calibration holds for the size it was \
                     made at; leave --image-size out or recalibrate"
                ),
            ));
        }
        ((Some(w), Some(h)), _) => (w, h),
        (_, Some(size)) => size,
        ((None, _), None) => {
            return Err(field_error(
                path,
                size_fields.0,
                "missing: give the image size with --image-size WxH",
            ));
        }
        ((_, None), None) => {
            return Err(field_error(
                path,
                size_fields.1,
                "missing: give the image size with --image-size WxH",
            ));
        }
    };
    CameraModel::new(name, width_px, height_px, intrinsics, distortion).map_err(|e| {
        use roitrack_core::CameraError as E;
        // The value at fault, by its name (fx, k1, ...): each format keeps it under a key of its own.
        let field = match &e {
            E::NotFinite { field, .. } | E::NotPositive { field, .. } => Some(*field),
            E::Implausible(e) => Some(e.field),
            E::Lens(e) => Some(e.coefficient()),
            E::ImageTooLarge { .. } | E::EmptyImage { .. } => Some(size_fields.0),
            E::UndistortionDiverged { .. } | E::TimeModel(_) => None,
        };
        let error = FormatError::new(path, e.to_string());
        match field {
            Some(field) => error.with_field(field),
            None => error,
        }
    })
}

/// A camera read by the ROS YAML reader, with its size checked against the options.
pub(super) fn check_image_size(
    camera: CameraModel,
    options: &CameraFileOptions,
    path: &Path,
    size_fields: (&str, &str),
) -> Result<CameraModel, FormatError> {
    build(
        camera.name.clone(),
        (Some(camera.width_px), Some(camera.height_px)),
        camera.intrinsics,
        camera.distortion,
        options,
        path,
        size_fields,
    )
}
