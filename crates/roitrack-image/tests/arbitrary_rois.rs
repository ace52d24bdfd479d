//! `measure_blob` on arbitrary pixels: it answers (a centroid inside the ROI or a rejection), never panics.

use proptest::prelude::*;
use roitrack_image::{CentroidOptions, Roi, measure_blob};

/// An ROI of 1 to 64 pixels a side and its pixels: noise, or a few bright rectangles and spots on a background, so that
/// the component walk and the symmetry check see blobs of every shape.
fn roi_and_pixels() -> impl Strategy<Value = (Roi, Vec<u16>)> {
    (1u32..=64, 1u32..=64).prop_flat_map(|(w, h)| {
        let n = (w * h) as usize;
        let noise = proptest::collection::vec(any::<u16>(), n).boxed();
        let shapes = (
            0u16..40,
            proptest::collection::vec((0..w, 0..h, 1..=w, 1..=h, 50u16..=255), 1..4),
        )
            .prop_map(move |(background, rects)| {
                let mut pixels = vec![background; n];
                for (x, y, rw, rh, value) in rects {
                    for j in y..(y + rh).min(h) {
                        for i in x..(x + rw).min(w) {
                            pixels[(j * w + i) as usize] = value;
                        }
                    }
                }
                pixels
            })
            .boxed();
        (Just(Roi::new(3, 5, w, h)), prop_oneof![noise, shapes])
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    #[test]
    fn measure_blob_answers_on_any_roi((roi, pixels) in roi_and_pixels()) {
        for opts in [
            CentroidOptions::default(),
            CentroidOptions::binary(),
            CentroidOptions { symmetry: None, ..CentroidOptions::default() },
        ] {
            if let Ok(c) = measure_blob(&pixels, &roi, &opts) {
                prop_assert!(c.u_px.is_finite() && c.v_px.is_finite());
                prop_assert!(c.u_px >= f64::from(roi.x0) && c.u_px <= f64::from(roi.x_end()));
                prop_assert!(c.v_px >= f64::from(roi.y0) && c.v_px <= f64::from(roi.y_end()));
            }
        }
    }
}
