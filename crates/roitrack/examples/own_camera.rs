//! Run the real-time loop with a camera of your own: implement `RoiCamera` (grab a ROI, grab a full frame) and the loop
//! does the rest: finds the target in a first full frame, places every ROI where the tracker predicts its blob,
//! centroids it, and tracks pose and velocity on a second thread.
//!
//! ```sh
//! cargo run --release -p roitrack --example own_camera
//! ```
//!
//! The camera here draws each blob as a Gaussian spot where a known motion puts it: a stand-in for a real camera
//! driver. Replace `grab_roi` and `grab_full_frame` with calls to your camera's SDK (set the ROI's offset and size,
//! trigger, read the buffer and its timestamp, converted to the loop's clock: that of the trigger times) and keep the
//! rest.

use roitrack::image::{GrabError, RoiTrigger};
use roitrack::nalgebra::{Rotation3, Vector2, Vector3};
use roitrack::pipeline::{LoopConfig, run_loop};
use roitrack::{
    CameraModel, Frame, MotionState, RoiCamera, RoiImage, Target, TrackStatus, TrackerConfig,
};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// A camera that sees the blobs of `target` as Gaussian spots, the target moving on a circle in front of it.
struct SpotCamera {
    camera: CameraModel,
    target: Target,
}

impl SpotCamera {
    /// The true motion: a 40 mm circle at 0.6 m, once a second, the target tilted a little.
    fn truth(t_s: f64) -> MotionState {
        let w = std::f64::consts::TAU;
        MotionState {
            cam_r_obj: Rotation3::from_euler_angles(0.15, -0.1, 0.05),
            cam_t_obj_m: Vector3::new(0.04 * (w * t_s).cos(), 0.04 * (w * t_s).sin(), 0.6),
            velocity_mps: Vector3::new(
                -0.04 * w * (w * t_s).sin(),
                0.04 * w * (w * t_s).cos(),
                0.0,
            ),
            angular_velocity_radps: Vector3::zeros(),
        }
    }

    /// Each blob's image centre (raw pixels) and spread (px) at time `t_s`.
    fn spots(&self, t_s: f64) -> Vec<(Vector2<f64>, f64)> {
        let state = Self::truth(t_s);
        self.target
            .points()
            .iter()
            .filter_map(|p| {
                let in_cam = state.point_in_cam_at(&p.point_in_obj_m, 0.0);
                let centre = self.camera.raw_pixel_from_cam(&in_cam)?;
                let diameter_px =
                    self.camera.intrinsics.fx_px * p.diameter_m.unwrap_or(0.006) / in_cam.z;
                Some((centre, diameter_px / 4.0))
            })
            .collect()
    }

    /// The value (8 bits) of pixel (i, j): a dark background and the spots.
    fn value(spots: &[(Vector2<f64>, f64)], i: u32, j: u32) -> u16 {
        let p = Vector2::new(f64::from(i), f64::from(j));
        let light: f64 = spots
            .iter()
            .map(|(c, sigma)| (-(p - c).norm_squared() / (2.0 * sigma * sigma)).exp())
            .sum();
        (12.0 + 220.0 * light).min(255.0) as u16
    }
}

impl RoiCamera for SpotCamera {
    fn grab_roi(
        &mut self,
        trigger: &RoiTrigger,
        image: &mut RoiImage,
    ) -> std::result::Result<(), GrabError> {
        let roi = trigger.roi;
        if !roi.fits_in(self.camera.width_px, self.camera.height_px) {
            return Err(GrabError::InvalidRoi {
                roi,
                reason: "off the sensor".to_string(),
            });
        }
        // A real camera reports when it exposed the ROI; this one exposes exactly when asked.
        image.set(trigger.t_s, trigger.point_id, roi, 8);
        let spots = self.spots(trigger.t_s);
        for (k, pixel) in image.pixels.iter_mut().enumerate() {
            let (i, j) = roi.pixel_at(k);
            *pixel = Self::value(&spots, i, j);
        }
        Ok(())
    }

    fn grab_full_frame(
        &mut self,
        t_s: f64,
        frame: &mut Frame,
    ) -> std::result::Result<(), GrabError> {
        frame.resize(self.camera.width_px, self.camera.height_px, 8);
        frame.t_s = t_s;
        let spots = self.spots(t_s);
        let width = frame.width;
        for (k, pixel) in frame.pixels.iter_mut().enumerate() {
            *pixel = Self::value(&spots, k as u32 % width, k as u32 / width);
        }
        Ok(())
    }
}

fn main() -> Result<()> {
    let (camera, target) = (CameraModel::canonical(), Target::grid4x4());
    let mut spot_camera = SpotCamera {
        camera: camera.clone(),
        target: target.clone(),
    };
    // Two seconds of ROIs at 4 kHz, an estimate every 10 ROIs; the camera runs as fast as the loop takes it.
    let config = LoopConfig {
        roi_slots: 8000,
        ..LoopConfig::default()
    };
    let report = run_loop(
        &mut spot_camera,
        &camera,
        &target,
        TrackerConfig::default(),
        &config,
    )?;
    println!(
        "{} ROIs read ({:.0} per second), {} estimates, {} rejected blobs, {} full-frame initialisation(s), median \
         latency {:.1} us",
        report.acquisition.rois,
        report.rois_per_s(),
        report.estimates.len(),
        report.acquisition.rejections.total(),
        report.acquisition.initialisations,
        report.latency_quantile_us(0.5)
    );
    let tracking: Vec<_> = report
        .estimates
        .iter()
        .filter(|e| e.status == TrackStatus::Tracking)
        .collect();
    let rms = |f: &dyn Fn(&roitrack::Estimate) -> f64| {
        (tracking.iter().map(|e| f(e).powi(2)).sum::<f64>() / tracking.len().max(1) as f64).sqrt()
    };
    let position_mm =
        rms(&|e| (e.state.cam_t_obj_m - SpotCamera::truth(e.t_ref_s).cam_t_obj_m).norm() * 1e3);
    let velocity_mm_s =
        rms(&|e| (e.state.velocity_mps - SpotCamera::truth(e.t_ref_s).velocity_mps).norm() * 1e3);
    println!(
        "{} tracking estimates: position error {position_mm:.3} mm RMS, velocity error {velocity_mm_s:.1} mm/s RMS",
        tracking.len()
    );
    if let Some(last) = report.estimates.last() {
        let p = last.state.cam_t_obj_m * 1e3;
        let v = last.state.velocity_mps * 1e3;
        println!(
            "last estimate at t = {:.4} s: position ({:.2}, {:.2}, {:.2}) mm, velocity ({:.1}, {:.1}, {:.1}) mm/s, {}",
            last.t_ref_s,
            p.x,
            p.y,
            p.z,
            v.x,
            v.y,
            v.z,
            last.status.name()
        );
    }
    if position_mm > 1.0 {
        return Err(format!("the loop did not track the spots: {position_mm:.3} mm RMS").into());
    }
    Ok(())
}
