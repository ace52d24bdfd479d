//! `--polarity auto` on a frame where the likelier polarity is the wrong one (auto-polarity speed): dark circles on
//! paper among bright specular glints outdoors. The wrong polarity's blobs (the glints) hold many small chance
//! lattices, whose placements on a large grid were verified one by one before the right polarity was tried (8,848
//! hypotheses, 300 times the right polarity's work). The checks count work, not time: which polarities went through
//! identification, whose blobs' centres were measured, and how many hypotheses were verified.

use nalgebra::{Rotation3, Vector3};
use roitrack_core::target::{CircleGrid, GridLayout};
use roitrack_core::{CameraModel, Target};
use roitrack_detect::detect_target;
use roitrack_detect::photo::{PhotoOptions, PolarityChoice, likely_polarity};
use roitrack_image::Polarity;
use roitrack_sim::glints::add_glints;
use roitrack_sim::photo::{PhotoScene, render_photo};

#[test]
fn auto_identifies_the_right_polarity_first_among_glints() {
    let camera = CameraModel::canonical();
    let target = Target::circle_grid(&CircleGrid {
        rows: 8,
        cols: 10,
        spacing_m: 0.025,
        diameter_m: 0.015,
        layout: GridLayout::Square,
    })
    .unwrap();
    let tilt = Rotation3::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians());
    for seed in [5, 6] {
        let scene = PhotoScene::facing(camera.clone(), target.clone(), 1.2, tilt)
            .harsh()
            .with_seed(seed);
        let mut rendered = render_photo(&scene).unwrap();
        add_glints(&mut rendered, 1000, seed);
        let frame = rendered.frame;
        // The scene is what it is meant to be: the glints outvote the print.
        assert_eq!(likely_polarity(&frame), Polarity::Bright, "seed {seed}");
        let dark = detect_target(
            &camera,
            &target,
            &frame,
            &PhotoOptions {
                polarity: PolarityChoice::Dark,
                ..PhotoOptions::default()
            },
        )
        .unwrap();
        let auto = detect_target(&camera, &target, &frame, &PhotoOptions::default()).unwrap();
        assert_eq!(auto.points, dark.points, "seed {seed}");
        assert_eq!(auto.polarity, Polarity::Dark);
        // The glints' blobs were detected but never identified: the right polarity's work only.
        assert_eq!(auto.polarities_tried, vec![Polarity::Dark], "seed {seed}");
        assert_eq!(auto.hypotheses, dark.hypotheses, "seed {seed}");
        // The glints were thresholded, ranked below the print by their lattices' growth, and their centres never
        // measured.
        assert_eq!(
            auto.polarities_measured,
            vec![Polarity::Dark],
            "seed {seed}"
        );
    }
}

#[test]
fn auto_takes_a_right_guess_without_looking_at_the_other_polarity() {
    // Dark circles on paper, no glints: the guess is dark, and the dark blobs hold the whole grid.
    let camera = CameraModel::canonical();
    let target = Target::circle_grid(&CircleGrid {
        rows: 6,
        cols: 7,
        spacing_m: 0.03,
        diameter_m: 0.018,
        layout: GridLayout::Square,
    })
    .unwrap();
    let scene = PhotoScene::facing(camera.clone(), target.clone(), 1.0, Rotation3::identity())
        .harsh()
        .with_seed(2);
    let frame = render_photo(&scene).unwrap().frame;
    assert_eq!(likely_polarity(&frame), Polarity::Dark);
    let auto = detect_target(&camera, &target, &frame, &PhotoOptions::default()).unwrap();
    assert_eq!(auto.polarities_tried, vec![Polarity::Dark]);
    assert_eq!(auto.polarities_measured, vec![Polarity::Dark]);
    assert_eq!(auto.points.len(), 42);
}
