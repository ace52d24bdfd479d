//! The target in a photograph: blobs of either polarity ([`roitrack_image::photo`]), identified with no prior
//! ([`identify`](mod@crate::identify)), the pose, each point's centre.

use nalgebra::{UnitQuaternion, Vector2};
use roitrack_core::{CameraModel, MotionState, Target};
use roitrack_image::photo::{
    PhotoBlobCandidates, find_photo_blob_candidates, find_rough_photo_blob_candidates,
};
use roitrack_image::{Frame, PhotoBlob, PhotoBlobOptions, PhotoScratch, Polarity};

use crate::identify::{
    Identification, identify_if_promising, lattice_promise, on_lattice, whole_view_points,
};
use crate::matching::{DetectedBlob, MatchError};

/// Which blobs to look for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PolarityChoice {
    /// Both, per image: the likelier first ([`likely_polarity`]) unless its blobs hold less of the target than the
    /// other's, the other if the first does not identify the target ([`detect_target`]).
    #[default]
    Auto,
    /// Bright blobs on a darker background.
    Bright,
    /// Dark blobs on a lighter background.
    Dark,
}

/// Settings of [`detect_target`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PhotoOptions {
    /// Which blobs to look for: bright, dark, or both in the likelier order ([`PolarityChoice::Auto`], the default).
    pub polarity: PolarityChoice,
    /// The blob detector's settings, whose area range [`Self::distance_range_m`] narrows ([`Self::blob_options`]).
    pub blobs: PhotoBlobOptions,
    /// The distances (m) at which the target may be, nearest and farthest, if known: blobs whose area no target
    /// circle can have at such a distance (from the target's diameters, taken as up to 2x off, and the focal length,
    /// tilts up to 80°, a threshold's error of a factor 2) are left out before identification. `None`: any size from
    /// [`PhotoBlobOptions::min_area_px`] to a quarter of the image.
    pub distance_range_m: Option<(f64, f64)>,
}

impl PhotoOptions {
    /// The blob options with the area range narrowed by [`Self::distance_range_m`] and the target's diameters.
    ///
    /// ```
    /// use roitrack_core::{CameraModel, Target};
    /// use roitrack_detect::photo::PhotoOptions;
    /// let options = PhotoOptions { distance_range_m: Some((0.15, 3.0)), ..PhotoOptions::default() };
    /// // 6 and 9 mm circles at 0.15-3 m through a 1500 px lens: 3 to 90 px across, as drawn.
    /// let blobs = options.blob_options(&CameraModel::canonical(), &Target::grid4x4());
    /// assert_eq!(blobs.min_area_px, PhotoOptions::default().blobs.min_area_px);
    /// assert!(blobs.max_area_fraction < 0.06);
    /// let near = PhotoOptions { distance_range_m: Some((0.3, 0.35)), ..PhotoOptions::default() }
    ///     .blob_options(&CameraModel::canonical(), &Target::grid4x4());
    /// assert!(near.min_area_px > 10.0);
    /// ```
    pub fn blob_options(&self, camera: &CameraModel, target: &Target) -> PhotoBlobOptions {
        let mut blobs = self.blobs;
        let diameters = target.points().iter().filter_map(|p| p.diameter_m);
        let (small, large) = diameters.fold((f64::INFINITY, 0.0f64), |(lo, hi), d| {
            (lo.min(d), hi.max(d))
        });
        let Some((near, far)) = self.distance_range_m else {
            return blobs;
        };
        if !(small.is_finite() && near > 0.0 && far >= near) {
            return blobs;
        }
        let focal = camera.intrinsics.fx_px.max(camera.intrinsics.fy_px);
        let area = |d: f64, z: f64| std::f64::consts::FRAC_PI_4 * (focal * d / z).powi(2);
        // Foreshortening to cos 80°, a threshold that finds half the area below and twice above, and the file's
        // diameters nominal: up to 2x off either way (a factor 4 in area, as identification allows).
        let min_area = 0.5 * 80f64.to_radians().cos() * area(small, far) / NOMINAL_DIAMETER_AREA;
        let max_area = 2.0 * area(large, near) * NOMINAL_DIAMETER_AREA;
        let image_area = f64::from(camera.width_px) * f64::from(camera.height_px);
        blobs.min_area_px = blobs.min_area_px.max(min_area);
        blobs.max_area_fraction = blobs.max_area_fraction.min(max_area / image_area);
        blobs
    }
}

