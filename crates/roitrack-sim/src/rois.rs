//! Rendered ROI recordings: the ROI images a camera would have read for a simulated run, for tracking from pixels
//! offline (`roitrack simulate --rois`, then `roitrack track --rois`).

use nalgebra::Vector2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use roitrack_core::{Measurement, MotionState};
use roitrack_image::{Roi, RoiImage};
use thiserror::Error;

use crate::{
    ReflectionFault, RenderScratch, RoiRenderer, Scenario, SensorModel, SimulatedRun,
    SimulationOptions,
};

/// Side of the rendered ROIs (px).
pub const RECORDED_ROI_SIZE_PX: u32 = 40;
/// Largest offset (px, each axis) of a ROI's centre from its blob: a real scheduler places ROIs from a prediction.
pub const RECORDED_ROI_OFFSET_PX: f64 = 4.0;

/// Why a ROI could not be rendered.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RenderError {
    /// The sensor model is invalid.
    #[error("invalid sensor model: {0}")]
    Sensor(#[from] crate::SensorError),
    /// A measurement names a point the target does not have.
    #[error("measurement at t = {t_s} s: point id {id} is not in the target")]
    UnknownId {
        /// The measurement's time (s).
        t_s: f64,
        /// The unknown point id.
        id: u32,
    },
    /// A measurement's blob is behind the camera or outside the image at its time.
    #[error("measurement at t = {t_s} s: the blob of point {id} is not visible")]
    NotVisible {
        /// The measurement's time (s).
        t_s: f64,
        /// The point's id.
        id: u32,
    },
    /// The camera's image cannot hold one recorded ROI.
    #[error("the camera's image is smaller than a {RECORDED_ROI_SIZE_PX} px ROI")]
    SensorTooSmall,
}

/// The ROI image of every measurement of `run`: a [`RECORDED_ROI_SIZE_PX`] square placed on the blob with a random
/// error of up to [`RECORDED_ROI_OFFSET_PX`] (as a real scheduler would), rendered by the simulated camera with
/// `sensor` at the measurement's time and the truth of `options` (its jump and excursion included), with a
/// reflection in a fraction of them if `reflections` is given. Deterministic for `options.seed`; the reflections have
/// their own generator, so the ROIs are the same with and without them. Rendered one at a time, as iterated (by a
/// [`RoiImageRenderer`], which renders a measurement at a time for runs that are not held in memory).
///
/// ```
/// use roitrack_sim::{Scenario, ScenarioKind, SensorModel, SimulationOptions, render_roi_images, simulate};
///
/// let scenario = Scenario::new(ScenarioKind::Static, 1);
/// let options = SimulationOptions::default();
/// let run = simulate(&scenario, &options).unwrap();
/// let first: Vec<_> = render_roi_images(&scenario, &options, &run, SensorModel::default(), None)
///     .unwrap()
///     .take(3)
///     .collect::<Result<_, _>>()
///     .unwrap();
/// assert_eq!(first.len(), 3);
/// assert_eq!(first[0].point_id, run.measurements[0].id);
/// assert_eq!(first[0].pixels.len(), 40 * 40);
/// ```
pub fn render_roi_images<'a>(
    scenario: &'a Scenario,
    options: &'a SimulationOptions,
    run: &'a SimulatedRun,
    sensor: SensorModel,
    reflections: Option<ReflectionFault>,
) -> Result<impl Iterator<Item = Result<RoiImage, RenderError>> + 'a, RenderError> {
    let mut renderer = RoiImageRenderer::new(scenario, options, sensor, reflections)?;
    Ok(run.measurements.iter().map(move |m| renderer.render(m)))
}

/// Renders the ROI image of one measurement after another, as [`render_roi_images`] does for a whole run (the same
/// images, in the same order, for the same measurements): for runs streamed by a [`crate::Simulation`].
///
/// ```
/// use roitrack_sim::{RoiImageRenderer, Scenario, ScenarioKind, SensorModel, Simulation, SimulationOptions};
///
/// let scenario = Scenario::new(ScenarioKind::Static, 1);
/// let options = SimulationOptions::default();
/// let mut renderer = RoiImageRenderer::new(&scenario, &options, SensorModel::default(), None).unwrap();
/// for roi in Simulation::new(&scenario, &options).unwrap().take(3) {
///     let m = roi.unwrap().measurement.unwrap();
///     assert_eq!(renderer.render(&m).unwrap().point_id, m.id);
/// }
/// ```
#[derive(Debug)]
pub struct RoiImageRenderer<'a> {
    scenario: &'a Scenario,
    options: &'a SimulationOptions,
    renderer: RoiRenderer,
    bit_depth: u8,
    rng: ChaCha8Rng,
    fault_rng: ChaCha8Rng,
    scratch: RenderScratch,
    reflections: Option<ReflectionFault>,
}

impl<'a> RoiImageRenderer<'a> {
    /// A renderer of the scenario's camera and target with `sensor`, and a reflection in a fraction of the ROIs if
    /// `reflections` is given.
    pub fn new(
        scenario: &'a Scenario,
        options: &'a SimulationOptions,
        sensor: SensorModel,
        reflections: Option<ReflectionFault>,
    ) -> Result<Self, RenderError> {
        let seed = options.seed;
        Ok(Self {
            scenario,
            options,
            renderer: RoiRenderer::new(scenario.camera.clone(), scenario.target.clone(), sensor)?,
            bit_depth: sensor.bit_depth as u8,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x0005_1f0c_a11e),
            fault_rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_FA17),
            scratch: RenderScratch::new(),
            reflections,
        })
    }

    /// The ROI image of `m`, the next measurement of the run.
    pub fn render(&mut self, m: &Measurement) -> Result<RoiImage, RenderError> {
        let (scenario, options) = (self.scenario, self.options);
        let truth = move |t: f64| -> MotionState { options.truth_at(scenario, t) };
        let camera = &scenario.camera;
        let index = scenario
            .target
            .index_of(m.id)
            .ok_or(RenderError::UnknownId {
                t_s: m.t_s,
                id: m.id,
            })?;
        let centre = self
            .renderer
            .disk_image_centre_px(&truth(m.t_s), index)
            .ok_or(RenderError::NotVisible {
                t_s: m.t_s,
                id: m.id,
            })?;
        let offset = Vector2::new(
            self.rng
                .random_range(-RECORDED_ROI_OFFSET_PX..RECORDED_ROI_OFFSET_PX),
            self.rng
                .random_range(-RECORDED_ROI_OFFSET_PX..RECORDED_ROI_OFFSET_PX),
        );
        let roi = Roi::centred(
            centre.x + offset.x,
            centre.y + offset.y,
            RECORDED_ROI_SIZE_PX,
            camera.width_px,
            camera.height_px,
        )
        .ok_or(RenderError::SensorTooSmall)?;
        let mut image = RoiImage::with_capacity(roi.len());
        image.set(m.t_s, m.id, roi, self.bit_depth);
        self.renderer.render_roi_with_scratch(
            &truth,
            &roi,
            m.t_s,
            &mut self.rng,
            &mut self.scratch,
            &mut image.pixels,
        );
        if let Some(fault) = &self.reflections
            && self.fault_rng.random::<f64>() < fault.fraction
        {
            fault.add_spot(
                &mut self.fault_rng,
                &roi,
                &mut image.pixels,
                self.renderer.sensor().max_dn(),
            );
        }
        Ok(image)
    }
}
