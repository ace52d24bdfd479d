//! `roitrack detect`: find, identify and measure the target in photographs (see [`roitrack::pipeline::photo`]).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use roitrack::formats::{MarkKind, OverlayMark};
use roitrack::pipeline::{PhotoDetection, PhotoOptions, PolarityChoice, detect_target};
use roitrack::{CameraModel, Target};
use serde_json::json;

use crate::args::{CameraArgs, TargetArgs};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PolarityArg {
    /// Try both, per image, and say which identified the target.
    Auto,
    /// Bright blobs on a darker background (LEDs, retro-reflective markers).
    Bright,
    /// Dark blobs on a lighter background (printed circles).
    Dark,
}

impl From<PolarityArg> for PolarityChoice {
    fn from(p: PolarityArg) -> Self {
        match p {
            PolarityArg::Auto => PolarityChoice::Auto,
            PolarityArg::Bright => PolarityChoice::Bright,
            PolarityArg::Dark => PolarityChoice::Dark,
        }
    }
}

/// The `--distance-m NEAR FAR` option, checked.
pub fn distance_range(distance_m: Option<&[f64]>) -> Result<Option<(f64, f64)>> {
    match distance_m {
        Some(&[near, far]) if near > 0.0 && far >= near && far.is_finite() => Ok(Some((near, far))),
        Some(other) => {
            bail!("--distance-m: want NEAR_M FAR_M with 0 < NEAR_M <= FAR_M, got {other:?}")
        }
        None => Ok(None),
    }
}

/// Find the target in photographs (PNG, JPEG, PGM/PPM, TIFF; 8 or 16 bits; colour made grey): detect the blobs,
/// identify the target's points among them (clutter, partial views, symmetric and hexagonal grids), solve the pose.
/// Exits with status 1 if any image failed, each failure's reason printed.
#[derive(Debug, Args)]
pub struct DetectArgs {
    /// The camera (the images must be its size).
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub target: TargetArgs,
    /// Which blobs to look for.
    #[arg(long, value_enum, default_value = "auto")]
    pub polarity: PolarityArg,
    /// The nearest and farthest distances (m) the target may be at: blobs no target circle can make at such
    /// distances are left out (needs diameters in the target file). Default: any size.
    #[arg(long, num_args = 2, value_names = ["NEAR_M", "FAR_M"])]
    pub distance_m: Option<Vec<f64>>,
    /// Write per image a PNG (`<image name>.overlay.png`) with the matched blobs and their ids (green), the model
    /// projected with the pose (red +), unmatched blobs (yellow) and points expected but not found (magenta x), into
    /// this folder. Default: no overlay.
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// One JSON object per image on its own line of stdout, instead of a table. Fields: image, ok, error (when not
    /// ok), polarity, ambiguous, points [{id, u_px, v_px}] (raw distorted pixels), cam_t_obj_m [x, y, z],
    /// cam_q_obj_xyzw [x, y, z, w] (x_cam = R x_obj + t), residual_rms_px (sqrt of the mean squared reprojection
    /// distance), missing, blobs, time_ms.
    #[arg(long)]
    pub json: bool,
    /// The photographs.
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
}