/// How far a target file's diameters may be off the true ones, as a factor in area either way (2x in diameter).
pub(crate) const NOMINAL_DIAMETER_AREA: f64 = 4.0;

/// One identified target point in a photograph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotoPoint {
    /// The point's id, as in the target file.
    pub id: u32,
    /// Its centre (raw, distorted pixels), corrected for the perspective displacement of a disk's centre.
    pub centre_px: Vector2<f64>,
    /// Index of its blob in [`PhotoDetection::blobs`].
    pub blob: usize,
}

/// The target found in a photograph ([`detect_target`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoDetection {
    /// The polarity used (decided per image with [`PolarityChoice::Auto`]).
    pub polarity: Polarity,
    /// The pose of the target in the camera frame (velocity zero).
    pub state: MotionState,
    /// The identified points, by increasing id.
    pub points: Vec<PhotoPoint>,
    /// The target's symmetry leaves the labelling undecided; the labelling is the canonical one
    /// ([`identify`](mod@crate::identify)).
    pub ambiguous: bool,
    /// Root mean square of the reprojection distance (px): sqrt(mean |projection - centre|²), as OpenCV's
    /// calibration reports it (√2 times the per-coordinate RMS).
    pub reprojection_rms_px: f64,
    /// Target points predicted well inside the image that had no blob.
    pub missing: usize,
    /// Every candidate blob of the polarity used, matched or not.
    pub blobs: Vec<PhotoBlob>,
    /// The polarities whose blobs went through identification, in the order they did (the last is
    /// [`Self::polarity`]): with [`PolarityChoice::Auto`], one when the first tried was the right one.
    pub polarities_tried: Vec<Polarity>,
    /// The polarities whose blobs' centres were measured (their outlines), in the order they were: with
    /// [`PolarityChoice::Auto`], one when the polarities' thresholded blobs ranked the right one first. The other is
    /// at most thresholded.
    pub polarities_measured: Vec<Polarity>,
    /// Hypotheses verified by identification, over every polarity tried: the work identification did.
    pub hypotheses: usize,
}

impl PhotoDetection {
    /// The orientation as a unit quaternion (object to camera).
    pub fn cam_q_obj(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&self.state.cam_r_obj)
    }
}

/// Why the target was not found in a photograph.
///
/// ```
/// use roitrack_core::{CameraModel, Target};
/// use roitrack_image::Frame;
/// use roitrack_detect::photo::{PhotoError, PhotoOptions, detect_target};
///
/// let mut frame = Frame::default();
/// frame.resize(640, 480, 8);
/// let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
/// let e = detect_target(&camera, &target, &frame, &PhotoOptions::default()).unwrap_err();
/// assert!(matches!(e, PhotoError::ImageSize { image_width: 640, camera_width: 1024, .. }));
/// assert_eq!(e.blobs_seen().count(), 0);
/// ```
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhotoError {
    /// The image is not of the camera model's size; nothing was looked for.
    #[error(
        "the image is {image_width} x {image_height} px, the camera's {camera_width} x {camera_height} px"
    )]
    ImageSize {
        /// The image's width (px).
        image_width: u32,
        /// The image's height (px).
        image_height: u32,
        /// The camera model's image width (px).
        camera_width: u32,
        /// The camera model's image height (px).
        camera_height: u32,
    },
    /// The target was not identified among the blobs of the one polarity asked for ([`PolarityChoice::Bright`] or
    /// [`PolarityChoice::Dark`]).
    #[error("{polarity} blobs: {source}")]
    NotFound {
        /// `"bright"` or `"dark"` ([`Polarity::name`]).
        polarity: &'static str,
        /// The candidate blobs of that polarity, among which the target was not identified.
        blobs: Vec<PhotoBlob>,
        /// Why identification failed among them.
        source: MatchError,
    },
    /// With [`PolarityChoice::Auto`], the target was identified among the blobs of neither polarity.
    #[error(
        "neither polarity: dark blobs ({}): {dark}; bright blobs ({}): {bright}",
        .dark_blobs.len(),
        .bright_blobs.len()
    )]
    NotFoundEither {
        /// The candidate dark blobs, among which the target was not identified.
        dark_blobs: Vec<PhotoBlob>,
        /// Why identification failed among the dark blobs.
        dark: MatchError,
        /// The candidate bright blobs, among which the target was not identified.
        bright_blobs: Vec<PhotoBlob>,
        /// Why identification failed among the bright blobs.
        bright: MatchError,
    },
}

