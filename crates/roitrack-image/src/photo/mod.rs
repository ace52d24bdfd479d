//! Blob detection in photographs: dark or bright blobs of any size under uneven light, with shape filters and
//! sub-pixel grey-level centres ([`detect_photo_blobs`]).
//!
//! One threshold cannot serve a photograph: light falls off towards the corners, a shadow crosses the target, the sun
//! brightens one side. So the image is thresholded at many levels spread between its dark and bright ends (as
//! OpenCV's `SimpleBlobDetector` does); a blob is a connected component (8-connectivity) that passes the shape filters
//! at one level, and the same blob seen at several levels (nested components with nearly the same centre) is one
//! detection. In a shadow it is found at the low levels, in full light at the high ones. The shape filters ask what a
//! circle's image is at any viewing angle, an ellipse: the inertia ratio (minor over major second moment) bounds the
//! foreshortening, the area against that of the ellipse with the same second moments rejects rings, crosses and
//! merged pairs, at most two runs of pixels per row on average reject what is far from convex, and a component
//! touching the image border is cut and refused. The centre is then measured again from the grey levels, on the outline (the `edge` module): on
//! rays from the thresholded centre, the point where the profile crosses the level halfway between the blob's inside
//! and its outside on that ray, and the centre of the ellipse fitted to these points; where that fails, background-
//! corrected moments in an elliptical window (the `centre` module). Each ray takes its own levels, so a shadow's edge
//! or a gradient across a blob hardly moves it; on the real photographs this project was measured on, it brought the
//! reprojection RMS below OpenCV's `findCirclesGrid` (0.276 against 0.283 px and 0.491 against 0.492 px, median per
//! set, same labels and intrinsics) where the moments alone stayed above it (0.288 and 0.511 px).
//!
//! Dark blobs are found as bright blobs of the inverted image, so everything downstream sees one polarity.

mod centre;
mod edge;

use crate::components::{Component, Labeller};
use centre::{Ellipse, grey_centre, principal_moments};

/// Whether the blobs are brighter or darker than what surrounds them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Polarity {
    /// Bright blobs on a darker background (LEDs, retro-reflective markers, white dots on black).
    Bright,
    /// Dark blobs on a lighter background (printed circles on paper).
    Dark,
}

impl Polarity {
    /// `"bright"` or `"dark"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Bright => "bright",
            Self::Dark => "dark",
        }
    }

    /// The opposite polarity.
    pub fn other(self) -> Self {
        match self {
            Self::Bright => Self::Dark,
            Self::Dark => Self::Bright,
        }
    }
}

/// Settings of [`detect_photo_blobs`]. The defaults suit photographs of printed circles and of bright markers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotoBlobOptions {
    /// Smallest blob area (px at the threshold that finds it): below, a centre is too noisy to be worth matching.
    pub min_area_px: f64,
    /// Largest blob area as a fraction of the image's area.
    pub max_area_fraction: f64,
    /// Smallest ratio of the minor to the major second moment (the square of the ellipse's axis ratio): 0.04 allows
    /// circles seen 78° off their axis.
    pub min_inertia_ratio: f64,
    /// Bounds of the area over the area of the ellipse with the same second moments (1 for an ellipse).
    pub ellipse_fill_range: (f64, f64),
    /// Most horizontal runs per row (1 for a convex shape; noise on the outline of a faint blob, found at few levels,
    /// breaks it into more: 2 keeps such blobs, and rings and crosses still fail the ellipse fill).
    pub max_runs_per_row: f64,
    /// Number of threshold levels between the image's dark and bright ends.
    pub levels: usize,
    /// Levels a blob must be found at to count (a blob found at one level only is a noise-level feature).
    pub min_levels: usize,
    /// Threads the work is shared between: 1, or 2 (the default) to label half of the levels and measure half of
    /// the blobs on a second thread, for images of 100,000 pixels or more. The result is the same either way.
    pub threads: usize,
    /// Smallest contrast of a blob against its background, as a fraction of the image's dynamic range (its 1st
    /// percentile to its maximum).
    pub min_contrast_fraction: f64,
}

impl Default for PhotoBlobOptions {
    fn default() -> Self {
        Self {
            min_area_px: 7.0,
            max_area_fraction: 0.25,
            min_inertia_ratio: 0.04,
            ellipse_fill_range: (0.8, 1.15),
            max_runs_per_row: 2.0,
            levels: 8,
            min_levels: 2,
            min_contrast_fraction: 0.08,
            threads: 2,
        }
    }
}

/// A blob found in a photograph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotoBlob {
    /// Sub-pixel centre (raw pixels): the centre of the ellipse fitted to the blob's outline (see the module's
    /// documentation), the centre of the blob's image: column.
    pub u_px: f64,
    /// Its row.
    pub v_px: f64,
    /// Area (px²) of the ellipse the blob's second moments describe, at the threshold midway through the levels
    /// that found it.
    pub area_px: f64,
    /// Semi-major axis of that ellipse (px).
    pub semi_major_px: f64,
    /// Its semi-minor axis (px).
    pub semi_minor_px: f64,
    /// The angle of its major axis from the u axis (rad).
    pub angle_rad: f64,
    /// How far the blob stands from its local background (DN).
    pub contrast: f64,
    /// Threshold levels at which it was found.
    pub levels: u32,
}

