//! Random clutter: disks, ellipses, strokes, rectangles and text-like marks around the board, and the printed marks
//! in the paper's margin ([`Clutter`]).

use nalgebra::Vector2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::PhotoError;
use super::board::PlaneShape;
use super::light::segment_distance2;
use super::rays::Area;
use super::scene::{PhotoScene, check};
use super::{CLUTTER_STREAM, MARKS_STREAM};

/// Largest number of clutter items and board marks.
const MAX_CLUTTER: usize = 100_000;

/// Distractors: random shapes on the background, and optionally printed marks on the board's margin.
///
/// ```
/// use roitrack_sim::photo::Clutter;
/// let clutter = Clutter { board_marks: 4, ..Clutter::busy(50) };
/// assert_eq!(clutter.count, 50);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clutter {
    /// Random items drawn on the background (dark, bright and grey disks, ellipses, strokes, rectangles, lines of
    /// text-like marks), uniformly over the image. The board hides those behind it.
    pub count: usize,
    /// If set, every item keeps at least this far (px, bounding boxes) from the board's image; if not, items may
    /// touch the board's edge (and be partly hidden by it). Items that find no room in 20 tries are left out.
    pub clearance_px: Option<f64>,
    /// Printed marks on the paper (text-like lines of strokes and dots, in the circles' ink), in the margin between
    /// the circles and the board's edge. Marks that find no room in 50 tries are left out (a narrow margin holds none).
    pub board_marks: usize,
    /// Smallest distance (m) from a board mark to the bounding box of the circles.
    pub board_mark_gap_m: f64,
}

impl Default for Clutter {
    /// No clutter (marks, if asked for, 4 mm from the circles).
    fn default() -> Self {
        Self {
            count: 0,
            clearance_px: None,
            board_marks: 0,
            board_mark_gap_m: 0.004,
        }
    }
}

impl Clutter {
    /// `count` background items, allowed to touch the board; no board marks.
    pub fn busy(count: usize) -> Self {
        Self {
            count,
            ..Self::default()
        }
    }
}

impl Clutter {
    /// At most 100,000 items and marks, clearances and gaps of 0 or more.
    pub(super) fn check(&self) -> Result<(), PhotoError> {
        for (field, n) in [
            ("clutter count", self.count),
            ("clutter board_marks", self.board_marks),
        ] {
            check(field, n as f64, n <= MAX_CLUTTER, "at most 100000")?;
        }
        if let Some(c) = self.clearance_px {
            check(
                "clutter clearance_px",
                c,
                (0.0..1e9).contains(&c),
                "0 or more",
            )?;
        }
        let gap = self.board_mark_gap_m;
        check(
            "clutter board_mark_gap_m",
            gap,
            (0.0..1e6).contains(&gap),
            "0 or more",
        )?;
        Ok(())
    }
}