impl PhotoError {
    /// The candidate blobs the target was looked for among, of every polarity tried (dark ones first), matched to
    /// nothing: what was seen in a photograph where the target was not found, e.g. to draw it. Empty for
    /// [`PhotoError::ImageSize`], where nothing was looked at.
    pub fn blobs_seen(&self) -> impl Iterator<Item = &PhotoBlob> {
        let (first, second): (&[PhotoBlob], &[PhotoBlob]) = match self {
            Self::ImageSize { .. } => (&[], &[]),
            Self::NotFound { blobs, .. } => (blobs, &[]),
            Self::NotFoundEither {
                dark_blobs,
                bright_blobs,
                ..
            } => (dark_blobs, bright_blobs),
        };
        first.iter().chain(second)
    }
}

/// The blobs as identification takes them.
fn detected(blobs: &[PhotoBlob]) -> Vec<DetectedBlob> {
    blobs.iter().map(DetectedBlob::from).collect()
}

/// Finds, identifies and measures the target in a photograph: blob detection
/// ([`detect_photo_blobs`](roitrack_image::detect_photo_blobs)) in the polarity asked for or, with
/// [`PolarityChoice::Auto`], in both; identification ([`identify`](crate::identify::identify)); the pose.
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use roitrack_core::{CameraModel, MotionState, Target};
/// use roitrack_image::{Frame, Polarity};
/// use roitrack_sim::{RenderScratch, RoiRenderer, SensorModel};
/// use roitrack_detect::photo::{PhotoOptions, detect_target};
/// use rand::SeedableRng;
///
/// // A rendered frame of bright blobs; `Auto` finds them bright.
/// let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
/// let truth = MotionState::at_rest(Rotation3::from_euler_angles(0.2, -0.1, 0.4), Vector3::new(0.01, 0.0, 0.6));
/// let renderer = RoiRenderer::new(camera.clone(), target.clone(), SensorModel::default()).unwrap();
/// let mut frame = Frame::default();
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
/// renderer.render_frame(&|_t| truth, 0.0, &mut rng, &mut RenderScratch::new(), &mut frame);
/// let found = detect_target(&camera, &target, &frame, &PhotoOptions::default()).unwrap();
/// assert_eq!(found.polarity, Polarity::Bright);
/// assert_eq!(found.points.len(), 16);
/// assert!((found.state.cam_t_obj_m - truth.cam_t_obj_m).norm() < 1e-3);
/// ```
pub fn detect_target(
    camera: &CameraModel,
    target: &Target,
    frame: &Frame,
    options: &PhotoOptions,
) -> Result<PhotoDetection, PhotoError> {
    // The detector's buffers (a copy of the image, the labels' runs: about a megabyte for 640 x 480) kept on the
    // thread from one photograph to the next: allocating them each time costs page faults of their own.
    thread_local! {
        static SCRATCH: std::cell::RefCell<PhotoScratch> = std::cell::RefCell::default();
    }
    let mut scratch = SCRATCH.with(|kept| std::mem::take(&mut *kept.borrow_mut()));
    let found = detect_target_with(camera, target, frame, options, &mut scratch);
    SCRATCH.with(|kept| *kept.borrow_mut() = scratch);
    found
}