impl PhotoBlob {
    /// Diameter of the circle of the same area (px).
    pub fn diameter_px(&self) -> f64 {
        2.0 * (self.area_px / std::f64::consts::PI).sqrt()
    }
}

/// One blob seen at one or more levels.
#[derive(Debug, Clone)]
struct Group {
    u_px: f64,
    v_px: f64,
    radius_px: f64,
    /// The components that make it, by increasing threshold.
    members: Vec<Component>,
}

/// Reused buffers of [`detect_photo_blobs`] (hold one per thread to detect frame after frame without allocating).
#[derive(Debug, Default)]
pub struct PhotoScratch {
    inverted: Vec<u16>,
    workers: [WorkerScratch; 2],
}

/// The buffers of one of the threads [`detect_photo_blobs`] splits its work between.
#[derive(Debug, Default)]
struct WorkerScratch {
    labeller: Labeller<Component>,
    ring: Vec<(f64, f64, f64)>,
    edges: Vec<nalgebra::Vector2<f64>>,
    contrasts: Vec<f64>,
}

/// Images smaller than this (px) are searched on one thread: a second one would cost more to start than it saves.
const MIN_PIXELS_FOR_TWO_THREADS: usize = 100_000;

/// Runs `first(&mut workers[0])` here and, when `two`, `second(&mut workers[1])` on a scoped thread beside it.
fn split_work<A: Send, B: Send>(
    workers: &mut [WorkerScratch; 2],
    two: bool,
    first: impl FnOnce(&mut WorkerScratch) -> A,
    second: impl FnOnce(&mut WorkerScratch) -> B + Send,
) -> (A, B) {
    let [w0, w1] = workers;
    if !two {
        let a = first(w0);
        return (a, second(w1));
    }
    std::thread::scope(|scope| {
        let handle = scope.spawn(|| second(w1));
        let a = first(w0);
        let b = handle
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (a, b)
    })
}

/// Detects the blobs of one polarity in a row-major `width` x `height` photograph of `bit_depth`-bit values
/// (see the module's documentation for how). Blobs come sorted by decreasing contrast.
///
/// ```
/// use roitrack_image::photo::{PhotoBlobOptions, PhotoScratch, Polarity, detect_photo_blobs};
/// // A dark disk of radius 6 px at (30.3, 20.6) on a light background that brightens to the right.
/// let (w, h) = (64usize, 40usize);
/// let mut image = vec![0u16; w * h];
/// for j in 0..h {
///     for i in 0..w {
///         let mut ink = 0.0;
///         for s in 0..64 {
///             let (x, y) = (i as f64 - 0.5 + ((s % 8) as f64 + 0.5) / 8.0, j as f64 - 0.5 + ((s / 8) as f64 + 0.5) / 8.0);
///             if (x - 30.3).powi(2) + (y - 20.6).powi(2) < 36.0 { ink += 1.0 / 64.0; }
///         }
///         let light = 150.0 + i as f64;
///         image[j * w + i] = (light * (1.0 - 0.8 * ink)) as u16;
///     }
/// }
/// let blobs = detect_photo_blobs(&image, w as u32, h as u32, 8, Polarity::Dark, &PhotoBlobOptions::default(),
///     &mut PhotoScratch::default());
/// assert_eq!(blobs.len(), 1);
/// assert!((blobs[0].u_px - 30.3).abs() < 0.05 && (blobs[0].v_px - 20.6).abs() < 0.05);
/// assert!((blobs[0].diameter_px() - 12.0).abs() < 1.0);
/// ```
///
/// # Panics
/// If `pixels.len() != width * height`.
pub fn detect_photo_blobs(
    pixels: &[u16],
    width: u32,
    height: u32,
    bit_depth: u8,
    polarity: Polarity,
    options: &PhotoBlobOptions,
    scratch: &mut PhotoScratch,
) -> Vec<PhotoBlob> {
    find_photo_blob_candidates(pixels, width, height, bit_depth, polarity, options, scratch)
        .measure(scratch)
}

/// The blobs of one polarity found by thresholding, their centres not yet measured: the first of the two steps of
/// [`detect_photo_blobs`] ([`find_photo_blob_candidates`], then [`Self::measure`]). The second step (the outline of
/// every blob, then its contrast) costs about as much as the first; a caller that must choose between polarities
/// can judge each by its [`Self::rough_blobs`] and measure only the one it chooses. Found with
/// [`find_rough_photo_blob_candidates`], only a few of the levels are labelled until [`Self::measure`] asks for
/// the others: a quarter of the labelling, for a polarity that may be judged and left.
#[derive(Debug)]
pub struct PhotoBlobCandidates<'a> {
    polarity: Polarity,
    /// The photograph.
    pixels: &'a [u16],
    /// The histogram of the photograph (not of its inversion), which sets the levels of either polarity; `None` for
    /// an image too small to search.
    histogram: Option<crate::histogram::Histogram>,
    /// The image with the blobs bright: the photograph, or its inversion for dark blobs.
    image: std::borrow::Cow<'a, [u16]>,
    width: usize,
    height: usize,
    full_scale: u16,
    options: PhotoBlobOptions,
    /// The threshold of each level (none for an image without range).
    thresholds: Vec<u16>,
    /// Per level, the components that passed the shape filters; `None` for a level not labelled yet.
    found: Vec<Option<Vec<Component>>>,
    /// Smallest contrast a blob's outline must show (DN).
    min_contrast: f64,
    two_threads: bool,
}

