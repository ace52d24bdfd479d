//! Detection overlays: a frame as an RGB PNG with what was found in it drawn on top.
//!
//! [`write_overlay_png`] draws each [`OverlayMark`] by its [`MarkKind`]: a green circle and its id for a blob matched
//! to a target point, a small red `+` where the fitted pose projects a model point, a thin yellow circle for a blob
//! left unmatched and a magenta `x` where a target point should be seen but no blob was. Every mark has a dark halo
//! and every label a black box, so that both stay legible on dark and on bright parts of the image.

use std::path::Path;

use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use roitrack_image::Frame;

use crate::{AtomicFile, FormatError};

/// What a mark of an overlay shows, which decides how it is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MarkKind {
    /// A blob matched to a target point: a green circle of the mark's radius, with its label (the point's id).
    Detected,
    /// A model point projected with the fitted pose: a small red `+` (3 px arms), its centre at the projection.
    Reprojected,
    /// A candidate blob not matched to any target point: a thin yellow circle of the mark's radius.
    Unmatched,
    /// A target point predicted inside the image with no blob there: a magenta `x` of the mark's radius.
    Missing,
}

/// One mark of an overlay, in the frame's pixel coordinates (pixel `(i, j)` has its centre at `(u, v) = (i, j)`).
#[derive(Debug, Clone, PartialEq)]
pub struct OverlayMark {
    /// Column of the mark's centre (px).
    pub u_px: f64,
    /// Row of the mark's centre (px).
    pub v_px: f64,
    /// Radius of the circle, or half the size of the `x` of a missing point (px); at least 3 px are drawn.
    pub radius_px: f64,
    /// Text drawn beside the mark (digits, letters and `-.:?+/#_()=`; others are drawn as `?`), e.g. the point id.
    pub label: Option<String>,
    /// What the mark stands for (how it is drawn).
    pub kind: MarkKind,
}

type Rgb = [u8; 3];

const GREEN: Rgb = [0, 255, 0];
const RED: Rgb = [255, 32, 32];
const YELLOW: Rgb = [255, 230, 0];
const MAGENTA: Rgb = [255, 0, 255];
/// The halo around marks and the box behind labels.
const DARK: Rgb = [0, 0, 0];

/// Smallest circle radius and `x` half-size drawn (px), so that a mark on a tiny blob stays visible.
const MIN_MARK_RADIUS_PX: f64 = 3.0;
/// Half-length of the arms of a reprojection's `+` (px).
const CROSS_ARM_PX: i64 = 3;

/// Writes `frame` as an 8-bit RGB PNG at `path` with `marks` drawn on it, atomically (through [`AtomicFile`]: the
/// file appears complete or not at all).
///
/// The grey values are scaled from the frame's `bit_depth` to 8 bits (a 16-bit frame's 65535 becomes 255). Marks are
/// drawn in three passes (every mark's dark halo, then the marks, then the labels), so no halo hides another mark.
/// Labels are drawn with a built-in 5 x 7 pixel font, scaled up by an integer factor on large frames
/// (`1 + min(width, height) / 800`), in the mark's colour on a black box beside the mark, moved inside the image if
/// they would leave it. Marks with a non-finite position or radius are skipped; marks off the image are clipped (and
/// their labels not drawn).
///
/// Refuses, naming the file: a frame of zero width or height, one whose pixel count is not `width * height`, a
/// `bit_depth` outside 1 to 16, and the output's errors (missing directory, full disk, ...).
///
/// ```
/// use roitrack_formats::{MarkKind, OverlayMark, write_overlay_png};
/// use roitrack_image::Frame;
///
/// # fn main() -> Result<(), roitrack_formats::FormatError> {
/// let dir = tempfile::tempdir().unwrap();
/// let frame = Frame::new(64, 48, 8);
/// let marks = [
///     OverlayMark { u_px: 20.0, v_px: 24.0, radius_px: 6.0, label: Some("7".into()), kind: MarkKind::Detected },
///     OverlayMark { u_px: 20.3, v_px: 23.8, radius_px: 0.0, label: None, kind: MarkKind::Reprojected },
/// ];
/// write_overlay_png(dir.path().join("overlay.png"), &frame, &marks)?;
/// # Ok(())
/// # }
/// ```
pub fn write_overlay_png(
    path: impl AsRef<Path>,
    frame: &Frame,
    marks: &[OverlayMark],
) -> Result<(), FormatError> {
    let path = path.as_ref();
    let mut canvas = Canvas::from_frame(frame, path)?;
    let marks: Vec<&OverlayMark> = marks
        .iter()
        .filter(|m| m.u_px.is_finite() && m.v_px.is_finite() && m.radius_px.is_finite())
        .collect();
    for mark in &marks {
        canvas.draw_mark(mark, true);
    }
    for mark in &marks {
        canvas.draw_mark(mark, false);
    }
    let scale = 1 + frame.width.min(frame.height) as i64 / 800;
    for mark in &marks {
        if let Some(label) = &mark.label {
            canvas.draw_label(mark, label, scale);
        }
    }
    let mut file = AtomicFile::create(path)?;
    PngEncoder::new(&mut file)
        .write_image(
            &canvas.rgb,
            frame.width,
            frame.height,
            image::ColorType::Rgb8,
        )
        .map_err(|e| match e {
            image::ImageError::IoError(e) => file.write_error(e),
            other => FormatError::new(path, format!("cannot encode the PNG: {other}")),
        })?;
    file.finish()
}