/// [`detect_target`] with the detector's buffers `scratch`.
fn detect_target_with(
    camera: &CameraModel,
    target: &Target,
    frame: &Frame,
    options: &PhotoOptions,
    scratch: &mut PhotoScratch,
) -> Result<PhotoDetection, PhotoError> {
    if (frame.width, frame.height) != (camera.width_px, camera.height_px) {
        return Err(PhotoError::ImageSize {
            image_width: frame.width,
            image_height: frame.height,
            camera_width: camera.width_px,
            camera_height: camera.height_px,
        });
    }
    let mut search = PolaritySearch {
        camera,
        target,
        frame,
        blob_options: options.blob_options(camera, target),
        tally: Tally::default(),
    };
    let (polarity, blobs, found) = match options.polarity {
        PolarityChoice::Bright => search.given(Polarity::Bright, scratch)?,
        PolarityChoice::Dark => search.given(Polarity::Dark, scratch)?,
        // The likelier polarity first. If its blobs hold a structure the size of the whole target in view (the
        // first hypotheses its search would verify match that many points), they are identified at once: the guess
        // is taken. If not, the wrong polarity's blobs (sky, foliage, glints) may hold thousands of small placements
        // whose verification fails slowly: the other polarity's blobs are found too and the more promising set is
        // identified first. Both are identified before the target is declared not found, so the order changes only
        // the time.
        PolarityChoice::Auto if on_lattice(target) => search.auto_on_lattice(scratch)?,
        PolarityChoice::Auto => search.auto_off_lattice(scratch)?,
    };
    Ok(search
        .tally
        .into(finish(camera, target, polarity, blobs, found)))
}

/// A polarity's blobs, and the target identified among them.
type Found = (Polarity, Vec<PhotoBlob>, Identification);

/// One photograph's search for the target among the blobs of one polarity or both, counting the work.
struct PolaritySearch<'a> {
    camera: &'a CameraModel,
    target: &'a Target,
    frame: &'a Frame,
    blob_options: PhotoBlobOptions,
    tally: Tally,
}