/// A blob as thresholding sees it, before its centre is measured ([`PhotoBlobCandidates::rough_blobs`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoughBlob {
    /// Centre of its pixels at the middle level that found it (px): within a few tenths of a pixel of the measured
    /// centre under even light, farther under a gradient: column.
    pub u_px: f64,
    /// Its row.
    pub v_px: f64,
    /// Area of its ellipse (px²): with every level labelled, the same as [`PhotoBlob::area_px`].
    pub area_px: f64,
    /// Threshold levels at which it was found.
    pub levels: u32,
}

impl<'a> PhotoBlobCandidates<'a> {
    /// The polarity of the blobs.
    pub fn polarity(&self) -> Polarity {
        self.polarity
    }

    /// The other polarity's candidates in the same photograph as [`find_rough_photo_blob_candidates`] finds them,
    /// with the photograph's histogram (which sets either polarity's levels) taken from these instead of counted
    /// again.
    ///
    /// ```
    /// use roitrack_image::photo::{PhotoBlobOptions, PhotoScratch, Polarity, find_rough_photo_blob_candidates};
    /// // A bright and a dark square of 6 x 6 px on a grey background.
    /// let (w, h) = (40usize, 20usize);
    /// let mut image = vec![100u16; w * h];
    /// for j in 7..13 {
    ///     for i in 8..14 {
    ///         image[j * w + i] = 200;
    ///         image[j * w + i + 16] = 10;
    ///     }
    /// }
    /// let options = PhotoBlobOptions { ellipse_fill_range: (0.7, 1.3), ..PhotoBlobOptions::default() };
    /// let mut scratch = PhotoScratch::default();
    /// let bright = find_rough_photo_blob_candidates(&image, w as u32, h as u32, 8, Polarity::Bright, &options, &mut scratch);
    /// let dark = bright.other_polarity_rough(&mut scratch);
    /// assert_eq!(dark.polarity(), Polarity::Dark);
    /// let direct = find_rough_photo_blob_candidates(&image, w as u32, h as u32, 8, Polarity::Dark, &options, &mut scratch);
    /// assert_eq!(dark.rough_blobs(), direct.rough_blobs());
    /// assert_eq!(dark.measure(&mut scratch), direct.measure(&mut scratch));
    /// ```
    pub fn other_polarity_rough(&self, scratch: &mut PhotoScratch) -> PhotoBlobCandidates<'a> {
        let mut candidates = unlabelled(
            self.pixels,
            self.width,
            self.height,
            self.full_scale,
            self.polarity.other(),
            &self.options,
            self.histogram.clone(),
            scratch,
        );
        candidates.label_rough(scratch);
        candidates
    }

    /// Whether every level has been labelled (not yet for [`find_rough_photo_blob_candidates`]'s).
    pub fn is_complete(&self) -> bool {
        self.found.iter().all(Option::is_some)
    }

    /// The blobs found by the levels labelled so far, in the order they were found: with every level, those found at
    /// [`PhotoBlobOptions::min_levels`] levels or more; with a few, those found at any.
    fn groups(&self) -> Vec<Group> {
        let mut groups: Vec<Group> = Vec::new();
        let mut grid = CellGrid::new(self.width, self.height);
        // A blob is seen once a level at most, mostly: its members' room taken at once, not grown (and moved) level
        // after level.
        let labelled = self.found.iter().flatten().count();
        // In the order of the levels, as if one thread had found them all.
        for found in self.found.iter().flatten() {
            for c in found {
                add_to_group(&mut groups, &mut grid, c, labelled);
            }
        }
        let min_levels = if self.is_complete() {
            self.options.min_levels
        } else {
            1
        };
        groups.retain(|g| g.members.len() >= min_levels);
        groups
    }

    /// Every candidate as the levels labelled so far see it, those found at the most levels (the strongest) first.
    pub fn rough_blobs(&self) -> Vec<RoughBlob> {
        let mut rough: Vec<RoughBlob> = self
            .groups()
            .iter()
            .map(|g| {
                let shape = middle_shape(g);
                RoughBlob {
                    u_px: shape.u_px,
                    v_px: shape.v_px,
                    area_px: shape.area_px(),
                    levels: g.members.len() as u32,
                }
            })
            .collect();
        // Stable: equally strong ones stay in the order they were found.
        rough.sort_by_key(|b| std::cmp::Reverse(b.levels));
        rough
    }

    /// Labels the levels a third and two thirds of the way up ([`find_rough_photo_blob_candidates`]).
    fn label_rough(&mut self, scratch: &mut PhotoScratch) {
        let levels = self.found.len();
        let mut some = vec![levels / 3, 2 * levels / 3];
        some.dedup();
        some.retain(|&k| k < levels);
        // On one thread: the second level reads only the words of the image that held pixels at the first, and a
        // thread started for one level's labelling costs about as much as it saves.
        let two_threads = std::mem::replace(&mut self.two_threads, false);
        self.label(&some, scratch);
        self.two_threads = two_threads;
    }

    /// Labels the levels `todo` (increasing), half of them on a second thread when the image is large.
    fn label(&mut self, todo: &[usize], scratch: &mut PhotoScratch) {
        let (w, h) = (self.width, self.height);
        let image: &[u16] = &self.image;
        let (options, thresholds) = (&self.options, &self.thresholds);
        let max_area = options.max_area_fraction * (w * h) as f64;
        // Each thread's thresholds climb, so each of its levels reads only the words of the image that held pixels
        // at the one before.
        let label = |levels: &[usize], worker: &mut WorkerScratch| -> Vec<Vec<Component>> {
            worker.labeller.forget_levels();
            levels
                .iter()
                .map(|&k| {
                    let mut found = Vec::new();
                    // The shape filters refuse a component on the border or of too few or too many pixels
                    // whatever its shape: such components are not summed.
                    worker.labeller.components_above_previous_admitted(
                        image,
                        w,
                        h,
                        thresholds[k],
                        pixels_admitted(options.min_area_px, max_area),
                        |c| {
                            if passes_shape(c, options, max_area) {
                                found.push(*c);
                            }
                        },
                    );
                    found
                })
                .collect()
        };
        let split = if self.two_threads && todo.len() >= 2 {
            todo.len() / 2
        } else {
            todo.len()
        };
        let (low, high) = todo.split_at(split);
        let (mut first, second) = split_work(
            &mut scratch.workers,
            self.two_threads && !high.is_empty(),
            |worker| label(low, worker),
            |worker| label(high, worker),
        );
        first.extend(second);
        for (&k, found) in todo.iter().zip(first) {
            self.found[k] = Some(found);
        }
    }

    /// Measures every candidate's centre and contrast (see the module's documentation), the levels not labelled yet
    /// labelled first, and keeps those with enough contrast: the blobs [`detect_photo_blobs`] returns, sorted by
    /// decreasing contrast.
    pub fn measure(mut self, scratch: &mut PhotoScratch) -> Vec<PhotoBlob> {
        let todo: Vec<usize> = (0..self.found.len())
            .filter(|&k| self.found[k].is_none())
            .collect();
        self.label(&todo, scratch);
        let groups = self.groups();
        let Self {
            polarity,
            image,
            width: w,
            height: h,
            full_scale,
            min_contrast,
            two_threads,
            ..
        } = self;
        // The centres, half of the blobs on each thread, kept in the order of the groups.
        let half = if two_threads {
            groups.len() / 2
        } else {
            groups.len()
        };
        let measure_all = |part: &[Group], worker: &mut WorkerScratch| -> Vec<PhotoBlob> {
            part.iter()
                .filter_map(|g| {
                    measure(
                        g,
                        &image,
                        (w, h),
                        polarity,
                        full_scale,
                        min_contrast,
                        worker,
                    )
                })
                .collect()
        };
        let (mut blobs, rest) = split_work(
            &mut scratch.workers,
            two_threads,
            |worker| measure_all(&groups[..half], worker),
            |worker| measure_all(&groups[half..], worker),
        );
        blobs.extend(rest);
        blobs.sort_by(|a, b| b.contrast.total_cmp(&a.contrast));
        // The inverted image's buffer goes back to the scratch, for the next image.
        if let std::borrow::Cow::Owned(inverted) = image {
            scratch.inverted = inverted;
        }
        blobs
    }
}

