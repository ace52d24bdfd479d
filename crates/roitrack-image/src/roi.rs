//! Regions of interest: rectangles of whole pixels on the sensor ([`Roi`]), and the pixels a camera read in one with
//! the time it exposed them ([`RoiImage`]): the one ROI type of cameras, recordings and the real-time loop.

/// A region of interest: `width` x `height` pixels whose top-left pixel is (`x0`, `y0`) (column, row).
///
/// ```
/// use roitrack_image::Roi;
/// // A 24 x 24 ROI centred on (100.2, 50.7) of a 1024 x 1024 sensor.
/// let roi = Roi::centred(100.2, 50.7, 24, 1024, 1024).unwrap();
/// assert_eq!(roi, Roi::new(89, 39, 24, 24));
/// assert!(roi.contains(100.2, 50.7));
/// ```
///
/// Pixel (i, j) has its centre at image coordinates (u, v) = (i, j) and covers [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5]
/// (the convention of [`roitrack_core::CameraModel`]). An ROI's pixels are stored row-major: pixel (x0 + i, y0 + j) at
/// index `j * width + i`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Roi {
    /// Its first column on the sensor.
    pub x0: u32,
    /// Its first row on the sensor.
    pub y0: u32,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

impl Roi {
    /// The window of `width` x `height` pixels from column `x0` and row `y0`.
    pub fn new(x0: u32, y0: u32, width: u32, height: u32) -> Self {
        Self {
            x0,
            y0,
            width,
            height,
        }
    }

    /// The whole sensor as an ROI.
    pub fn full(width: u32, height: u32) -> Self {
        Self::new(0, 0, width, height)
    }

    /// An ROI of `size` x `size` pixels centred (to the nearest pixel) on the image point (`u_px`, `v_px`), shifted
    /// as little as needed to lie inside a `sensor_w` x `sensor_h` sensor. `None` if the sensor is smaller than the
    /// ROI, `size` is 0, or the point is not finite.
    ///
    /// For an even size the point falls within half a pixel of the ROI's centre (the corner shared by its four middle
    /// pixels); for an odd size within half a pixel of its middle pixel's centre.
    pub fn centred(u_px: f64, v_px: f64, size: u32, sensor_w: u32, sensor_h: u32) -> Option<Roi> {
        if size == 0 || size > sensor_w || size > sensor_h || !u_px.is_finite() || !v_px.is_finite()
        {
            return None;
        }
        // The ROI's centre in image coordinates is x0 + (size - 1) / 2.
        let half = f64::from(size - 1) / 2.0;
        let place = |p: f64, sensor: u32| -> u32 {
            let max = f64::from(sensor - size);
            (p - half).round().clamp(0.0, max) as u32
        };
        Some(Roi::new(
            place(u_px, sensor_w),
            place(v_px, sensor_h),
            size,
            size,
        ))
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether it holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// One past the last column.
    pub fn x_end(&self) -> u32 {
        self.x0 + self.width
    }

    /// One past the last row.
    pub fn y_end(&self) -> u32 {
        self.y0 + self.height
    }

    /// Whether the image point (`u_px`, `v_px`) lies on the ROI's pixels, i.e. in
    /// [x0 - 0.5, x0 + width - 0.5) x [y0 - 0.5, y0 + height - 0.5).
    pub fn contains(&self, u_px: f64, v_px: f64) -> bool {
        let (x0, y0) = (f64::from(self.x0) - 0.5, f64::from(self.y0) - 0.5);
        u_px >= x0
            && v_px >= y0
            && u_px < x0 + f64::from(self.width)
            && v_px < y0 + f64::from(self.height)
    }

    /// Whether pixel (column `i`, row `j`) of the sensor belongs to the ROI.
    pub fn contains_pixel(&self, i: u32, j: u32) -> bool {
        i >= self.x0 && j >= self.y0 && i < self.x_end() && j < self.y_end()
    }

    /// Whether the ROI lies entirely on a `sensor_w` x `sensor_h` sensor.
    pub fn fits_in(&self, sensor_w: u32, sensor_h: u32) -> bool {
        self.x_end() <= sensor_w && self.y_end() <= sensor_h
    }

    /// Index in the ROI's buffer of sensor pixel (`i`, `j`), if it belongs to the ROI.
    pub fn index_of(&self, i: u32, j: u32) -> Option<usize> {
        self.contains_pixel(i, j)
            .then(|| (j - self.y0) as usize * self.width as usize + (i - self.x0) as usize)
    }

    /// Sensor pixel (column, row) at `index` of the ROI's buffer.
    pub fn pixel_at(&self, index: usize) -> (u32, u32) {
        let w = self.width as usize;
        (self.x0 + (index % w) as u32, self.y0 + (index / w) as u32)
    }

    /// Copies the ROI out of a row-major full frame `frame_width` pixels wide.
    ///
    /// # Panics
    /// If the ROI does not lie inside the frame or `out` is not `self.len()` long.
    pub fn crop_from(&self, frame: &[u16], frame_width: u32, out: &mut [u16]) {
        assert_eq!(out.len(), self.len(), "output buffer length");
        assert!(self.x_end() <= frame_width, "ROI beyond the frame's width");
        let (fw, w) = (frame_width as usize, self.width as usize);
        for (j, row) in out.chunks_exact_mut(w.max(1)).enumerate() {
            let start = (self.y0 as usize + j) * fw + self.x0 as usize;
            row.copy_from_slice(&frame[start..start + w]);
        }
    }
}

/// The pixels a camera read in one ROI, with when and where: what a [`crate::RoiCamera`] fills, what a ROI recording
/// holds, and what the real-time loop centroids.
///
/// ```
/// use roitrack_image::{Roi, RoiImage};
/// let mut image = RoiImage::with_capacity(64 * 64);
/// image.set(2.5e-3, 7, Roi::new(100, 200, 24, 24), 8);
/// assert_eq!(image.pixels.len(), 24 * 24);
/// assert!(image.is_consistent());
/// ```
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RoiImage {
    /// Mid-exposure time of the ROI's first row (s): of every row, but for a rolling shutter, whose row `y0 + k` is
    /// exposed `k` line delays later (see [`roitrack_core::TimeModel`]).
    pub t_s: f64,
    /// Id of the target point the ROI was placed on.
    pub point_id: u32,
    /// Where the ROI lies on the sensor.
    pub roi: Roi,
    /// Bits per pixel value (8 to 16): values are below `2^bit_depth`.
    pub bit_depth: u8,
    /// Row-major, `roi.len()` values.
    pub pixels: Vec<u16>,
}

impl RoiImage {
    /// Whether the pixel buffer holds the ROI's pixels (one value per pixel, at least one pixel).
    pub fn is_consistent(&self) -> bool {
        !self.roi.is_empty() && self.pixels.len() == self.roi.len()
    }