impl<'a> PolaritySearch<'a> {
    /// The blobs of `polarity` at the few levels that rank the polarities ([`find_rough_photo_blob_candidates`]).
    fn find_rough(
        &self,
        polarity: Polarity,
        scratch: &mut PhotoScratch,
    ) -> PhotoBlobCandidates<'a> {
        let frame = self.frame;
        find_rough_photo_blob_candidates(
            &frame.pixels,
            frame.width,
            frame.height,
            frame.bit_depth,
            polarity,
            &self.blob_options,
            scratch,
        )
    }

    /// The blobs of `polarity` at every level.
    fn find(&self, polarity: Polarity, scratch: &mut PhotoScratch) -> PhotoBlobCandidates<'a> {
        let frame = self.frame;
        find_photo_blob_candidates(
            &frame.pixels,
            frame.width,
            frame.height,
            frame.bit_depth,
            polarity,
            &self.blob_options,
            scratch,
        )
    }

    /// The blobs of `polarity` at every level, their centres measured, the work counted.
    fn measured(&mut self, polarity: Polarity, scratch: &mut PhotoScratch) -> Vec<PhotoBlob> {
        let candidates = self.find(polarity, scratch);
        self.measure(candidates, scratch)
    }

    /// The candidates' centres measured, the work counted.
    fn measure(
        &mut self,
        candidates: PhotoBlobCandidates<'_>,
        scratch: &mut PhotoScratch,
    ) -> Vec<PhotoBlob> {
        self.tally.measured.push(candidates.polarity());
        candidates.measure(scratch)
    }

    /// Identifies the target among `blobs` if their search's first hypotheses match at least `min_promise` points
    /// (`None` if not), counting the work; also returns that promise.
    fn attempt(
        &mut self,
        polarity: Polarity,
        blobs: &[PhotoBlob],
        min_promise: usize,
    ) -> (Option<Result<Identification, MatchError>>, usize) {
        let (outcome, work) =
            identify_if_promising(self.camera, self.target, &detected(blobs), min_promise);
        self.tally.hypotheses += work.hypotheses;
        if outcome.is_some() {
            self.tally.polarities.push(polarity);
        }
        (outcome, work.promise)
    }

    /// Identification of every hypothesis.
    fn identify_among(
        &mut self,
        polarity: Polarity,
        blobs: &[PhotoBlob],
    ) -> Result<Identification, MatchError> {
        self.attempt(polarity, blobs, 0)
            .0
            .expect("a search asking no promise stopped")
    }

    /// The target among the blobs of the polarity the user gave.
    fn given(
        &mut self,
        polarity: Polarity,
        scratch: &mut PhotoScratch,
    ) -> Result<Found, PhotoError> {
        let blobs = self.measured(polarity, scratch);
        match self.identify_among(polarity, &blobs) {
            Ok(found) => Ok((polarity, blobs, found)),
            Err(source) => Err(PhotoError::NotFound {
                polarity: polarity.name(),
                blobs,
                source,
            }),
        }
    }

    /// A target on a lattice: each polarity judged by its lattices' growth on the blobs of two thresholds, before
    /// the other levels are labelled and any centre is measured (a wrong polarity's few hundred glints cost as much
    /// to label and measure as identifying the target), and only the first in that order labelled in full and
    /// measured unless it fails.
    fn auto_on_lattice(&mut self, scratch: &mut PhotoScratch) -> Result<Found, PhotoError> {
        let (camera, target) = (self.camera, self.target);
        let whole_view = whole_view_points(target.len());
        let guess_candidates = self.find_rough(likely_polarity(self.frame), scratch);
        // Promises are compared with the whole view's size and with each other only: each is grown no further than
        // the comparison needs (the right polarity's lattice, grown in full, was most of its cost).
        let guess_promise =
            lattice_promise(camera, target, &rough(&guess_candidates), whole_view).unwrap_or(0);
        let (first, second) = if guess_promise >= whole_view {
            (guess_candidates, None)
        } else if guess_promise == 0 {
            // Nothing grew: the other polarity cannot promise less.
            (
                guess_candidates.other_polarity_rough(scratch),
                Some(guess_candidates),
            )
        } else {
            let other_candidates = guess_candidates.other_polarity_rough(scratch);
            // Only whether it exceeds the guess's matters.
            let other_promise =
                lattice_promise(camera, target, &rough(&other_candidates), guess_promise + 1)
                    .unwrap_or(0);
            if other_promise > guess_promise {
                (other_candidates, Some(guess_candidates))
            } else {
                (guess_candidates, Some(other_candidates))
            }
        };
        let first_polarity = first.polarity();
        let first_blobs = self.measure(first, scratch);
        match self.identify_among(first_polarity, &first_blobs) {
            Ok(found) => Ok((first_polarity, first_blobs, found)),
            Err(first_error) => {
                let second = second.unwrap_or_else(|| self.find(first_polarity.other(), scratch));
                let second_polarity = second.polarity();
                let second_blobs = self.measure(second, scratch);
                let outcome = self.identify_among(second_polarity, &second_blobs);
                fall_back(
                    (first_polarity, first_blobs, first_error),
                    (second_polarity, second_blobs, outcome),
                )
            }
        }
    }

    /// A target on no lattice: judging a polarity costs about as much as identifying it, so the guess is measured
    /// and its promise known from its search's first hypotheses. If it does not hold the whole target, the other
    /// polarity's is asked for more.
    fn auto_off_lattice(&mut self, scratch: &mut PhotoScratch) -> Result<Found, PhotoError> {
        let guess = likely_polarity(self.frame);
        let other = guess.other();
        let whole_view = whole_view_points(self.target.len());
        let guess_blobs = self.measured(guess, scratch);
        let (outcome, guess_promise) = self.attempt(guess, &guess_blobs, whole_view);
        match outcome {
            Some(Ok(found)) => Ok((guess, guess_blobs, found)),
            Some(Err(guess_error)) => {
                let other_blobs = self.measured(other, scratch);
                let outcome = self.identify_among(other, &other_blobs);
                fall_back(
                    (guess, guess_blobs, guess_error),
                    (other, other_blobs, outcome),
                )
            }
            // The guess's search stopped for too small a promise: the other polarity is asked for more.
            None => {
                let other_blobs = self.measured(other, scratch);
                let (other_outcome, _) = self.attempt(other, &other_blobs, guess_promise + 1);
                if let Some(Ok(found)) = other_outcome {
                    return Ok((other, other_blobs, found));
                }
                match self.identify_among(guess, &guess_blobs) {
                    Ok(found) => Ok((guess, guess_blobs, found)),
                    Err(guess_error) => {
                        let outcome = other_outcome
                            .unwrap_or_else(|| self.identify_among(other, &other_blobs));
                        fall_back(
                            (guess, guess_blobs, guess_error),
                            (other, other_blobs, outcome),
                        )
                    }
                }
            }
        }
    }
}