pub fn run(args: &DetectArgs) -> Result<()> {
    let camera = args.camera.read()?;
    let target = args.target.read()?;
    if let Some(dir) = &args.overlay {
        std::fs::create_dir_all(dir).map_err(|e| {
            anyhow::anyhow!("{}: cannot create the overlay folder: {e}", dir.display())
        })?;
    }
    let options = PhotoOptions {
        polarity: args.polarity.into(),
        distance_range_m: distance_range(args.distance_m.as_deref())?,
        ..PhotoOptions::default()
    };
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    if !args.json {
        writeln!(
            out,
            "{:<32} {:>6} {:>7} {:>9} {:>8} {:>9}  result",
            "image", "points", "blobs", "polarity", "rms px", "time ms"
        )?;
    }
    let mut failures = 0;
    for path in &args.images {
        let started = Instant::now();
        let outcome = detect_one(path, &camera, &target, &options, args.overlay.as_deref());
        let time_ms = started.elapsed().as_secs_f64() * 1e3;
        let name = path.display().to_string();
        match outcome {
            Ok(found) => {
                let q = found.cam_q_obj();
                let t = found.state.cam_t_obj_m;
                if args.json {
                    let points: Vec<_> = found
                        .points
                        .iter()
                        .map(|p| json!({"id": p.id, "u_px": p.centre_px.x, "v_px": p.centre_px.y}))
                        .collect();
                    let line = json!({
                        "image": name,
                        "ok": true,
                        "polarity": found.polarity.name(),
                        "ambiguous": found.ambiguous,
                        "points": points,
                        "cam_t_obj_m": [t.x, t.y, t.z],
                        "cam_q_obj_xyzw": [q.i, q.j, q.k, q.w],
                        "residual_rms_px": found.reprojection_rms_px,
                        "missing": found.missing,
                        "blobs": found.blobs.len(),
                        "time_ms": time_ms,
                    });
                    writeln!(out, "{line}")?;
                } else {
                    writeln!(
                        out,
                        "{:<32} {:>6} {:>7} {:>9} {:>8.3} {:>9.2}  {}",
                        name,
                        found.points.len(),
                        found.blobs.len(),
                        found.polarity.name(),
                        found.reprojection_rms_px,
                        time_ms,
                        if found.ambiguous {
                            "found (ambiguous: the target's symmetry leaves the labelling open; canonical labels)"
                        } else {
                            "found"
                        }
                    )?;
                }
            }
            Err(error) => {
                failures += 1;
                if args.json {
                    let line = json!({"image": name, "ok": false, "error": format!("{error:#}"), "time_ms": time_ms});
                    writeln!(out, "{line}")?;
                } else {
                    writeln!(
                        out,
                        "{name:<32} {:>6} {:>7} {:>9} {:>8} {time_ms:>9.2}  FAILED: {error:#}",
                        "-", "-", "-", "-"
                    )?;
                }
            }
        }
    }
    out.flush()?;
    if failures > 0 {
        bail!(
            "the target was not found in {failures} of {} images",
            args.images.len()
        );
    }
    Ok(())
}

fn detect_one(
    path: &Path,
    camera: &CameraModel,
    target: &Target,
    options: &PhotoOptions,
    overlay: Option<&Path>,
) -> Result<PhotoDetection> {
    let frame = roitrack::formats::read_frame(path)?;
    roitrack::formats::check_frame_size(&frame, camera, path)?;
    let found = detect_target(camera, target, &frame, options)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if let Some(dir) = overlay {
        let name = path
            .file_name()
            .map_or("image".into(), |n| n.to_string_lossy().into_owned());
        roitrack::formats::write_overlay_png(
            dir.join(format!("{name}.overlay.png")),
            &frame,
            &overlay_marks(&found, camera, target),
        )?;
    }
    Ok(found)
}

/// The overlay's marks: matched blobs with ids, the model projected, unmatched blobs.
fn overlay_marks(
    found: &PhotoDetection,
    camera: &CameraModel,
    target: &Target,
) -> Vec<OverlayMark> {
    let mut marks = Vec::new();
    let mut matched = vec![false; found.blobs.len()];
    for p in &found.points {
        matched[p.blob] = true;
        marks.push(OverlayMark {
            u_px: p.centre_px.x,
            v_px: p.centre_px.y,
            radius_px: found.blobs[p.blob].semi_major_px,
            label: Some(p.id.to_string()),
            kind: MarkKind::Detected,
        });
    }
    for (blob, _) in found.blobs.iter().zip(&matched).filter(|(_, m)| !**m) {
        marks.push(OverlayMark {
            u_px: blob.u_px,
            v_px: blob.v_px,
            radius_px: blob.semi_major_px,
            label: None,
            kind: MarkKind::Unmatched,
        });
    }
    for point in target.points() {
        let Some(px) =
            camera.raw_pixel_from_cam(&found.state.point_in_cam_at(&point.point_in_obj_m, 0.0))
        else {
            continue;
        };
        let seen = found.points.iter().any(|p| p.id == point.id);
        if camera.contains_raw_pixel(&px) {
            marks.push(OverlayMark {
                u_px: px.x,
                v_px: px.y,
                radius_px: 4.0,
                label: None,
                kind: if seen {
                    MarkKind::Reprojected
                } else {
                    MarkKind::Missing
                },
            });
        }
    }
    marks
}