/// Adds the printed marks of `scene.clutter` to `shapes`: in the board `(lo, hi)`, off the circles' bounding box
/// expanded by the gap.
pub(super) fn board_marks(
    scene: &PhotoScene,
    circles: (Vector2<f64>, Vector2<f64>),
    board: (Vector2<f64>, Vector2<f64>),
    shapes: &mut Vec<PlaneShape>,
) {
    let count = scene.clutter.board_marks;
    if count == 0 {
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed);
    rng.set_stream(MARKS_STREAM);
    let gap = Vector2::repeat(scene.clutter.board_mark_gap_m);
    let (keep_lo, keep_hi) = (circles.0 - gap, circles.1 + gap);
    let level = scene.circle_level;
    for _ in 0..count {
        for _ in 0..50 {
            let glyph = rng.random_range(0.002..0.005);
            let text = rng.random_bool(0.6);
            let chars = rng.random_range(2..7usize);
            let size = if text {
                Vector2::new(chars as f64 * 0.8 * glyph, glyph)
            } else {
                Vector2::repeat(glyph)
            };
            let inset = Vector2::repeat(0.5 * glyph);
            let room = board.1 - board.0 - size - 2.0 * inset;
            if room.x <= 0.0 || room.y <= 0.0 {
                break;
            }
            let lo = board.0
                + inset
                + Vector2::new(rng.random::<f64>() * room.x, rng.random::<f64>() * room.y);
            let hi = lo + size;
            if lo.x < keep_hi.x && hi.x > keep_lo.x && lo.y < keep_hi.y && hi.y > keep_lo.y {
                continue;
            }
            if !text {
                shapes.push(PlaneShape::Disk {
                    centre: lo + 0.5 * size,
                    radius: 0.5 * glyph,
                    level,
                });
                break;
            }
            let stroke = 0.15 * glyph;
            let width = 0.6 * glyph;
            for c in 0..chars {
                let x = lo.x + c as f64 * 0.8 * glyph;
                let mut drawn = false;
                for kind in 0..6 {
                    if !(rng.random_bool(0.4) || (kind == 5 && !drawn)) {
                        continue;
                    }
                    drawn = true;
                    let (a, b) = match kind {
                        // Vertical strokes: left, middle, right.
                        0..=2 => {
                            let sx = x + kind as f64 * 0.5 * (width - stroke);
                            (Vector2::new(sx, lo.y), Vector2::new(sx + stroke, hi.y))
                        }
                        // Horizontal strokes: top, middle, bottom.
                        _ => {
                            let sy = lo.y + (kind - 3) as f64 * 0.5 * (glyph - stroke);
                            (Vector2::new(x, sy), Vector2::new(x + width, sy + stroke))
                        }
                    };
                    shapes.push(PlaneShape::Rect {
                        lo: a,
                        hi: b,
                        level,
                    });
                }
            }
            break;
        }
    }
}

/// An item of background clutter, in raw pixels.
#[derive(Debug, Clone, Copy)]
enum Stamp {
    Ellipse {
        centre: Vector2<f64>,
        semi_axes: Vector2<f64>,
        /// (cos, sin) of the angle of the first axis.
        rotation: Vector2<f64>,
        level: f64,
    },
    Segment {
        a: Vector2<f64>,
        b: Vector2<f64>,
        half_width: f64,
        level: f64,
    },
    Box {
        centre: Vector2<f64>,
        half_size: Vector2<f64>,
        /// (cos, sin) of the angle of the first side.
        rotation: Vector2<f64>,
        level: f64,
    },
}

impl Stamp {
    pub(super) fn level(&self) -> f64 {
        match *self {
            Self::Ellipse { level, .. } | Self::Segment { level, .. } | Self::Box { level, .. } => {
                level
            }
        }
    }

    /// Bounding box (lo, hi), raw pixels.
    pub(super) fn bounds(&self) -> (Vector2<f64>, Vector2<f64>) {
        match *self {
            Self::Ellipse {
                centre, semi_axes, ..
            } => {
                let r = Vector2::repeat(semi_axes.max());
                (centre - r, centre + r)
            }
            Self::Segment {
                a, b, half_width, ..
            } => {
                let r = Vector2::repeat(half_width);
                (a.inf(&b) - r, a.sup(&b) + r)
            }
            Self::Box {
                centre, half_size, ..
            } => {
                let r = Vector2::repeat(half_size.norm());
                (centre - r, centre + r)
            }
        }
    }