/// The blobs as the thresholds see them, for ranking the polarities ([`lattice_promise`]).
fn rough(candidates: &PhotoBlobCandidates<'_>) -> Vec<DetectedBlob> {
    candidates
        .rough_blobs()
        .iter()
        .map(DetectedBlob::from)
        .collect()
}

/// The polarity identified after another failed: its identification, or the failure of both.
fn fall_back(
    (first, first_blobs, first_error): (Polarity, Vec<PhotoBlob>, MatchError),
    (second, second_blobs, outcome): (Polarity, Vec<PhotoBlob>, Result<Identification, MatchError>),
) -> Result<Found, PhotoError> {
    match outcome {
        Ok(found) => Ok((second, second_blobs, found)),
        Err(second_error) => {
            let ((dark_blobs, dark), (bright_blobs, bright)) = match first {
                Polarity::Dark => ((first_blobs, first_error), (second_blobs, second_error)),
                Polarity::Bright => ((second_blobs, second_error), (first_blobs, first_error)),
            };
            debug_assert_ne!(first, second);
            Err(PhotoError::NotFoundEither {
                dark_blobs,
                dark,
                bright_blobs,
                bright,
            })
        }
    }
}

/// The work of identification over the polarities tried ([`PhotoDetection::polarities_tried`],
/// [`PhotoDetection::hypotheses`]).
#[derive(Debug, Default)]
struct Tally {
    polarities: Vec<Polarity>,
    measured: Vec<Polarity>,
    hypotheses: usize,
}

impl Tally {
    /// `detection` with this work.
    fn into(self, mut detection: PhotoDetection) -> PhotoDetection {
        detection.polarities_tried = self.polarities;
        detection.polarities_measured = self.measured;
        detection.hypotheses = self.hypotheses;
        detection
    }
}
/// Side of a square cell (px) of [`likely_polarity`]: a few blobs' worth.
const POLARITY_CELL_PX: usize = 32;

/// Dark blobs if small dark features dominate the frame's local contrast, else bright. Each 32 x 32 cell (every other
/// pixel of every other row) votes with its contrast: a few dark blobs on paper pull a cell's minimum far below its
/// mean while its maximum stays near it, bright markers the other way round; an edge or a smooth gradient pulls both
/// alike. Global statistics (the median against the range) fail on a print in a shadowed or dark scene. It is only
/// a guess (bright glints outdoors outvote a small print): [`detect_target`] checks it against the blobs.
pub fn likely_polarity(frame: &Frame) -> Polarity {
    let cells = cell_statistics(frame);
    let mut vote = 0.0;
    for &(lo, hi, sum, n) in &cells {
        if n == 0 {
            continue;
        }
        let mean = sum as f64 / f64::from(n);
        // How far below the mean the darkest pixel lies, against how far above it the brightest.
        vote += (mean - f64::from(lo)) - (f64::from(hi) - mean);
    }
    if vote > 0.0 {
        Polarity::Dark
    } else {
        Polarity::Bright
    }
}