/// An RGB image being drawn on; every write is clipped to it.
struct Canvas {
    width: i64,
    height: i64,
    rgb: Vec<u8>,
}

impl Canvas {
    /// The frame's grey values, scaled to 8 bits, in all three channels.
    fn from_frame(frame: &Frame, path: &Path) -> Result<Self, FormatError> {
        crate::image_file::check_frame_buffer(frame, path, "draw an overlay on")?;
        let (width, height) = (frame.width, frame.height);
        let max = (1u32 << frame.bit_depth) - 1;
        let rgb = frame
            .pixels
            .iter()
            .flat_map(|&v| {
                // Rounded, and saturated for values above the bit depth.
                let grey = ((u32::from(v).min(max) * 255 + max / 2) / max) as u8;
                [grey; 3]
            })
            .collect();
        Ok(Self {
            width: i64::from(width),
            height: i64::from(height),
            rgb,
        })
    }

    fn put(&mut self, i: i64, j: i64, colour: Rgb) {
        if (0..self.width).contains(&i) && (0..self.height).contains(&j) {
            let at = 3 * (j * self.width + i) as usize;
            self.rgb[at..at + 3].copy_from_slice(&colour);
        }
    }

    /// The pixels whose centres lie within `half_width` of the circle of radius `r` about `(u, v)`.
    fn ring(&mut self, u: f64, v: f64, r: f64, half_width: f64, colour: Rgb) {
        let outer = r + half_width;
        let (i0, i1) = self.clipped(u - outer, u + outer, self.width);
        let (j0, j1) = self.clipped(v - outer, v + outer, self.height);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let d = (i as f64 - u).hypot(j as f64 - v);
                if (d - r).abs() <= half_width {
                    self.put(i, j, colour);
                }
            }
        }
    }

    /// The pixel range `[lo, hi]` (rounded) clipped to `0..size` (empty, lo > hi, if it misses the image).
    fn clipped(&self, lo: f64, hi: f64, size: i64) -> (i64, i64) {
        let lo = lo.round().max(0.0);
        let hi = hi.round().min((size - 1) as f64);
        // Both finite (the marks are) and within the image, or lo > hi.
        (lo as i64, hi as i64)
    }

    /// A `+` (`diagonal` false) or an `x` (true) of arm length `arm` about the pixel nearest `(u, v)`, thickened by
    /// `grow` pixels on every side.
    fn cross(&mut self, u: f64, v: f64, arm: i64, diagonal: bool, grow: i64, colour: Rgb) {
        // The centre pixel, clamped far outside the image so that the arithmetic cannot overflow.
        let limit = 4 * (self.width + self.height + arm);
        let ci = (u.round() as i64).clamp(-limit, limit);
        let cj = (v.round() as i64).clamp(-limit, limit);
        for k in -arm..=arm {
            let (a, b) = if diagonal {
                ((k, k), (k, -k))
            } else {
                ((k, 0), (0, k))
            };
            for (di, dj) in [a, b] {
                for gj in -grow..=grow {
                    for gi in -grow..=grow {
                        self.put(ci + di + gi, cj + dj + gj, colour);
                    }
                }
            }
        }
    }

    /// The mark, or only its dark halo.
    fn draw_mark(&mut self, mark: &OverlayMark, halo: bool) {
        let (u, v) = (mark.u_px, mark.v_px);
        let r = mark.radius_px.max(MIN_MARK_RADIUS_PX);
        match (mark.kind, halo) {
            (MarkKind::Detected, false) => self.ring(u, v, r, 0.75, GREEN),
            (MarkKind::Detected, true) => self.ring(u, v, r, 1.75, DARK),
            (MarkKind::Unmatched, false) => self.ring(u, v, r, 0.5, YELLOW),
            (MarkKind::Unmatched, true) => self.ring(u, v, r, 1.5, DARK),
            (MarkKind::Reprojected, halo) => {
                let (grow, colour) = if halo { (1, DARK) } else { (0, RED) };
                self.cross(u, v, CROSS_ARM_PX, false, grow, colour);
            }
            (MarkKind::Missing, halo) => {
                let arm = (r / std::f64::consts::SQRT_2).round() as i64;
                let (grow, colour) = if halo { (1, DARK) } else { (0, MAGENTA) };
                self.cross(u, v, arm.min(self.width + self.height), true, grow, colour);
            }
        }
    }

    /// The label on a black box, to the upper right of the mark (on the image), moved inside the image if need be.
    fn draw_label(&mut self, mark: &OverlayMark, label: &str, scale: i64) {
        let colour = match mark.kind {
            MarkKind::Detected => GREEN,
            MarkKind::Reprojected => RED,
            MarkKind::Unmatched => YELLOW,
            MarkKind::Missing => MAGENTA,
        };
        // A label is for a mark on the image: one off it would otherwise be moved in, away from what it names.
        let on_image = |x: f64, size: i64| (-0.5..size as f64 - 0.5).contains(&x);
        let chars: Vec<char> = label.chars().take(64).collect();
        if chars.is_empty() || !on_image(mark.u_px, self.width) || !on_image(mark.v_px, self.height)
        {
            return;
        }
        let n = chars.len() as i64;
        // One pixel of box around the text and between the characters (all scaled).
        let box_w = (6 * n + 1) * scale;
        let box_h = 9 * scale;
        let r = mark.radius_px.max(MIN_MARK_RADIUS_PX) * std::f64::consts::FRAC_1_SQRT_2 + 2.0;
        let x = (mark.u_px + r)
            .round()
            .clamp(0.0, (self.width - box_w).max(0) as f64) as i64;
        let y = (mark.v_px - r).round() - box_h as f64;
        let y = y.clamp(0.0, (self.height - box_h).max(0) as f64) as i64;
        for j in y..y + box_h {
            for i in x..x + box_w {
                self.put(i, j, DARK);
            }
        }
        for (k, c) in chars.iter().enumerate() {
            let rows = glyph(*c);
            let left = x + (1 + 6 * k as i64) * scale;
            for (row, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0b10000 >> col) != 0 {
                        let (i, j) = (left + col * scale, y + (1 + row as i64) * scale);
                        for dj in 0..scale {
                            for di in 0..scale {
                                self.put(i + di, j + dj, colour);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// The 5 x 7 bitmap of a character: seven rows, top first, the five low bits of each the columns (left = 0b10000).
///
/// A built-in font rather than a system one: labels must look the same on every machine, including those with no
/// fonts installed, and ids are digits and a few letters, which 5 x 7 pixels render legibly at any image size (the
/// caller scales them up on large frames). The embedded TrueType font of `roitrack-plot` is out of reach here
/// (formats may not depend on plot) and would need anti-aliased text rendering, for no gain on short labels.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        ' ' => [0; 7],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '#' => [0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04], // '?'
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mark(u: f64, v: f64, r: f64, label: Option<&str>, kind: MarkKind) -> OverlayMark {
        OverlayMark {
            u_px: u,
            v_px: v,
            radius_px: r,
            label: label.map(str::to_owned),
            kind,
        }
    }

    /// A frame with a dark left half and a bright right half (16 bits).
    fn half_bright_frame() -> Frame {
        let mut frame = Frame::new(120, 80, 16);
        for j in 0..80 {
            for i in 60..120 {
                let k = frame.index(i, j);
                frame.pixels[k] = 60000;
            }
        }
        frame
    }

    fn read_back(path: &Path) -> image::RgbImage {
        image::open(path).unwrap().into_rgb8()
    }

    #[test]
    fn overlay_reads_back_with_the_marks_drawn() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("overlay.png");
        let frame = half_bright_frame();
        let marks = [
            mark(30.0, 40.0, 8.0, Some("12"), MarkKind::Detected),
            mark(90.0, 40.0, 8.0, Some("35"), MarkKind::Detected),
            mark(30.4, 39.7, 0.0, None, MarkKind::Reprojected),
            mark(60.0, 15.0, 5.0, None, MarkKind::Unmatched),
            mark(100.0, 70.0, 5.0, Some("7"), MarkKind::Missing),
            mark(f64::NAN, 1.0, 3.0, Some("skipped"), MarkKind::Detected),
            mark(1e12, -1e12, 1e9, Some("far"), MarkKind::Missing),
        ];
        write_overlay_png(&path, &frame, &marks).unwrap();
        let image = read_back(&path);
        assert_eq!(image.dimensions(), (120, 80));
        // Grey scaled from 16 to 8 bits away from the marks.
        assert_eq!(image.get_pixel(5, 75).0, [0, 0, 0]);
        assert_eq!(image.get_pixel(115, 75).0, [233, 233, 233]); // 60000 / 65535 * 255 = 233.4
        // The detected marks' circles are green, on the dark and on the bright side: (30 + 8, 40), (90 - 8, 40).
        assert_eq!(image.get_pixel(38, 40).0, GREEN);
        assert_eq!(image.get_pixel(82, 40).0, GREEN);
        // ... with a dark halo outside the circle on the bright side, the image beyond it.
        assert_eq!(image.get_pixel(81, 40).0, DARK);
        assert_eq!(image.get_pixel(79, 40).0, [233, 233, 233]);
        // The reprojection's + at pixel (30, 40), the unmatched blob's yellow circle, the missing point's x.
        assert_eq!(image.get_pixel(30, 40).0, RED);
        assert_eq!(image.get_pixel(33, 40).0, RED);
        assert_eq!(image.get_pixel(60, 20).0, YELLOW);
        assert_eq!(image.get_pixel(100, 70).0, MAGENTA);
        assert_eq!(image.get_pixel(103, 73).0, MAGENTA);
        // The labels: green text on black boxes up and right of the circles.
        let green_in = |x0: u32, x1: u32, y0: u32, y1: u32| {
            (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|&(x, y)| image.get_pixel(x, y).0 == GREEN)
                .count()
        };
        let label_box = |u: f64, v: f64| {
            let r = 8.0 * std::f64::consts::FRAC_1_SQRT_2 + 2.0;
            let (x, y) = ((u + r).round() as u32, (v - r).round() as u32 - 9);
            (x, y)
        };
        for (u, v) in [(30.0, 40.0), (90.0, 40.0)] {
            let (x, y) = label_box(u, v);
            assert_eq!(image.get_pixel(x, y).0, DARK);
            assert!(green_in(x, x + 13, y, y + 9) > 10, "label at ({x}, {y})");
        }
        // Nothing of the mark with no position was drawn, no temporary file is left.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn labels_near_the_edge_stay_inside_and_large_frames_get_larger_text() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("edge.png");
        let frame = Frame::new(1600, 1600, 8);
        let marks = [mark(1599.0, 0.0, 4.0, Some("99"), MarkKind::Detected)];
        write_overlay_png(&path, &frame, &marks).unwrap();
        let image = read_back(&path);
        // Scale 3: a box of (6 * 2 + 1) * 3 = 39 x 27 px in the top right corner, with green text in it.
        let green = (0..27)
            .flat_map(|y| (1600 - 39..1600).map(move |x| (x, y)))
            .filter(|&(x, y)| image.get_pixel(x, y).0 == GREEN)
            .count();
        assert!(green >= 2 * 9 * 9, "{green}");
        assert_eq!(image.get_pixel(1599 - 38, 26).0, DARK);
    }

    #[test]
    fn bad_frames_and_paths_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.png");
        let mut frame = Frame::new(4, 4, 8);
        frame.pixels.pop();
        let e = write_overlay_png(&path, &frame, &[]).unwrap_err();
        assert!(
            e.to_string().starts_with(&path.display().to_string()),
            "{e}"
        );
        assert!(
            write_overlay_png(&path, &Frame::new(0, 4, 8), &[])
                .unwrap_err()
                .to_string()
                .contains("empty frame")
        );
        assert!(write_overlay_png(&path, &Frame::new(4, 4, 17), &[]).is_err());
        assert!(!path.exists());
        let missing = dir.path().join("no-such-dir").join("o.png");
        let e = write_overlay_png(&missing, &Frame::new(4, 4, 8), &[]).unwrap_err();
        assert!(e.to_string().contains("o.png"), "{e}");
    }

    #[test]
    fn the_font_has_distinct_glyphs() {
        let chars = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ -.:+/#_()=?";
        let glyphs: Vec<[u8; 7]> = chars.chars().map(glyph).collect();
        for (a, ga) in chars.chars().zip(&glyphs) {
            assert!(ga.iter().all(|row| row >> 5 == 0), "{a}");
            for (b, gb) in chars.chars().zip(&glyphs) {
                assert!(a == b || ga != gb, "{a} and {b}");
            }
        }
        assert_eq!(glyph('a'), glyph('A'));
        assert_eq!(glyph('~'), glyph('?'));
    }
}
