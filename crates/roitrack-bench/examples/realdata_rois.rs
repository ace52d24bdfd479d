//! The per-ROI centroid on real blobs: cuts a window around every circle that `detect` identifies in real photographs,
//! sized as the tracker sizes one around a predicted blob (the blob, the blur margin and four times the smallest
//! prediction spread: 7 px a side with the scheduler's defaults; 12 to 64 px), flattens it as the frame tracker does
//! ([`flatten_window`]: the background's plane through its border taken away, or for dark circles divided out) and measures it as
//! the tracker measures an ROI ([`measure_blob`] with the default options, shape check on). Prints per set what it
//! accepted and rejected (`--verbose`: every rejection other than the shape check's, such as a window that cuts a
//! neighbour in a dense grid, which the tracker would size the same) and the distances between the accepted centroids
//! and the outline centres `detect` measured (median, 90th and 99th percentiles, largest). Exits 1 when the shape check
//! rejected more than `--max-asymmetric N` blobs (default 0): these are clean blobs as a real camera gives them.
//!
//! ```text
//! cargo run --release -p roitrack-bench --example realdata_rois -- REALDATA_DIR [--verbose] [--max-asymmetric N]
//! ```
//!
//! The folder holds `sets.json` (`{"sets": [names]}` or `{"sets": [{"name": ...}]}`), and per set
//! `cameras/NAME.yaml`, `targets/NAME.csv` and the photographs in `images/NAME/` (`scripts/realdata` runs this).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use roitrack_detect::photo::{PhotoDetection, PhotoOptions, detect_target};
use roitrack_image::{BlobRejection, CentroidOptions, Frame, Roi};
use roitrack_pipeline::frames::{FlatWindow, flatten_window, measure_flat_window};
use roitrack_pipeline::scheduler::SchedulerConfig;

#[derive(Debug, Default)]
struct Counts {
    asymmetric: usize,
    other: usize,
    /// Per accepted blob: the distance between the ROI centroid and the detection's outline centre (px).
    offsets_px: Vec<f64>,
}

/// An identified circle's window.
struct BlobWindow {
    id: u32,
    roi: Roi,
    /// The window's pixels, the blob bright, and what flattening them found.
    pixels: Vec<u16>,
    flat: FlatWindow,
    /// The centre `detect` measured from the blob's outline (px).
    outline_centre: (f64, f64),
}

/// The windows of one photograph's identified circles.
fn rois(frame: &Frame, found: &PhotoDetection) -> Vec<BlobWindow> {
    let windows = SchedulerConfig::default();
    let mut out = Vec::new();
    for point in &found.points {
        let blob = &found.blobs[point.blob];
        // As the tracker sizes a window around a predicted blob: the blob, the blur margin, and the prediction's
        // spread at its smallest (the scheduler's defaults).
        let half = blob.semi_major_px
            + windows.blur_margin_px
            + windows.sigma_margin * windows.min_sigma_px;
        let side = (2.0 * half.ceil() + 1.0).clamp(
            f64::from(windows.min_size_px),
            f64::from(windows.max_size_px),
        ) as u32;
        let x0 = blob.u_px.round() as i64 - i64::from(side / 2);
        let y0 = blob.v_px.round() as i64 - i64::from(side / 2);
        if x0 < 0
            || y0 < 0
            || x0 + i64::from(side) > i64::from(frame.width)
            || y0 + i64::from(side) > i64::from(frame.height)
        {
            continue;
        }
        let (x0, y0) = (x0 as u32, y0 as u32);
        let roi = Roi::new(x0, y0, side, side);
        let mut pixels = Vec::with_capacity(roi.len());
        let flat = flatten_window(frame, &roi, found.polarity, &mut pixels);
        out.push(BlobWindow {
            id: point.id,
            roi,
            pixels,
            flat,
            outline_centre: (blob.u_px, blob.v_px),
        });
    }
    out
}