    /// An empty image whose pixel buffer holds `capacity` values without growing: grabbing ROIs up to that size into
    /// it never allocates.
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            pixels: Vec::with_capacity(capacity),
            ..Self::default()
        }
    }

    /// Sets time, point, place and depth, and sizes the pixel buffer to the ROI (zeros where it grew; no allocation
    /// within its capacity).
    pub fn set(&mut self, t_s: f64, point_id: u32, roi: Roi, bit_depth: u8) {
        self.t_s = t_s;
        self.point_id = point_id;
        self.roi = roi;
        self.bit_depth = bit_depth;
        self.pixels.resize(roi.len(), 0);
    }

    /// Keeps only the part of the image within `roi` (a camera that reads a fixed window larger than the ROI asked
    /// for: a neighbouring blob in the rest of the window would make the blob's ROI refused), in place, without
    /// allocating; its time becomes that of its new first row by `time` (later, for a rolling shutter). Returns
    /// whether anything was cut; an image that `roi` does not overlap, or that is not consistent, is left whole.
    ///
    /// ```
    /// use roitrack_core::TimeModel;
    /// use roitrack_image::{Roi, RoiImage};
    /// let mut image = RoiImage::default();
    /// image.set(1.0, 7, Roi::new(10, 20, 4, 3), 8);
    /// image.pixels = (0..12).collect();
    /// assert!(image.crop_to(&Roi::new(11, 21, 2, 5), &TimeModel::default()));
    /// assert_eq!((image.roi, image.pixels.clone(), image.t_s), (Roi::new(11, 21, 2, 2), vec![5, 6, 9, 10], 1.0));
    /// ```
    pub fn crop_to(&mut self, roi: &Roi, time: &roitrack_core::TimeModel) -> bool {
        if !self.is_consistent() {
            return false;
        }
        let have = self.roi;
        let (x0, y0) = (have.x0.max(roi.x0), have.y0.max(roi.y0));
        let x1 = (have.x0 + have.width).min(roi.x0.saturating_add(roi.width));
        let y1 = (have.y0 + have.height).min(roi.y0.saturating_add(roi.height));
        if x1 <= x0 || y1 <= y0 || (x1 - x0, y1 - y0) == (have.width, have.height) {
            return false;
        }
        let (width, height) = ((x1 - x0) as usize, (y1 - y0) as usize);
        let (dx, dy) = ((x0 - have.x0) as usize, (y0 - have.y0) as usize);
        let stride = have.width as usize;
        // Row by row towards the front: a row's destination never lies after its source.
        for row in 0..height {
            let from = (dy + row) * stride + dx;
            self.pixels.copy_within(from..from + width, row * width);
        }
        self.pixels.truncate(width * height);
        self.t_s = time.blob_time_s(self.t_s, dy as f64);
        self.roi = Roi::new(x0, y0, width as u32, height as u32);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A window of `w` x `h` at (x0, y0) whose pixel at sensor (i, j) holds `1000 * j + i`: what a crop keeps is
    /// checked pixel by pixel against where it lies on the sensor.
    fn window(x0: u32, y0: u32, w: u32, h: u32) -> RoiImage {
        let mut image = RoiImage::default();
        image.set(2.0, 3, Roi::new(x0, y0, w, h), 16);
        for (k, p) in image.pixels.iter_mut().enumerate() {
            let (i, j) = (x0 + k as u32 % w, y0 + k as u32 / w);
            *p = (1000 * j + i) as u16;
        }
        image
    }

    #[test]
    fn a_crop_keeps_the_pixels_of_the_overlap_and_the_time_of_its_first_row() {
        let rolling = roitrack_core::TimeModel {
            readout: roitrack_core::Readout::RollingShutter { line_delay_s: 1e-5 },
            exposure_s: 1e-4,
        };
        // Inside, across an edge, and the window whole: the overlap, its pixels where they lie, its first row's time.
        for (asked, kept) in [
            (Roi::new(13, 24, 5, 4), Roi::new(13, 24, 5, 4)),
            (Roi::new(5, 30, 10, 40), Roi::new(10, 30, 5, 10)),
            (Roi::new(0, 0, 100, 100), Roi::new(10, 20, 20, 20)),
        ] {
            let mut image = window(10, 20, 20, 20);
            let capacity = image.pixels.capacity();
            let cut = image.crop_to(&asked, &rolling);
            assert_eq!(
                (cut, image.roi),
                (kept != Roi::new(10, 20, 20, 20), kept),
                "{asked:?}"
            );
            let expected: Vec<u16> = (kept.y0..kept.y0 + kept.height)
                .flat_map(|j| (kept.x0..kept.x0 + kept.width).map(move |i| (1000 * j + i) as u16))
                .collect();
            assert_eq!(image.pixels, expected, "{asked:?}");
            assert!((image.t_s - (2.0 + f64::from(kept.y0 - 20) * 1e-5)).abs() < 1e-15);
            assert_eq!(image.pixels.capacity(), capacity, "no allocation");
        }
        // No overlap: left whole.
        let mut image = window(10, 20, 20, 20);
        assert!(!image.crop_to(&Roi::new(40, 20, 8, 8), &rolling));
        assert_eq!(
            (image.roi, image.pixels.len(), image.t_s),
            (Roi::new(10, 20, 20, 20), 400, 2.0)
        );
    }

    #[test]
    fn centred_puts_the_point_in_the_middle() {
        let r = Roi::centred(100.2, 50.7, 24, 1024, 1024).unwrap();
        assert_eq!(r, Roi::new(89, 39, 24, 24));
        // Centre of the ROI: x0 + 11.5.
        assert!((f64::from(r.x0) + 11.5 - 100.2).abs() <= 0.5);
        assert!((f64::from(r.y0) + 11.5 - 50.7).abs() <= 0.5);
        let odd = Roi::centred(100.2, 50.7, 25, 1024, 1024).unwrap();
        assert_eq!((odd.x0 + 12, odd.y0 + 12), (100, 51));
        assert!(r.contains(100.2, 50.7) && odd.contains(100.2, 50.7));
    }

    #[test]
    fn centred_clamps_to_the_sensor() {
        assert_eq!(
            Roi::centred(-40.0, 3.0, 24, 1024, 768),
            Some(Roi::new(0, 0, 24, 24))
        );
        assert_eq!(
            Roi::centred(2000.0, 767.4, 24, 1024, 768),
            Some(Roi::new(1000, 744, 24, 24))
        );
        assert_eq!(Roi::centred(5.0, 5.0, 24, 20, 768), None);
        assert_eq!(Roi::centred(f64::NAN, 5.0, 24, 1024, 768), None);
        assert_eq!(
            Roi::centred(5.0, 5.0, 24, 24, 24),
            Some(Roi::new(0, 0, 24, 24))
        );
    }

    #[test]
    fn pixel_bookkeeping() {
        let r = Roi::new(10, 20, 4, 3);
        assert_eq!(r.len(), 12);
        assert!(r.contains(9.5, 19.5) && !r.contains(13.5, 20.0) && r.contains(13.49, 22.49));
        assert_eq!(r.index_of(11, 22), Some(9));
        assert_eq!(r.pixel_at(9), (11, 22));
        assert_eq!(r.index_of(14, 22), None);
        let frame: Vec<u16> = (0..100 * 100).map(|k| k as u16).collect();
        let mut out = vec![0; r.len()];
        r.crop_from(&frame, 100, &mut out);
        assert_eq!(out[9], 22 * 100 + 11);
    }
}