/// The first step of [`detect_photo_blobs`]: the image thresholded at every level, the components that pass the
/// shape filters grouped into blobs, no centre measured ([`PhotoBlobCandidates`]).
///
/// ```
/// use roitrack_image::photo::{PhotoBlobOptions, PhotoScratch, Polarity, detect_photo_blobs, find_photo_blob_candidates};
/// // Two bright squares of 5 x 5 px on a dark background.
/// let (w, h) = (40usize, 20usize);
/// let mut image = vec![10u16; w * h];
/// for (i0, j0) in [(8, 8), (25, 6)] {
///     for j in j0..j0 + 5 {
///         for i in i0..i0 + 5 {
///             image[j * w + i] = 200;
///         }
///     }
/// }
/// let options = PhotoBlobOptions { ellipse_fill_range: (0.7, 1.3), ..PhotoBlobOptions::default() };
/// let mut scratch = PhotoScratch::default();
/// let candidates = find_photo_blob_candidates(&image, w as u32, h as u32, 8, Polarity::Bright, &options, &mut scratch);
/// let rough = candidates.rough_blobs();
/// assert_eq!(rough.len(), 2);
/// assert!(rough.iter().any(|b| (b.u_px - 10.0).abs() < 1e-9 && (b.v_px - 10.0).abs() < 1e-9));
/// // Measuring them gives what the one-step detection gives.
/// let blobs = candidates.measure(&mut scratch);
/// let direct = detect_photo_blobs(&image, w as u32, h as u32, 8, Polarity::Bright, &options, &mut scratch);
/// assert_eq!(blobs, direct);
/// ```
///
/// # Panics
/// If `pixels.len() != width * height`.
pub fn find_photo_blob_candidates<'a>(
    pixels: &'a [u16],
    width: u32,
    height: u32,
    bit_depth: u8,
    polarity: Polarity,
    options: &PhotoBlobOptions,
    scratch: &mut PhotoScratch,
) -> PhotoBlobCandidates<'a> {
    let mut candidates =
        unlabelled_photo(pixels, width, height, bit_depth, polarity, options, scratch);
    let every: Vec<usize> = (0..candidates.found.len()).collect();
    candidates.label(&every, scratch);
    candidates
}