/// Per [`POLARITY_CELL_PX`] cell of the frame (row-major), the minimum, maximum, sum and count of its pixels at
/// even columns of even rows.
fn cell_statistics(frame: &Frame) -> Vec<(u16, u16, u64, u32)> {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let (cols, rows) = (w.div_ceil(POLARITY_CELL_PX), h.div_ceil(POLARITY_CELL_PX));
    let mut cells = vec![(u16::MAX, 0u16, 0u64, 0u32); cols * rows];
    // Whole cells' rows of pixels 8 at a time (SSE2, every x86_64 CPU), about ten times the speed of a pixel at a
    // time; a partial cell at the right pixel by pixel.
    #[cfg(target_arch = "x86_64")]
    let whole = w / POLARITY_CELL_PX;
    #[cfg(not(target_arch = "x86_64"))]
    let whole = 0;
    #[cfg(target_arch = "x86_64")]
    let mut lanes = vec![simd::CellLanes::new(); whole];
    for cell_row in 0..rows {
        let cell_row_cells = &mut cells[cell_row * cols..][..cols];
        let rows_in_cell = cell_row * POLARITY_CELL_PX..((cell_row + 1) * POLARITY_CELL_PX).min(h);
        for j in rows_in_cell.step_by(2) {
            let row = &frame.pixels[j * w..(j + 1) * w];
            #[cfg(target_arch = "x86_64")]
            for (lane, chunk) in lanes.iter_mut().zip(row.as_chunks::<POLARITY_CELL_PX>().0) {
                lane.add(chunk);
            }
            for (cell, chunk) in cell_row_cells[whole..]
                .iter_mut()
                .zip(row[whole * POLARITY_CELL_PX..].chunks(POLARITY_CELL_PX))
            {
                for &p in chunk.iter().step_by(2) {
                    cell.0 = cell.0.min(p);
                    cell.1 = cell.1.max(p);
                    cell.2 += u64::from(p);
                    cell.3 += 1;
                }
            }
        }
        #[cfg(target_arch = "x86_64")]
        for (cell, lane) in cell_row_cells.iter_mut().zip(&mut lanes) {
            *cell = lane.take();
        }
    }
    cells
}

/// [`cell_statistics`] for whole cells with SSE2.
#[cfg(target_arch = "x86_64")]
mod simd {
    use super::POLARITY_CELL_PX;
    use std::arch::x86_64::{
        __m128i, _mm_add_epi32, _mm_and_si128, _mm_loadu_si128, _mm_max_epi16, _mm_min_epi16,
        _mm_set1_epi16, _mm_set1_epi32, _mm_setzero_si128, _mm_storeu_si128, _mm_xor_si128,
    };

    /// One cell's minimum, maximum and sum over its rows so far, in 8 lanes of 16 bits (4 of 32 for the sum): the
    /// pixels at even columns are the even lanes; the odd lanes, which see the odd columns, are left out when the
    /// cell is taken (lanes never mix, so they need no neutral values of their own at each row).
    #[derive(Clone, Copy)]
    pub(super) struct CellLanes {
        /// Signed minimum and maximum of the values with their top bit flipped (SSE2 compares signed 16-bit values
        /// only).
        min: __m128i,
        max: __m128i,
        sum: __m128i,
        count: u32,
    }

    impl CellLanes {
        pub(super) fn new() -> Self {
            // SAFETY: SSE2 is part of the x86_64 baseline.
            unsafe {
                Self {
                    min: _mm_set1_epi16(i16::MAX),
                    max: _mm_set1_epi16(i16::MIN),
                    sum: _mm_setzero_si128(),
                    count: 0,
                }
            }
        }

        /// Adds the even columns of one row of the cell.
        pub(super) fn add(&mut self, pixels: &[u16; POLARITY_CELL_PX]) {
            // SAFETY: SSE2 is part of the x86_64 baseline; the loads read 16 bytes at offsets 0..=48 of a 64-byte
            // array.
            unsafe {
                let bias = _mm_set1_epi16(i16::MIN);
                let even = _mm_set1_epi32(0xFFFF);
                let base = pixels.as_ptr().cast::<__m128i>();
                for k in 0..POLARITY_CELL_PX / 8 {
                    let v = _mm_loadu_si128(base.add(k));
                    let evens = _mm_and_si128(v, even);
                    let biased = _mm_xor_si128(v, bias);
                    self.min = _mm_min_epi16(self.min, biased);
                    self.max = _mm_max_epi16(self.max, biased);
                    // 16 rows of 4 values of at most 65535 a lane: far within 32 bits.
                    self.sum = _mm_add_epi32(self.sum, evens);
                }
            }
            self.count += (POLARITY_CELL_PX / 2) as u32;
        }