    /// Signed distance (approximate for ellipses) from `p` to the shape's edge, negative inside.
    fn distance(&self, p: Vector2<f64>) -> f64 {
        let local = |centre: Vector2<f64>, rotation: Vector2<f64>| {
            let (c, s) = (rotation.x, rotation.y);
            let d = p - centre;
            Vector2::new(c * d.x + s * d.y, -s * d.x + c * d.y)
        };
        match *self {
            Self::Ellipse {
                centre,
                semi_axes,
                rotation,
                ..
            } => {
                let q = local(centre, rotation);
                let k0 = Vector2::new(q.x / semi_axes.x, q.y / semi_axes.y).norm();
                let k1 = Vector2::new(
                    q.x / (semi_axes.x * semi_axes.x),
                    q.y / (semi_axes.y * semi_axes.y),
                )
                .norm();
                if k1 == 0.0 {
                    -semi_axes.min()
                } else {
                    k0 * (k0 - 1.0) / k1
                }
            }
            Self::Segment {
                a, b, half_width, ..
            } => segment_distance2(a, b, p).sqrt() - half_width,
            Self::Box {
                centre,
                half_size,
                rotation,
                ..
            } => {
                let q = local(centre, rotation).abs() - half_size;
                q.sup(&Vector2::zeros()).norm() + q.x.max(q.y).min(0.0)
            }
        }
    }
}

/// One random clutter item (a text line is several stamps), `scale` the image's size relative to 480 px.
fn random_item(rng: &mut ChaCha8Rng, w: f64, h: f64, scale: f64) -> Vec<Stamp> {
    let centre = Vector2::new(
        rng.random_range(-0.05..1.05) * w,
        rng.random_range(-0.05..1.05) * h,
    );
    let level = match rng.random_range(0..3) {
        0 => rng.random_range(0.0..0.2),
        1 => rng.random_range(0.65..1.0),
        _ => rng.random_range(0.25..0.6),
    };
    let angle: f64 = rng.random_range(0.0..std::f64::consts::PI);
    let rotation = Vector2::new(angle.cos(), angle.sin());
    match rng.random_range(0..10) {
        // Disks, the likeliest confusers: as many as everything else.
        0..=3 => {
            let r = rng.random_range(1.5..25.0) * scale;
            vec![Stamp::Ellipse {
                centre,
                semi_axes: Vector2::repeat(r),
                rotation: Vector2::x(),
                level,
            }]
        }
        4 | 5 => {
            let a = rng.random_range(3.0..40.0) * scale;
            let b = a * rng.random_range(0.2..1.0);
            vec![Stamp::Ellipse {
                centre,
                semi_axes: Vector2::new(a, b),
                rotation,
                level,
            }]
        }
        6 => {
            let length = rng.random_range(10.0..150.0) * scale;
            let d = 0.5 * length * rotation;
            vec![Stamp::Segment {
                a: centre - d,
                b: centre + d,
                half_width: rng.random_range(0.5..3.0) * scale,
                level,
            }]
        }
        7 => {
            let half_size = Vector2::new(
                rng.random_range(5.0..80.0) * scale,
                rng.random_range(5.0..80.0) * scale,
            );
            vec![Stamp::Box {
                centre,
                half_size,
                rotation,
                level,
            }]
        }
        // A line of text-like glyphs: each a few strokes in a cell.
        _ => text_line(rng, centre, level, scale),
    }
}

/// Draws `scene.clutter.count` random items on the background `layer`, each kept off the board by the clutter's
/// clearance when it has one (an item that comes too near is drawn again, up to 20 times).
pub(super) fn draw_clutter(
    scene: &PhotoScene,
    area: &Area,
    background_fraction: &[f64],
    layer: &mut [f64],
) {
    let clutter = &scene.clutter;
    // Where the board is, for the clearance: a summed-area table of the pixels it touches.
    let (aw, ah) = (area.width, area.height);
    let mut board_sat = vec![0u32; (aw + 1) * (ah + 1)];
    for j in 0..ah {
        let mut row = 0;
        for i in 0..aw {
            row += u32::from(background_fraction[j * aw + i] < 1.0);
            board_sat[(j + 1) * (aw + 1) + i + 1] = board_sat[j * (aw + 1) + i + 1] + row;
        }
    }
    let to_area =
        |x: f64, n: usize| (x + area.margin as f64).round().clamp(0.0, n as f64 - 1.0) as usize;
    let board_in = |lo: Vector2<f64>, hi: Vector2<f64>| {
        let (i0, i1) = (to_area(lo.x.floor(), aw), to_area(hi.x.ceil(), aw) + 1);
        let (j0, j1) = (to_area(lo.y.floor(), ah), to_area(hi.y.ceil(), ah) + 1);
        let at = |i: usize, j: usize| board_sat[j * (aw + 1) + i];
        at(i1, j1) + at(i0, j0) > at(i0, j1) + at(i1, j0)
    };
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed);
    rng.set_stream(CLUTTER_STREAM);
    let (w, h) = (
        f64::from(scene.camera.width_px),
        f64::from(scene.camera.height_px),
    );
    let scale = w.min(h) / 480.0;
    for _ in 0..clutter.count {
        for _ in 0..20 {
            let stamps = random_item(&mut rng, w, h, scale);
            if let Some(clearance) = clutter.clearance_px {
                let (lo, hi) = stamps.iter().fold(
                    (Vector2::repeat(f64::MAX), Vector2::repeat(f64::MIN)),
                    |(lo, hi), s| {
                        let (a, b) = s.bounds();
                        (lo.inf(&a), hi.sup(&b))
                    },
                );
                let c = Vector2::repeat(clearance + 1.0);
                if board_in(lo - c, hi + c) {
                    continue;
                }
            }
            for stamp in &stamps {
                draw_stamp(stamp, area, layer);
            }
            break;
        }
    }
}