/// [`find_photo_blob_candidates`] with only the levels a third and two thirds of the way up labelled (a quarter of
/// the work with the default 8 levels), the others when the candidates are measured: enough to judge a polarity by
/// its [`PhotoBlobCandidates::rough_blobs`] (any blob found at either level) before paying for the rest. Measured,
/// the candidates give exactly what [`detect_photo_blobs`] gives.
///
/// ```
/// use roitrack_image::photo::{PhotoBlobOptions, PhotoScratch, Polarity, detect_photo_blobs, find_rough_photo_blob_candidates};
/// // A bright square of 6 x 6 px on a dark background.
/// let (w, h) = (30usize, 20usize);
/// let mut image = vec![10u16; w * h];
/// for j in 7..13 {
///     for i in 12..18 {
///         image[j * w + i] = 200;
///     }
/// }
/// let options = PhotoBlobOptions { ellipse_fill_range: (0.7, 1.3), ..PhotoBlobOptions::default() };
/// let mut scratch = PhotoScratch::default();
/// let rough = find_rough_photo_blob_candidates(&image, w as u32, h as u32, 8, Polarity::Bright, &options, &mut scratch);
/// assert!(!rough.is_complete());
/// assert_eq!(rough.rough_blobs().len(), 1);
/// let blobs = rough.measure(&mut scratch);
/// assert_eq!(blobs, detect_photo_blobs(&image, w as u32, h as u32, 8, Polarity::Bright, &options, &mut scratch));
/// ```
///
/// # Panics
/// If `pixels.len() != width * height`.
pub fn find_rough_photo_blob_candidates<'a>(
    pixels: &'a [u16],
    width: u32,
    height: u32,
    bit_depth: u8,
    polarity: Polarity,
    options: &PhotoBlobOptions,
    scratch: &mut PhotoScratch,
) -> PhotoBlobCandidates<'a> {
    let mut candidates =
        unlabelled_photo(pixels, width, height, bit_depth, polarity, options, scratch);
    candidates.label_rough(scratch);
    candidates
}

/// The candidates of a photograph before any level is labelled: the image of the polarity, the levels' thresholds.
fn unlabelled_photo<'a>(
    pixels: &'a [u16],
    width: u32,
    height: u32,
    bit_depth: u8,
    polarity: Polarity,
    options: &PhotoBlobOptions,
    scratch: &mut PhotoScratch,
) -> PhotoBlobCandidates<'a> {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(pixels.len(), w * h, "pixel buffer length");
    let full_scale = ((1u32 << bit_depth.clamp(1, 16)) - 1) as u16;
    let histogram = (w >= 3 && h >= 3).then(|| crate::histogram::Histogram::of(pixels, full_scale));
    unlabelled(
        pixels, w, h, full_scale, polarity, options, histogram, scratch,
    )
}

/// The candidates of a `w` x `h` photograph of values up to `full_scale` whose histogram is `histogram` (`None`:
/// too small to search) before any level is labelled.
#[allow(clippy::too_many_arguments)]
fn unlabelled<'a>(
    pixels: &'a [u16],
    w: usize,
    h: usize,
    full_scale: u16,
    polarity: Polarity,
    options: &PhotoBlobOptions,
    histogram: Option<crate::histogram::Histogram>,
    scratch: &mut PhotoScratch,
) -> PhotoBlobCandidates<'a> {
    let levels = options.levels.max(1);
    let image = match polarity {
        Polarity::Bright => std::borrow::Cow::Borrowed(pixels),
        Polarity::Dark => {
            let mut inverted = std::mem::take(&mut scratch.inverted);
            inverted.clear();
            inverted.extend(pixels.iter().map(|&p| full_scale.saturating_sub(p)));
            std::borrow::Cow::Owned(inverted)
        }
    };
    let mut candidates = PhotoBlobCandidates {
        polarity,
        pixels,
        histogram,
        image,
        width: w,
        height: h,
        full_scale,
        options: *options,
        thresholds: Vec::new(),
        found: Vec::new(),
        min_contrast: 0.0,
        two_threads: options.threads >= 2 && w * h >= MIN_PIXELS_FOR_TWO_THREADS && levels >= 2,
    };
    let Some(histogram) = &candidates.histogram else {
        return candidates;
    };
    // The range of the image with the blobs bright (the photograph's or its inversion's), from its 1st percentile
    // to its brightest pixel: small blobs can be far fewer than 1 % of the pixels. The inversion's histogram is the
    // photograph's mirrored.
    let (low, high) = match polarity {
        Polarity::Bright => (histogram.percentile(0.01), histogram.percentile(1.0)),
        Polarity::Dark => (
            full_scale - histogram.percentile_from_top(0.01),
            full_scale - histogram.percentile_from_top(1.0),
        ),
    };
    let range = f64::from(high.saturating_sub(low));
    if range < 4.0 {
        return candidates;
    }
    candidates.thresholds = (0..levels)
        .map(|k| (f64::from(low) + range * (k as f64 + 1.0) / (levels as f64 + 1.0)) as u16)
        .collect();
    candidates.found = vec![None; levels];
    candidates.min_contrast = options.min_contrast_fraction * range;
    candidates
}

