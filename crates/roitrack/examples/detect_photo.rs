//! Find, identify and measure a circle grid in a photograph: the work of `roitrack detect`, as a library call.
//!
//! ```sh
//! cargo run --release -p roitrack --example detect_photo            # a synthetic photograph, checked against its truth
//! cargo run --release -p roitrack --example detect_photo -- CAMERA.yaml TARGET.csv PHOTO.jpg   # your own
//! ```
//!
//! Without arguments the photograph is rendered by roitrack's photo simulator (a hexagonal grid of dark circles on
//! paper, tilted, under uneven light with a shadow, clutter around, noise), so the pose found can be checked against
//! the truth. With arguments it reads your camera file, target file and photograph.

use roitrack::core::target::{CircleGrid, GridLayout};
use roitrack::detect::{PhotoOptions, detect_target};
use roitrack::nalgebra::{Rotation3, Vector3};
use roitrack::sim::photo::{PhotoScene, render_photo};
use roitrack::{CameraModel, Target};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let [camera, target, photo] = args.as_slice() {
        let camera = roitrack::formats::read_camera_yaml(camera)?;
        let target = roitrack::formats::read_target_csv(target)?;
        let frame = roitrack::formats::read_frame(photo)?;
        roitrack::formats::check_frame_size(&frame, &camera, photo)?;
        let found = detect_target(&camera, &target, &frame, &PhotoOptions::default())?;
        println!(
            "{} of {} points ({} blobs), rms {:.3} px, ambiguous {}, target at {:.4?} m",
            found.points.len(),
            target.len(),
            found.polarity.name(),
            found.reprojection_rms_px,
            found.ambiguous,
            found.state.cam_t_obj_m.as_slice()
        );
        return Ok(());
    }
    // A 10 x 14 hexagonal grid (70 circles, 12 mm apart, 8 mm across) 0.5 m away, turned 35° and 20° about two axes.
    let target = Target::circle_grid(&CircleGrid {
        rows: 10,
        cols: 14,
        spacing_m: 0.012,
        diameter_m: 0.008,
        layout: GridLayout::Hexagonal,
    })?;
    let camera = CameraModel::canonical();
    let tilt = Rotation3::from_euler_angles(35f64.to_radians(), 20f64.to_radians(), 0.3);
    let scene = PhotoScene::facing(camera.clone(), target.clone(), 0.5, tilt)
        .harsh()
        .with_seed(3);
    let photo = render_photo(&scene)?;
    let found = detect_target(&camera, &target, &photo.frame, &PhotoOptions::default())?;
    // The centres against the truth (a hexagonal grid of even width looks the same turned half a turn: compare with
    // the labelling found, which the pose follows).
    let mut worst_px = 0.0f64;
    for point in &found.points {
        let index = target.index_of(point.id).ok_or("unknown id")?;
        let projected = camera
            .raw_pixel_from_cam(
                &found
                    .state
                    .point_in_cam_at(&target.points()[index].point_in_obj_m, 0.0),
            )
            .ok_or("behind the camera")?;
        worst_px = worst_px.max((projected - point.centre_px).norm());
    }
    // The grid's centre is where it is whichever way round it was labelled.
    let centre_in_obj = target
        .points()
        .iter()
        .map(|p| p.point_in_obj_m)
        .sum::<Vector3<f64>>()
        / target.len() as f64;
    let truth_centre = scene.cam_r_obj * centre_in_obj + scene.cam_t_obj_m;
    let found_centre = found.state.cam_r_obj * centre_in_obj + found.state.cam_t_obj_m;
    println!(
        "{} of {} circles among {} {} blobs; reprojection rms {:.3} px (worst {:.3} px); ambiguous {}",
        found.points.len(),
        target.len(),
        found.blobs.len(),
        found.polarity.name(),
        found.reprojection_rms_px,
        worst_px,
        found.ambiguous
    );
    let error_mm = 1e3 * (found_centre - truth_centre).norm();
    println!("grid centre {error_mm:.3} mm from the truth");
    if found.points.len() < target.len() * 9 / 10 || error_mm > 1.0 {
        return Err("the grid was not found as it should be".into());
    }
    Ok(())
}
