//! `roitrack detect`: find, identify and measure the target in photographs (see [`roitrack::detect::photo`]).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use roitrack::detect::{PhotoDetection, PhotoError, PhotoOptions, PolarityChoice, detect_target};
use roitrack::formats::{MarkKind, OverlayMark};
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
/// Exits with status 1 if any image failed, each failure's reason printed (with --json, also on standard error): a
/// file that could not be read or decoded, an image not of the camera's size, the target not found.
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
    #[arg(long, num_args = 2, value_names = ["NEAR_M", "FAR_M"], value_parser = crate::ranges::positive_up_to(1e3, " m", "a target seen from a kilometre is a pixel"))]
    pub distance_m: Option<Vec<f64>>,
    /// Write per image a PNG (`<image name>.overlay.png`) with the matched blobs and their ids (green), the model
    /// projected with the pose (red +), unmatched blobs (yellow) and points expected but not found (magenta x), into
    /// this folder. Where the target is not found, the overlay shows what was seen: every candidate blob (yellow, of
    /// both polarities with `--polarity auto`). An image that could not be read, decoded or is not of the camera's
    /// size gets none. The report names each overlay written. Default: no overlay.
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// One JSON object per image on its own line of stdout, instead of a table. Fields: image, ok, failure and error
    /// (when not ok: failure is read, decode, size, not_found or overlay; error says why, naming the file), polarity,
    /// ambiguous, points [{id, u_px, v_px}] (raw distorted pixels), cam_t_obj_m [x, y, z], cam_q_obj_xyzw
    /// [x, y, z, w] (x_cam = R x_obj + t), residual_rms_px (sqrt of the mean squared reprojection distance), missing,
    /// blobs, time_ms; with --overlay, overlay (the file written, or null).
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
        check_overlay_paths(args, dir)?;
        roitrack::formats::create_output_dir(dir)?;
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
    let mut failures = Vec::new();
    for path in &args.images {
        // A signal stops the run here, through the error path: no overlay is written (src/signals.rs).
        crate::signals::check(path)?;
        let started = Instant::now();
        let outcome = detect_one(path, &camera, &target, &options, args.overlay.as_deref());
        let time_ms = started.elapsed().as_secs_f64() * 1e3;
        let name = path.display().to_string();
        let overlay = outcome.overlay.as_ref().map(|o| o.display().to_string());
        // Said at the end of the table's result column.
        let overlay_note = overlay
            .as_ref()
            .map_or(String::new(), |o| format!("; overlay {o}"));
        match outcome.result {
            Ok(found) => {
                let q = found.cam_q_obj();
                let t = found.state.cam_t_obj_m;
                if args.json {
                    let points: Vec<_> = found
                        .points
                        .iter()
                        .map(|p| json!({"id": p.id, "u_px": p.centre_px.x, "v_px": p.centre_px.y}))
                        .collect();
                    let mut line = json!({
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
                    if args.overlay.is_some() {
                        line["overlay"] = json!(overlay);
                    }
                    writeln!(out, "{line}")?;
                } else {
                    writeln!(
                        out,
                        "{:<32} {:>6} {:>7} {:>9} {:>8.3} {:>9.2}  {}{overlay_note}",
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
            Err((failure, error)) => {
                failures.push(failure);
                if args.json {
                    let mut line = json!({
                        "image": name,
                        "ok": false,
                        "failure": failure.name(),
                        "error": error,
                        "time_ms": time_ms,
                    });
                    if args.overlay.is_some() {
                        line["overlay"] = json!(overlay);
                    }
                    writeln!(out, "{line}")?;
                    // Standard output may go to a file: each failure is said where the user sees it too.
                    eprintln!("roitrack: {error}");
                } else {
                    writeln!(
                        out,
                        "{name:<32} {:>6} {:>7} {:>9} {:>8} {time_ms:>9.2}  FAILED: {error}{overlay_note}",
                        "-", "-", "-", "-"
                    )?;
                }
            }
        }
    }
    out.flush()?;
    if !failures.is_empty() {
        // The other images' overlays stand.
        return Err(crate::OutputsStand(failures_summary(&failures, args.images.len())).into());
    }
    Ok(())
}

/// Why an image gave no detection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Failure {
    /// The file could not be read.
    Read,
    /// The file was read but could not be decoded as an image (truncated, corrupt, not an image).
    Decode,
    /// The image is not of the camera's size.
    Size,
    /// The image was looked at and the target was not found in it.
    NotFound,
    /// The target was found, but its overlay could not be written.
    Overlay,
}

impl Failure {
    /// The `failure` field of the JSON output.
    fn name(self) -> &'static str {
        match self {
            Self::Read => "read",
            Self::Decode => "decode",
            Self::Size => "size",
            Self::NotFound => "not_found",
            Self::Overlay => "overlay",
        }
    }
}

/// The error of the run: how many images failed, and why (the target not found is not said of an image that could
/// not be read).
/// The overlay each image gets (`DIR/<image name>.overlay.png`): refused, before anything is read or written, where
/// one is an input (an image, the camera, the target; also through links) or two images would share one.
fn check_overlay_paths(args: &DetectArgs, dir: &Path) -> Result<()> {
    let named: Vec<(String, &Path)> = args
        .images
        .iter()
        .map(|p| (format!("image {}", p.display()), p.as_path()))
        .collect();
    let mut inputs: Vec<(&str, &Path)> = vec![
        ("--camera", args.camera.camera.as_path()),
        ("--target", args.target.target.as_path()),
    ];
    inputs.extend(named.iter().map(|(n, p)| (n.as_str(), *p)));
    let overlays: Vec<(String, PathBuf)> = args
        .images
        .iter()
        .map(|p| {
            let name = p
                .file_name()
                .map_or("image".into(), |n| n.to_string_lossy().into_owned());
            (
                format!("the overlay of {}", p.display()),
                dir.join(format!("{name}.overlay.png")),
            )
        })
        .collect();
    let outputs: Vec<(&str, &Path)> = overlays
        .iter()
        .map(|(n, p)| (n.as_str(), p.as_path()))
        .collect();
    Ok(roitrack::formats::check_output_paths(&inputs, &outputs)?)
}

fn failures_summary(failures: &[Failure], images: usize) -> String {
    let count = |kind: Failure| failures.iter().filter(|&&f| f == kind).count();
    let not_found = count(Failure::NotFound);
    if not_found == failures.len() {
        return format!("the target was not found in {not_found} of {images} images");
    }
    let parts: Vec<String> = [
        (Failure::Read, "could not be read"),
        (Failure::Decode, "could not be decoded"),
        (Failure::Size, "not of the camera's size"),
    ]
    .into_iter()
    .filter(|&(kind, _)| count(kind) > 0)
    .map(|(kind, what)| format!("{} {what}", count(kind)))
    .chain((not_found > 0).then(|| format!("the target not found in {not_found}")))
    .chain(
        (count(Failure::Overlay) > 0)
            .then(|| format!("the overlay not written for {}", count(Failure::Overlay))),
    )
    .collect();
    format!(
        "{} of {images} images failed: {}",
        failures.len(),
        parts.join(", ")
    )
}

/// What became of one image: the detection or why there is none, and the overlay written, if any.
struct Outcome {
    result: std::result::Result<PhotoDetection, (Failure, String)>,
    overlay: Option<PathBuf>,
}

fn detect_one(
    path: &Path,
    camera: &CameraModel,
    target: &Target,
    options: &PhotoOptions,
    overlay_dir: Option<&Path>,
) -> Outcome {
    // Nothing to draw on when the image is not read, decoded and of the camera's size.
    let no_overlay = if overlay_dir.is_some() {
        "; no overlay written"
    } else {
        ""
    };
    let refused = |failure: Failure, error: String| Outcome {
        result: Err((failure, format!("{error}{no_overlay}"))),
        overlay: None,
    };
    let frame = match roitrack::formats::read_frame(path) {
        Ok(frame) => frame,
        Err(e) if e.io_error().is_some() => return refused(Failure::Read, e.to_string()),
        Err(e) => {
            return refused(
                Failure::Decode,
                format!("{}: could not be decoded: {}", path.display(), e.message()),
            );
        }
    };
    if let Err(e) = roitrack::formats::check_frame_size(&frame, camera, path) {
        return refused(Failure::Size, e.to_string());
    }
    let result = detect_target(camera, target, &frame, options);
    let Some(dir) = overlay_dir else {
        return Outcome {
            result: result.map_err(|e| (Failure::NotFound, format!("{}: {e}", path.display()))),
            overlay: None,
        };
    };
    let name = path
        .file_name()
        .map_or("image".into(), |n| n.to_string_lossy().into_owned());
    let overlay = dir.join(format!("{name}.overlay.png"));
    let marks = match &result {
        Ok(found) => found_marks(found, camera, target),
        Err(e) => seen_marks(e),
    };
    let written = roitrack::formats::write_overlay_png(&overlay, &frame, &marks);
    match (result, written) {
        (Ok(found), Ok(())) => Outcome {
            result: Ok(found),
            overlay: Some(overlay),
        },
        (Ok(_), Err(e)) => Outcome {
            result: Err((
                Failure::Overlay,
                format!(
                    "{}: found, but the overlay was not written: {e}",
                    path.display()
                ),
            )),
            overlay: None,
        },
        (Err(e), Ok(())) => Outcome {
            result: Err((Failure::NotFound, format!("{}: {e}", path.display()))),
            overlay: Some(overlay),
        },
        (Err(e), Err(write)) => Outcome {
            result: Err((
                Failure::NotFound,
                format!(
                    "{}: {e}; the overlay was not written: {write}",
                    path.display()
                ),
            )),
            overlay: None,
        },
    }
}

/// The overlay of an image where the target was not found: every candidate blob looked at, unmatched. (The
/// identification keeps no rejected hypothesis to draw.)
fn seen_marks(error: &PhotoError) -> Vec<OverlayMark> {
    error
        .blobs_seen()
        .map(|blob| OverlayMark {
            u_px: blob.u_px,
            v_px: blob.v_px,
            radius_px: blob.semi_major_px,
            label: None,
            kind: MarkKind::Unmatched,
        })
        .collect()
}

/// The overlay of an image where the target was found: matched blobs with ids, the model projected, unmatched blobs.
fn found_marks(found: &PhotoDetection, camera: &CameraModel, target: &Target) -> Vec<OverlayMark> {
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