/// The shape of the component of a group at its middle level: its threshold sits halfway up the blob's edge, so its
/// area is the blob's.
fn middle_shape(g: &Group) -> Ellipse {
    let c = &g.members[g.members.len() / 2];
    let (u_px, v_px) = c.centre();
    Ellipse::from_moments(u_px, v_px, c.covariance())
}

/// The blob of a group: its centre and contrast from the outline, its shape from the middle level.
fn measure(
    g: &Group,
    image: &[u16],
    (w, h): (usize, usize),
    polarity: Polarity,
    full_scale: u16,
    min_contrast: f64,
    worker: &mut WorkerScratch,
) -> Option<PhotoBlob> {
    let shape = middle_shape(g);
    // The outline's ellipse, from rays cast from the threshold's centre: the better centre under uneven light and on
    // real photographs. Where it cannot be fitted, background-corrected grey-level moments.
    let start = nalgebra::Vector2::new(shape.u_px, shape.v_px);
    let (centre, contrast) = match edge::edge_centre(
        image,
        w,
        h,
        &shape,
        start,
        &mut worker.edges,
        &mut worker.contrasts,
    ) {
        Some(found) => found,
        None => {
            let light = (polarity == Polarity::Dark).then_some(full_scale);
            let grey = grey_centre(image, w, h, &shape, light, 2, &mut worker.ring)?;
            (nalgebra::Vector2::new(grey.u_px, grey.v_px), grey.contrast)
        }
    };
    if contrast < min_contrast {
        return None;
    }
    Some(PhotoBlob {
        u_px: centre.x,
        v_px: centre.y,
        area_px: shape.area_px(),
        semi_major_px: shape.semi_major_px,
        semi_minor_px: shape.semi_minor_px,
        angle_rad: shape.angle_rad,
        contrast,
        levels: g.members.len() as u32,
    })
}

/// Buffers of [`outline_centre`], reused from one call to the next.
#[derive(Debug, Clone, Default)]
pub struct OutlineScratch {
    edges: Vec<nalgebra::Vector2<f64>>,
    contrasts: Vec<f64>,
}

/// The centre of the outline of the bright blob around `start_px` (in the coordinates of the row-major `width` x
/// `height` image `pixels`, pixel (i, j) centred on (i, j)) that covers about `area_px` pixels: the centre of the
/// ellipse fitted to the points where rays from `start_px` cross the level halfway between the blob's inside and
/// its outside, each ray with its own levels. The photograph detector's centre, for a blob found otherwise (in a
/// tracking window): the threshold-weighted moments of a window move with the pixels' noise near their threshold,
/// where the outline's points average it over the whole edge (on four dots in noisy frames, 0.042 against 0.029 px
/// from the true centres). `None` when too few rays find an edge (a blob cut by the image's border, or far from round
/// at `area_px`) or the fit is not an ellipse; the caller keeps its own centre then.
///
/// ```
/// use nalgebra::Vector2;
/// use roitrack_image::photo::{OutlineScratch, outline_centre};
///
/// // A disk of radius 6 px centred on (15.3, 14.6), 200 on 20, each pixel's value its area coverage.
/// let (w, h) = (32, 32);
/// let mut pixels = vec![0u16; w * h];
/// for j in 0..h {
///     for i in 0..w {
///         let mut inside = 0;
///         for a in 0..8 {
///             for b in 0..8 {
///                 let (x, y) = (i as f64 - 0.4375 + a as f64 / 8.0, j as f64 - 0.4375 + b as f64 / 8.0);
///                 inside += ((x - 15.3).hypot(y - 14.6) <= 6.0) as u32;
///             }
///         }
///         pixels[j * w + i] = (20 + 180 * inside / 64) as u16;
///     }
/// }
/// let start = Vector2::new(15.0, 15.0);
/// let centre = outline_centre(&pixels, w, h, start, 113.0, &mut OutlineScratch::default()).unwrap();
/// assert!((centre - Vector2::new(15.3, 14.6)).norm() < 0.02);
/// ```
pub fn outline_centre(
    pixels: &[u16],
    width: usize,
    height: usize,
    start_px: nalgebra::Vector2<f64>,
    area_px: f64,
    scratch: &mut OutlineScratch,
) -> Option<nalgebra::Vector2<f64>> {
    if !(area_px > 0.0 && pixels.len() == width * height && width >= 2 && height >= 2) {
        return None;
    }
    let radius_px = (area_px / std::f64::consts::PI).sqrt();
    let shape = Ellipse {
        u_px: start_px.x,
        v_px: start_px.y,
        semi_major_px: radius_px,
        semi_minor_px: radius_px,
        angle_rad: 0.0,
    };
    edge::edge_centre(
        pixels,
        width,
        height,
        &shape,
        start_px,
        &mut scratch.edges,
        &mut scratch.contrasts,
    )
    .map(|(centre, _)| centre)
}

