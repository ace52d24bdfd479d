//! The background under a blob as a plane: the least-squares plane through the pixels around it that belong to the
//! background. Photographs' outline centres (`photo/centre.rs`, through a ring around the blob) and the frame
//! tracker's windows (`window.rs`, through a window's border) fit it here, each choosing its pixels its own way.

/// The least-squares plane `[a, b, c]` (`a + b x + c y`) through the `pixels` `(x, y, value)`, from their centred
/// moments (one pass over raw sums). Their rank decides what they determine: a plane, a slope along one line (the
/// pixels of one row or column: the plane's other slope is unknown and taken as 0, rather than computed from
/// round-off), or, for one pixel, a level. `None` without pixels.
///
/// ```
/// use roitrack_image::background::fit_plane;
///
/// let grid = (0..25).map(|k| (f64::from(k % 5) - 2.0, f64::from(k / 5) - 2.0));
/// let pixels = grid.map(|(x, y)| (x, y, 100.0 + 3.0 * x - y));
/// let [a, b, c] = fit_plane(pixels).unwrap();
/// assert!((a - 100.0).abs() < 1e-12 && (b - 3.0).abs() < 1e-12 && (c + 1.0).abs() < 1e-12);
/// // One row: its slope, none across it.
/// assert_eq!(fit_plane([(0.0, 0.0, 1.0), (1.0, 0.0, 2.0)]), Some([1.0, 1.0, 0.0]));
/// assert_eq!(fit_plane([]), None);
/// ```
pub fn fit_plane(pixels: impl IntoIterator<Item = (f64, f64, f64)>) -> Option<[f64; 3]> {
    let mut sums = [0.0f64; 9];
    for (x, y, v) in pixels {
        for (sum, term) in sums
            .iter_mut()
            .zip([1.0, x, y, v, x * x, y * y, x * y, x * v, y * v])
        {
            *sum += term;
        }
    }
    let [count, sx, sy, sv, sxx, syy, sxy, sxv, syv] = sums;
    if count == 0.0 {
        return None;
    }
    let (mx, my, mv) = (sx / count, sy / count, sv / count);
    let (sxx, syy, sxy) = (sxx - sx * mx, syy - sy * my, sxy - sx * my);
    let (sxv, syv) = (sxv - sx * mv, syv - sy * mv);
    let det = sxx * syy - sxy * sxy;
    // Pixels sit on whole-pixel coordinates: spreads below a thousandth of a pixel squared are zero.
    let along = |dx: f64, dy: f64| {
        let g = (sxv * dx + syv * dy) / (sxx * dx * dx + 2.0 * sxy * dx * dy + syy * dy * dy);
        (g * dx, g * dy)
    };
    let (b, c) = if sxx > 1e-3 && syy > 1e-3 && det > 1e-6 * sxx * syy {
        ((syy * sxv - sxy * syv) / det, (sxx * syv - sxy * sxv) / det)
    } else if sxx >= syy && sxx > 1e-3 {
        // Along a line: the slope along its direction, none across it.
        along(1.0, sxy / sxx)
    } else if syy > 1e-3 {
        along(sxy / syy, 1.0)
    } else {
        (0.0, 0.0)
    };
    Some([mv - b * mx - c * my, b, c])
}