/// A line of text-like glyphs from `centre` (px), each a few strokes in a cell `scale` times 5 to 14 px high.
fn text_line(rng: &mut ChaCha8Rng, centre: Vector2<f64>, level: f64, scale: f64) -> Vec<Stamp> {
    let glyph = rng.random_range(5.0..14.0) * scale;
    let stroke = (0.12 * glyph).max(0.7);
    let chars = rng.random_range(3..9usize);
    let tilt: f64 = rng.random_range(-0.3..0.3);
    let (along, across) = (
        Vector2::new(tilt.cos(), tilt.sin()),
        Vector2::new(-tilt.sin(), tilt.cos()),
    );
    let mut stamps = Vec::new();
    for c in 0..chars {
        let origin = centre + along * (c as f64 * 0.8 * glyph);
        let strokes = rng.random_range(1..4);
        for _ in 0..strokes {
            let (a, b) = match rng.random_range(0..3) {
                0 => {
                    let x = rng.random_range(0.0..0.6) * glyph;
                    (Vector2::new(x, 0.0), Vector2::new(x, glyph))
                }
                1 => {
                    let y = rng.random_range(0.0..1.0) * glyph;
                    (Vector2::new(0.0, y), Vector2::new(0.6 * glyph, y))
                }
                _ => (Vector2::new(0.0, glyph), Vector2::new(0.6 * glyph, 0.0)),
            };
            stamps.push(Stamp::Segment {
                a: origin + along * a.x + across * a.y,
                b: origin + along * b.x + across * b.y,
                half_width: 0.5 * stroke,
                level,
            });
        }
    }
    stamps
}

/// Blends `stamp` into `layer` with its edge antialiased over a pixel.
fn draw_stamp(stamp: &Stamp, area: &Area, layer: &mut [f64]) {
    let (lo, hi) = stamp.bounds();
    let m = area.margin as f64;
    let range = |a: f64, b: f64, n: usize| {
        let first = (a + m - 1.0).floor().max(0.0);
        let last = (b + m + 1.0).ceil().min(n as f64 - 1.0);
        (first as usize, last as usize, first <= last)
    };
    let (i0, i1, ok_i) = range(lo.x, hi.x, area.width);
    let (j0, j1, ok_j) = range(lo.y, hi.y, area.height);
    if !(ok_i && ok_j) {
        return;
    }
    let level = stamp.level();
    for j in j0..=j1 {
        for i in i0..=i1 {
            let d = stamp.distance(Vector2::new(area.raw(i), area.raw(j)));
            let cover = (0.5 - d).clamp(0.0, 1.0);
            if cover > 0.0 {
                let k = j * area.width + i;
                layer[k] += (level - layer[k]) * cover;
            }
        }
    }
}