/// The pixel counts `n` that [`passes_shape`]'s area test admits, `!(n < min_area_px || n > max_area)` (`n` as
/// `f64`, exact below 2^53), as a range of counts: from the smallest count not below `min_area_px` to the largest not
/// above `max_area` (a NaN bound refuses nothing; a negative largest area, everything).
fn pixels_admitted(min_area_px: f64, max_area: f64) -> std::ops::RangeInclusive<u64> {
    let fewest = if min_area_px > 0.0 {
        min_area_px.ceil() as u64
    } else {
        0
    };
    if max_area < 0.0 {
        // Empty: every count refused.
        return std::ops::RangeInclusive::new(1, 0);
    }
    let most = if max_area.is_nan() {
        u64::MAX
    } else {
        max_area.floor() as u64
    };
    fewest..=most
}

fn passes_shape(c: &Component, options: &PhotoBlobOptions, max_area: f64) -> bool {
    let n = c.n as f64;
    if c.touches_border || n < options.min_area_px || n > max_area {
        return false;
    }
    let rows = f64::from(c.row_max - c.row_min + 1);
    if f64::from(c.runs) > options.max_runs_per_row * rows {
        return false;
    }
    let (l1, l2) = principal_moments(c.covariance());
    if l2 <= 0.0 || l2 < options.min_inertia_ratio * l1 {
        return false;
    }
    let fill = n / (4.0 * std::f64::consts::PI * (l1 * l2).sqrt());
    (options.ellipse_fill_range.0..=options.ellipse_fill_range.1).contains(&fill)
}

/// Groups' indices by 8 x 8 px cell of their centre, to find the group of a component in constant time: per cell, a
/// list linked through the groups, in the order they were added.
#[derive(Debug)]
struct CellGrid {
    cols: usize,
    rows: usize,
    /// Per cell, its first group (`NONE` for an empty cell). (No table of last groups: a cell holds a group or two,
    /// and setting a second table's every cell costs more than walking them.)
    first: Vec<u32>,
    /// Per group, the next group of its cell.
    next: Vec<u32>,
}

const CELL_PX: f64 = 8.0;

/// No group.
const NONE: u32 = u32::MAX;

impl CellGrid {
    fn new(width: usize, height: usize) -> Self {
        let cols = width.div_ceil(CELL_PX as usize);
        let rows = height.div_ceil(CELL_PX as usize);
        Self {
            cols,
            rows,
            first: vec![NONE; cols * rows],
            next: Vec::new(),
        }
    }

    fn cell(&self, u: f64, v: f64) -> (usize, usize) {
        (
            ((u / CELL_PX).max(0.0) as usize).min(self.cols - 1),
            ((v / CELL_PX).max(0.0) as usize).min(self.rows - 1),
        )
    }

    /// Adds group `g` (the next index) to cell `c`.
    fn push(&mut self, c: usize, g: u32) {
        debug_assert_eq!(g as usize, self.next.len());
        self.next.push(NONE);
        match self.first[c] {
            NONE => self.first[c] = g,
            mut last => {
                while self.next[last as usize] != NONE {
                    last = self.next[last as usize];
                }
                self.next[last as usize] = g;
            }
        }
    }

    /// The groups of cell `c`, in the order they were added.
    fn groups_of(&self, c: usize) -> impl Iterator<Item = u32> + '_ {
        std::iter::successors(Some(self.first[c]).filter(|&g| g != NONE), |&g| {
            Some(self.next[g as usize]).filter(|&n| n != NONE)
        })
    }
}