fn set_names(data: &Path) -> Result<Vec<String>, String> {
    let text = std::fs::read_to_string(data.join("sets.json"))
        .map_err(|e| format!("{}: {e}", data.join("sets.json").display()))?;
    let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    let sets = json["sets"]
        .as_array()
        .ok_or("sets.json: no list \"sets\"")?;
    Ok(sets
        .iter()
        .filter_map(|s| s.as_str().or_else(|| s["name"].as_str()))
        .map(str::to_owned)
        .collect())
}

fn run(data: &Path, verbose: bool) -> Result<usize, String> {
    let mut rejected = 0;
    println!(
        "{:<26} {:>7} {:>9} {:>10} {:>6} {:>12}",
        "set", "photos", "accepted", "asymmetric", "other", "worst off px"
    );
    for set in set_names(data)? {
        let camera = roitrack_formats::read_camera_yaml(data.join(format!("cameras/{set}.yaml")))
            .map_err(|e| e.to_string())?;
        let target = roitrack_formats::read_target_csv(data.join(format!("targets/{set}.csv")))
            .map_err(|e| e.to_string())?;
        let mut photos: Vec<PathBuf> = std::fs::read_dir(data.join("images").join(&set))
            .map_err(|e| format!("{set}: {e}"))?
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .collect();
        photos.sort();
        let mut counts = Counts::default();
        for photo in &photos {
            let frame = roitrack_formats::read_frame(photo).map_err(|e| e.to_string())?;
            let Ok(found) = detect_target(&camera, &target, &frame, &PhotoOptions::default())
            else {
                continue;
            };
            for BlobWindow {
                id,
                roi,
                pixels,
                flat,
                outline_centre,
            } in rois(&frame, &found)
            {
                match measure_flat_window(&pixels, &roi, &flat, &CentroidOptions::default(), None) {
                    Ok(c) => counts
                        .offsets_px
                        .push((c.u_px - outline_centre.0).hypot(c.v_px - outline_centre.1)),
                    Err(BlobRejection::Asymmetric) => {
                        counts.asymmetric += 1;
                        println!("  asymmetric: {} point {id}", photo.display());
                    }
                    Err(why) => {
                        counts.other += 1;
                        if verbose {
                            println!("  {why}: {} point {id}", photo.display());
                        }
                    }
                }
            }
        }
        let mut o = counts.offsets_px;
        o.sort_by(f64::total_cmp);
        println!(
            "{set:<26} {:>7} {:>9} {:>10} {:>6} {:>12.3}",
            photos.len(),
            o.len(),
            counts.asymmetric,
            counts.other,
            o.last().copied().unwrap_or(0.0)
        );
        rejected += counts.asymmetric;
        let q = |f: f64| {
            o.get(((o.len() as f64 - 1.0) * f) as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        println!(
            "{:<26} offsets from the outline centres (px): median {:.3}, 90 % {:.3}, 99 % {:.3}",
            "",
            q(0.5),
            q(0.9),
            q(0.99)
        );
    }
    Ok(rejected)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let verbose = args.iter().any(|a| a == "--verbose");
    let mut max_asymmetric = 0;
    let mut data = PathBuf::from("../shared/realdata");
    let mut rest = args.iter();
    while let Some(arg) = rest.next() {
        match arg.as_str() {
            "--verbose" => {}
            "--max-asymmetric" => match rest.next().and_then(|n| n.parse().ok()) {
                Some(n) => max_asymmetric = n,
                None => {
                    eprintln!("realdata_rois: --max-asymmetric needs a count");
                    return ExitCode::FAILURE;
                }
            },
            other => data = PathBuf::from(other),
        }
    }
    match run(&data, verbose) {
        Ok(n) if n <= max_asymmetric => {
            println!(
                "realdata_rois: the shape check rejected {n} real blob(s), at most {max_asymmetric} allowed"
            );
            ExitCode::SUCCESS
        }
        Ok(n) => {
            println!(
                "realdata_rois: the shape check rejected {n} real blob(s), more than the {max_asymmetric} allowed"
            );
            ExitCode::FAILURE
        }
        Err(e) => {
            eprintln!("realdata_rois: {e}");
            ExitCode::FAILURE
        }
    }
}