        /// The cell's minimum, maximum, sum and count, the lanes reset.
        pub(super) fn take(&mut self) -> (u16, u16, u64, u32) {
            let (mut min, mut max, mut sum) = ([0i16; 8], [0i16; 8], [0u32; 4]);
            // SAFETY: SSE2 is part of the x86_64 baseline; each store writes 16 bytes into a 16-byte array.
            unsafe {
                _mm_storeu_si128(min.as_mut_ptr().cast(), self.min);
                _mm_storeu_si128(max.as_mut_ptr().cast(), self.max);
                _mm_storeu_si128(sum.as_mut_ptr().cast(), self.sum);
            }
            let unbias = |v: i16| (v as u16) ^ 0x8000;
            // The even lanes: the even columns.
            let found = (
                unbias(*min.iter().step_by(2).min().unwrap_or(&i16::MAX)),
                unbias(*max.iter().step_by(2).max().unwrap_or(&i16::MIN)),
                sum.iter().map(|&s| u64::from(s)).sum(),
                self.count,
            );
            *self = Self::new();
            found
        }
    }
}

fn finish(
    camera: &CameraModel,
    target: &Target,
    polarity: Polarity,
    blobs: Vec<PhotoBlob>,
    found: Identification,
) -> PhotoDetection {
    let points = target.points();
    let mut sum = 0.0;
    let detected: Vec<PhotoPoint> = found
        .pairs
        .iter()
        .zip(&found.centres_px)
        .map(|(&(p, b), centre)| {
            if let Some(projected) = camera
                .raw_pixel_from_cam(&found.state.point_in_cam_at(&points[p].point_in_obj_m, 0.0))
            {
                sum += (projected - centre).norm_squared();
            }
            PhotoPoint {
                id: points[p].id,
                centre_px: *centre,
                blob: b,
            }
        })
        .collect();
    let mut detected = detected;
    detected.sort_by_key(|p| p.id);
    PhotoDetection {
        polarity,
        state: found.state,
        reprojection_rms_px: (sum / detected.len().max(1) as f64).sqrt(),
        points: detected,
        ambiguous: found.ambiguous,
        missing: found.missing,
        blobs,
        polarities_tried: vec![polarity],
        polarities_measured: vec![polarity],
        hypotheses: found.hypotheses,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cells' statistics as they were first computed, a pixel at a time: the reference of the fast ones.
    fn cell_statistics_by_pixel(frame: &Frame) -> Vec<(u16, u16, u64, u32)> {
        let (w, h) = (frame.width as usize, frame.height as usize);
        let (cols, rows) = (w.div_ceil(POLARITY_CELL_PX), h.div_ceil(POLARITY_CELL_PX));
        let mut cells = vec![(u16::MAX, 0u16, 0u64, 0u32); cols * rows];
        for j in (0..h).step_by(2) {
            let row = &frame.pixels[j * w..(j + 1) * w];
            let cell_row = &mut cells[(j / POLARITY_CELL_PX) * cols..][..cols];
            for (cell, chunk) in cell_row.iter_mut().zip(row.chunks(POLARITY_CELL_PX)) {
                for &p in chunk.iter().step_by(2) {
                    cell.0 = cell.0.min(p);
                    cell.1 = cell.1.max(p);
                    cell.2 += u64::from(p);
                    cell.3 += 1;
                }
            }
        }
        cells
    }

    #[test]
    fn cell_statistics_agree_with_a_pixel_at_a_time() {
        let mut state = 12_345u64;
        // Sizes with and without partial cells, 8- and 16-bit values (the extremes included).
        for (width, height, bit_depth) in [
            (640u32, 480u32, 8u8),
            (97, 70, 16),
            (64, 33, 12),
            (31, 5, 8),
        ] {
            let top = (1u32 << bit_depth) - 1;
            let pixels: Vec<u16> = (0..width * height)
                .map(|k| {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    match k % 97 {
                        0 => 0,
                        1 => top as u16,
                        _ => ((state >> 33) as u32 % (top + 1)) as u16,
                    }
                })
                .collect();
            let frame = Frame {
                width,
                height,
                bit_depth,
                pixels,
                ..Frame::default()
            };
            assert_eq!(
                cell_statistics(&frame),
                cell_statistics_by_pixel(&frame),
                "{width} x {height}, {bit_depth} bits"
            );
        }
    }
}
