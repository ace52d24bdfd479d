//! Full frames: a whole sensor's pixels, in a buffer the caller owns and reuses.

/// A full frame: row-major pixels of a `width` x `height` sensor with the frame's time.
///
/// ```
/// use roitrack_image::Frame;
/// let mut frame = Frame::new(640, 480, 8);
/// assert_eq!(frame.pixels.len(), 640 * 480);
/// let i = frame.index(10, 2);
/// frame.pixels[i] = 200;
/// assert_eq!(frame.pixels[2 * 640 + 10], 200);
/// ```
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Frame {
    /// Mid-exposure time (s); for a rolling shutter, that of row 0 (see [`roitrack_core::TimeModel`]).
    pub t_s: f64,
    /// Columns (px).
    pub width: u32,
    /// Rows (px).
    pub height: u32,
    /// Bits per pixel value (8 to 16).
    pub bit_depth: u8,
    /// Row-major, `width * height` values.
    pub pixels: Vec<u16>,
}

impl Frame {
    /// A black frame at time 0.
    pub fn new(width: u32, height: u32, bit_depth: u8) -> Self {
        let mut frame = Self::default();
        frame.resize(width, height, bit_depth);
        frame
    }

    /// Sets the size and depth, growing the buffer only when it is too small (so a frame grabbed again and again
    /// into the same buffer allocates once).
    pub fn resize(&mut self, width: u32, height: u32, bit_depth: u8) {
        self.width = width;
        self.height = height;
        self.bit_depth = bit_depth;
        self.pixels.resize(width as usize * height as usize, 0);
    }

    /// Index in [`Self::pixels`] of pixel (column `i`, row `j`).
    pub fn index(&self, i: u32, j: u32) -> usize {
        j as usize * self.width as usize + i as usize
    }
}