/// Adds a component to the group whose centre is within half the smaller radius of its own, or starts a group (with
/// room for `members` components).
fn add_to_group(groups: &mut Vec<Group>, grid: &mut CellGrid, c: &Component, members: usize) {
    let (u, v) = c.centre();
    let radius = (c.n as f64 / std::f64::consts::PI).sqrt();
    let reach = (0.5 * radius / CELL_PX).ceil() as usize;
    let (ci, cj) = grid.cell(u, v);
    let mut best: Option<(usize, f64)> = None;
    for gj in cj.saturating_sub(reach)..=(cj + reach).min(grid.rows - 1) {
        for gi in ci.saturating_sub(reach)..=(ci + reach).min(grid.cols - 1) {
            for g in grid.groups_of(gj * grid.cols + gi) {
                let group = &groups[g as usize];
                let d = (group.u_px - u).hypot(group.v_px - v);
                if d < 0.5 * group.radius_px.min(radius) && best.is_none_or(|(_, bd)| d < bd) {
                    best = Some((g as usize, d));
                }
            }
        }
    }
    match best {
        Some((g, _)) => {
            let group = &mut groups[g];
            group.members.push(*c);
            // Follow the latest level: a blob's centre drifts a little as the threshold climbs its edge.
            group.u_px = u;
            group.v_px = v;
            group.radius_px = radius;
        }
        None => {
            grid.push(cj * grid.cols + ci, groups.len() as u32);
            let mut first = Vec::with_capacity(members);
            first.push(*c);
            groups.push(Group {
                u_px: u,
                v_px: v,
                radius_px: radius,
                members: first,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    /// The admitted counts are those the area test admits, for whole, fractional, zero, negative and NaN bounds.
    #[test]
    fn pixels_admitted_are_those_the_area_test_admits() {
        let bounds = [
            0.0,
            1.0,
            6.5,
            7.0,
            7.2,
            40.0,
            40.9,
            -3.0,
            f64::NAN,
            f64::INFINITY,
        ];
        for &min_area_px in &bounds {
            for &max_area in &bounds {
                let admitted = super::pixels_admitted(min_area_px, max_area);
                for n in 0..60u64 {
                    let x = n as f64;
                    assert_eq!(
                        admitted.contains(&n),
                        !(x < min_area_px || x > max_area),
                        "{n} in {min_area_px}..={max_area}"
                    );
                }
            }
        }
    }

    use super::*;

    /// A `w` x `h` 8-bit scene: a background brightening to the right and down, dark and bright disks of 2 to 9 px
    /// radius, and noise of about ±6 DN, all from `seed` (a linear congruential generator: the scene is all that
    /// matters here, not the quality of its randomness).
    fn scene(w: usize, h: usize, seed: u64) -> Vec<u16> {
        let mut state = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        let mut uniform = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let disks: Vec<(f64, f64, f64, f64)> = (0..40)
            .map(|_| {
                let r = 2.0 + 7.0 * uniform();
                let (u, v) = (
                    r + 2.0 + (w as f64 - 2.0 * r - 4.0) * uniform(),
                    r + 2.0 + (h as f64 - 2.0 * r - 4.0) * uniform(),
                );
                let ink = if uniform() < 0.5 { -90.0 } else { 90.0 };
                (u, v, r, ink)
            })
            .collect();
        let mut pixels = vec![0u16; w * h];
        for j in 0..h {
            for i in 0..w {
                let mut value = 80.0 + 60.0 * i as f64 / w as f64 + 30.0 * j as f64 / h as f64;
                for &(u, v, r, ink) in &disks {
                    let d = (i as f64 - u).hypot(j as f64 - v);
                    // A half-pixel ramp at the edge, as a lens blurs it.
                    value += ink * (r + 0.5 - d).clamp(0.0, 1.0);
                }
                value += 12.0 * (uniform() - 0.5);
                pixels[j * w + i] = value.clamp(0.0, 255.0) as u16;
            }
        }
        pixels
    }

    #[test]
    fn candidates_measured_are_the_one_step_blobs_and_rough_ones_label_two_levels() {
        // 400 x 300: two threads; 200 x 150: one.
        for (w, h) in [(400usize, 300usize), (200, 150)] {
            for seed in 0..4 {
                let pixels = scene(w, h, seed);
                for polarity in [Polarity::Dark, Polarity::Bright] {
                    let options = PhotoBlobOptions::default();
                    let mut scratch = PhotoScratch::default();
                    let direct = detect_photo_blobs(
                        &pixels,
                        w as u32,
                        h as u32,
                        8,
                        polarity,
                        &options,
                        &mut scratch,
                    );
                    assert!(
                        direct.len() >= 5,
                        "{w} x {h}, seed {seed}: {}",
                        direct.len()
                    );
                    let rough = find_rough_photo_blob_candidates(
                        &pixels,
                        w as u32,
                        h as u32,
                        8,
                        polarity,
                        &options,
                        &mut scratch,
                    );
                    // The counted work of a rough pass: 2 of the 8 levels.
                    let labelled = rough.found.iter().filter(|f| f.is_some()).count();
                    assert_eq!(labelled, 2);
                    assert!(!rough.is_complete());
                    assert!(!rough.rough_blobs().is_empty());
                    assert_eq!(
                        rough.measure(&mut scratch),
                        direct,
                        "seed {seed} {polarity:?}"
                    );
                    let full = find_photo_blob_candidates(
                        &pixels,
                        w as u32,
                        h as u32,
                        8,
                        polarity,
                        &options,
                        &mut scratch,
                    );
                    assert!(full.is_complete());
                    assert_eq!(
                        full.measure(&mut scratch),
                        direct,
                        "seed {seed} {polarity:?}"
                    );
                }
            }
        }
    }
}
