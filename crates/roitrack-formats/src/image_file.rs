//! Image files in, [`Frame`]s out: PNG, JPEG, PGM/PPM (PNM, PAM) and TIFF, 8 or 16 bits, grey or colour.
//!
//! A full frame is what `roitrack_detect::find_target` looks for the target in. Colour is turned into grey with the
//! luma weights of ITU-R BT.601 (those of OpenCV's `cvtColor(..., COLOR_RGB2GRAY)`): `Y = 0.299 R + 0.587 G +
//! 0.114 B`, rounded to the nearest integer. An alpha channel is dropped (not composited). 16-bit files keep their
//! 16 bits (`bit_depth` 16); everything else is 8 bits.

use std::io::Read;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use image::codecs::png::PngEncoder;
use image::error::{ImageError, UnsupportedErrorKind};
use image::{DynamicImage, ImageEncoder, ImageFormat};
use roitrack_core::CameraModel;
use roitrack_image::Frame;

use crate::limits::{MAX_IMAGE_FILE_BYTES, check_file};
use crate::{AtomicFile, FormatError};

/// The image formats [`read_frame`] and [`decode_frame`] read, as said in their errors.
pub const FRAME_IMAGE_FORMATS: &str = "PNG, JPEG, PGM/PPM or TIFF";

/// Reads an image file into a grey [`Frame`] at time 0 (see [`decode_frame`] for what is accepted).
///
/// ```
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("frame.png");
/// // A 3 x 2 RGB image: the first pixel pure red.
/// let mut rgb = image::RgbImage::new(3, 2);
/// rgb.put_pixel(0, 0, image::Rgb([255, 0, 0]));
/// rgb.save(&path)?;
///
/// let frame = roitrack_formats::read_frame(&path)?;
/// assert_eq!((frame.width, frame.height, frame.bit_depth), (3, 2, 8));
/// assert_eq!(frame.pixels[0], 76); // 0.299 * 255 = 76.2
/// assert_eq!(frame.t_s, 0.0);
///
/// let missing = roitrack_formats::read_frame(dir.path().join("nope.png")).unwrap_err();
/// assert!(missing.to_string().contains("nope.png"));
/// # Ok(())
/// # }
/// ```
pub fn read_frame(path: impl AsRef<Path>) -> Result<Frame, FormatError> {
    let path = path.as_ref();
    let mut bytes = Vec::new();
    read_image_file(path, &mut bytes)?;
    decode_frame(&bytes, path)
}

/// Reads the image file `path` into `bytes` (cleared first, its capacity reused), looking before leaping: a folder or
/// a file larger than [`MAX_IMAGE_FILE_BYTES`] is refused before it is read, and a file whose first bytes (or, failing
/// them, whose extension) name no format roitrack reads is refused before the rest is read.
pub(crate) fn read_image_file(path: &Path, bytes: &mut Vec<u8>) -> Result<(), FormatError> {
    const WHAT: &str = "an image file";
    bytes.clear();
    let file = std::fs::File::open(path).map_err(|e| read_error(path, e))?;
    check_file(&file, path, WHAT, Some(MAX_IMAGE_FILE_BYTES))?;
    // Bounded for devices and pipes too, which have no size to check beforehand.
    let mut reader = file.take(MAX_IMAGE_FILE_BYTES + 1);
    (&mut reader)
        .take(64)
        .read_to_end(bytes)
        .map_err(|e| read_error(path, e))?;
    if !bytes.is_empty() {
        let format = choose_format(bytes, path)?;
        // Every format read here has magic bytes: content without them is no image, whatever its extension says.
        if image::guess_format(bytes).is_err() {
            return Err(FormatError::new(
                path,
                format!(
                    "not a {name} image, as its extension says, nor any other known image format (expected \
                     {FRAME_IMAGE_FORMATS}): it starts with {start:?}",
                    name = format_name(format),
                    start = String::from_utf8_lossy(&bytes[..bytes.len().min(16)])
                ),
            ));
        }
    }
    reader.read_to_end(bytes).map_err(|e| read_error(path, e))?;
    if bytes.len() as u64 > MAX_IMAGE_FILE_BYTES {
        return Err(FormatError::new(
            path,
            format!(
                "more than {}: {WHAT} is at most that large",
                crate::limits::format_bytes(MAX_IMAGE_FILE_BYTES)
            ),
        ));
    }
    Ok(())
}

/// The error of a frame file that cannot be read (the same for [`read_frame`] and the frame sources).
pub(crate) fn read_error(path: &Path, error: std::io::Error) -> FormatError {
    FormatError::io(path, "cannot read", error)
}

/// Decodes the bytes of an image file into a grey [`Frame`] at time 0; `path` names it in errors (and, when the
/// content does not say which format it is, its extension is tried).
///
/// Reads PNG, JPEG, PGM/PPM/PBM/PAM and TIFF; grey, grey + alpha, RGB and RGBA; 8 and 16 bits (PNG's 1, 2 and 4-bit
/// greys are expanded to 8 bits, a PNM `maxval` other than 255 or 65535 is scaled by the decoder to the full 8 or
/// 16 bits). Colour becomes grey by the BT.601 luma `0.299 R + 0.587 G + 0.114 B`, rounded; alpha is dropped.
/// `bit_depth` is 16 for 16-bit files, else 8.
///
/// Refuses, naming the file: an empty file, an unknown format or one not listed above (GIF, BMP, ...), a truncated
/// or corrupt image (with the decoder's message), an image of zero width or height, floating-point images, and
/// images whose decoding would need more than 512 MiB. Never panics.
pub fn decode_frame(bytes: &[u8], path: impl AsRef<Path>) -> Result<Frame, FormatError> {
    let mut frame = Frame::default();
    decode_frame_into(bytes, path.as_ref(), &mut frame)?;
    Ok(frame)
}

/// [`decode_frame`] into a frame the caller owns, reusing its pixel buffer (so a sequence of frames decoded into the
/// same `Frame` does not allocate a pixel buffer per frame). `frame.t_s` is set to 0.
pub(crate) fn decode_frame_into(
    bytes: &[u8],
    path: &Path,
    frame: &mut Frame,
) -> Result<(), FormatError> {
    if bytes.is_empty() {
        return Err(FormatError::new(
            path,
            format!("empty file: not an image (expected {FRAME_IMAGE_FORMATS})"),
        ));
    }
    let format = choose_format(bytes, path)?;
    // The decoders are third-party code fed with untrusted bytes: should one of them panic, the caller gets an error
    // naming the file instead of a crash. (A fuzz target still sees such a panic: libFuzzer's hook aborts first.)
    let decoded = catch_unwind(AssertUnwindSafe(|| {
        image::load_from_memory_with_format(bytes, format)
    }))
    .map_err(|_| {
        FormatError::new(
            path,
            format!(
                "cannot decode as {}: the decoder failed on this file (internal error)",
                format_name(format)
            ),
        )
    })?;
    let image = decoded.map_err(|e| {
        if image::guess_format(bytes).is_ok() {
            decode_error(path, format, e)
        } else {
            // Only the extension named the format, and the content is not of it.
            FormatError::new(
                path,
                format!(
                    "not a {name} image, as its extension says, nor any other known image format \
                     (expected {FRAME_IMAGE_FORMATS}): {e}",
                    name = format_name(format)
                ),
            )
        }
    })?;
    frame_from_image(image, path, frame)
}

/// Checks that a frame has the image size of the camera model it is to be used with.
///
/// ```
/// use roitrack_core::CameraModel;
/// use roitrack_image::Frame;
///
/// let camera = CameraModel::canonical();
/// let frame = Frame::new(camera.width_px, camera.height_px, 8);
/// roitrack_formats::check_frame_size(&frame, &camera, "frame.png").unwrap();
/// let e = roitrack_formats::check_frame_size(&Frame::new(64, 48, 8), &camera, "frame.png").unwrap_err();
/// assert!(e.to_string().starts_with("frame.png: image is 64 x 48 px, the camera file says "));
/// ```
pub fn check_frame_size(
    frame: &Frame,
    camera: &CameraModel,
    path: impl AsRef<Path>,
) -> Result<(), FormatError> {
    if (frame.width, frame.height) == (camera.width_px, camera.height_px) {
        return Ok(());
    }
    Err(FormatError::new(
        path,
        format!(
            "image is {} x {} px, the camera file says {} x {}",
            frame.width, frame.height, camera.width_px, camera.height_px
        ),
    ))
}

/// Writes `frame` as a grey PNG at `path`, atomically (through [`AtomicFile`]: the file appears complete or not at all).
///
/// A frame of `bit_depth` 8 or less becomes an 8-bit PNG, a deeper one a 16-bit PNG; the values are written as they
/// are, not scaled (a 12-bit frame's 4095 stays 4095, and reads back as a 16-bit frame). [`read_frame`] reads the file
/// back to the same pixels. `t_s` is not stored.
///
/// Refuses, naming the file: a frame of zero width or height, one whose pixel count is not `width * height`, a
/// `bit_depth` outside 1 to 16, a value above 255 in a frame of 8 bits or less, and the output's errors (missing
/// directory, full disk, ...).
///
/// ```
/// use roitrack_image::Frame;
///
/// # fn main() -> Result<(), roitrack_formats::FormatError> {
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("frame_00000.png");
/// let mut frame = Frame::new(4, 3, 12);
/// frame.pixels[5] = 4095;
/// roitrack_formats::write_frame_png(&path, &frame)?;
///
/// let back = roitrack_formats::read_frame(&path)?;
/// assert_eq!((back.width, back.height, back.bit_depth), (4, 3, 16));
/// assert_eq!(back.pixels, frame.pixels);
/// # Ok(())
/// # }
/// ```
pub fn write_frame_png(path: impl AsRef<Path>, frame: &Frame) -> Result<(), FormatError> {
    let path = path.as_ref();
    check_frame_buffer(frame, path, "write")?;
    let (width, height) = (frame.width, frame.height);
    let (bytes, color) = if frame.bit_depth <= 8 {
        if let Some(at) = frame.pixels.iter().position(|&v| v > 255) {
            let (column, row) = (at % width as usize, at / width as usize);
            return Err(FormatError::new(
                path,
                format!(
                    "pixel ({column}, {row}) is {}, above 255 in a frame of {} bits",
                    frame.pixels[at], frame.bit_depth
                ),
            ));
        }
        let bytes: Vec<u8> = frame.pixels.iter().map(|&v| v as u8).collect();
        (bytes, image::ColorType::L8)
    } else {
        // The encoder takes 16-bit samples in native byte order and writes them big-endian, as PNG wants.
        let bytes: Vec<u8> = frame.pixels.iter().flat_map(|v| v.to_ne_bytes()).collect();
        (bytes, image::ColorType::L16)
    };
    let mut file = AtomicFile::create(path)?;
    PngEncoder::new(&mut file)
        .write_image(&bytes, width, height, color)
        .map_err(|e| match e {
            ImageError::IoError(e) => file.write_error(e),
            other => FormatError::new(path, format!("cannot encode the PNG: {other}")),
        })?;
    file.finish()
}

/// The format to decode with: the one the content's magic bytes say if it is readable, else the extension's if that
/// is readable (the decoder then says what is wrong with the content), else an error.
fn choose_format(bytes: &[u8], path: &Path) -> Result<ImageFormat, FormatError> {
    let by_content = image::guess_format(bytes).ok();
    let by_extension = ImageFormat::from_path(path).ok();
    if let Some(format) = [by_content, by_extension]
        .into_iter()
        .flatten()
        .find(|f| f.reading_enabled())
    {
        return Ok(format);
    }
    Err(match by_content.or(by_extension) {
        Some(format) => FormatError::new(
            path,
            format!(
                "{} images are not supported (expected {FRAME_IMAGE_FORMATS})",
                format_name(format)
            ),
        ),
        None => FormatError::new(
            path,
            format!("unknown image format (expected {FRAME_IMAGE_FORMATS})"),
        ),
    })
}

fn format_name(format: ImageFormat) -> String {
    match format {
        ImageFormat::Png => "PNG".into(),
        ImageFormat::Jpeg => "JPEG".into(),
        ImageFormat::Pnm => "PNM".into(),
        ImageFormat::Tiff => "TIFF".into(),
        ImageFormat::Gif => "GIF".into(),
        ImageFormat::Bmp => "BMP".into(),
        other => format!("{other:?}").to_uppercase(),
    }
}

fn float_error(path: &Path) -> FormatError {
    FormatError::new(
        path,
        "floating-point images are not supported: roitrack reads 8-bit and 16-bit integer pixels \
         (convert the image to 16-bit integers first)",
    )
}

fn decode_error(path: &Path, format: ImageFormat, error: ImageError) -> FormatError {
    let name = format_name(format);
    match &error {
        // TIFF's SampleFormat tag: 3 is IEEE floating point.
        ImageError::Unsupported(e) if matches!(e.kind(), UnsupportedErrorKind::GenericFeature(feature) if feature.contains("IEEEFP")) => {
            float_error(path)
        }
        ImageError::Unsupported(_) => {
            FormatError::new(path, format!("unsupported {name} image: {error}"))
        }
        ImageError::Limits(_) => {
            FormatError::new(path, format!("{name} image too large to decode: {error}"))
        }
        ImageError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            FormatError::new(path, format!("truncated {name} image: {error}"))
        }
        _ => FormatError::new(
            path,
            format!("cannot decode as {name} (truncated or corrupt?): {error}"),
        ),
    }
}

/// BT.601 luma of an RGB pixel, rounded (8 or 16-bit channels alike).
fn luma(r: u16, g: u16, b: u16) -> u16 {
    // At most 0.299 + 0.587 + 0.114 = 1 times the channel maximum: the cast does not saturate (and would if it did).
    (0.299 * f64::from(r) + 0.587 * f64::from(g) + 0.114 * f64::from(b)).round() as u16
}

/// The grey frame of a decoded image, at time 0, written into `frame` (its pixel buffer reused).
fn frame_from_image(
    image: DynamicImage,
    path: &Path,
    frame: &mut Frame,
) -> Result<(), FormatError> {
    let (width, height) = (image.width(), image.height());
    if width == 0 || height == 0 {
        return Err(FormatError::new(
            path,
            format!("empty image: {width} x {height} px"),
        ));
    }
    let pixels = &mut frame.pixels;
    pixels.clear();
    let bit_depth = match image {
        DynamicImage::ImageLuma8(im) => {
            pixels.extend(im.as_raw().iter().map(|&v| u16::from(v)));
            8
        }
        DynamicImage::ImageLumaA8(im) => {
            pixels.extend(im.pixels().map(|p| u16::from(p.0[0])));
            8
        }
        DynamicImage::ImageRgb8(im) => {
            pixels.extend(
                im.pixels()
                    .map(|p| luma(p.0[0].into(), p.0[1].into(), p.0[2].into())),
            );
            8
        }
        DynamicImage::ImageRgba8(im) => {
            pixels.extend(
                im.pixels()
                    .map(|p| luma(p.0[0].into(), p.0[1].into(), p.0[2].into())),
            );
            8
        }
        DynamicImage::ImageLuma16(im) => {
            // A fresh frame takes the decoder's buffer as it is; a reused one keeps its own.
            if pixels.capacity() == 0 {
                *pixels = im.into_raw();
            } else {
                pixels.extend_from_slice(im.as_raw());
            }
            16
        }
        DynamicImage::ImageLumaA16(im) => {
            pixels.extend(im.pixels().map(|p| p.0[0]));
            16
        }
        DynamicImage::ImageRgb16(im) => {
            pixels.extend(im.pixels().map(|p| luma(p.0[0], p.0[1], p.0[2])));
            16
        }
        DynamicImage::ImageRgba16(im) => {
            pixels.extend(im.pixels().map(|p| luma(p.0[0], p.0[1], p.0[2])));
            16
        }
        DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_) => {
            return Err(float_error(path));
        }
        other => {
            return Err(FormatError::new(
                path,
                format!("unsupported pixel type {:?}", other.color()),
            ));
        }
    };
    frame.t_s = 0.0;
    frame.width = width;
    frame.height = height;
    frame.bit_depth = bit_depth;
    Ok(())
}

/// Refuses a frame that cannot be written or drawn on (`doing`: what was to be done with it): empty, a pixel buffer
/// that does not match its size, or a bit depth outside 1 to 16.
pub(crate) fn check_frame_buffer(
    frame: &Frame,
    path: &Path,
    doing: &str,
) -> Result<(), FormatError> {
    let (width, height) = (frame.width, frame.height);
    if width == 0 || height == 0 {
        return Err(FormatError::new(
            path,
            format!("cannot {doing} an empty frame ({width} x {height} px)"),
        ));
    }
    if (width as usize).checked_mul(height as usize) != Some(frame.pixels.len()) {
        return Err(FormatError::new(
            path,
            format!(
                "the frame has {} pixel values for {width} x {height} px",
                frame.pixels.len()
            ),
        ));
    }
    if !(1..=16).contains(&frame.bit_depth) {
        return Err(FormatError::new(
            path,
            format!(
                "the frame's bit depth is {}, expected 1 to 16",
                frame.bit_depth
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn luma_uses_the_bt601_weights_rounded() {
        assert_eq!(luma(255, 0, 0), 76); // 76.245
        assert_eq!(luma(0, 255, 0), 150); // 149.685
        assert_eq!(luma(0, 0, 255), 29); // 29.07
        assert_eq!(luma(255, 255, 255), 255);
        assert_eq!(luma(65535, 65535, 65535), 65535);
        assert_eq!(luma(10, 20, 30), 18); // 2.99 + 11.74 + 3.42 = 18.15
        for v in [0u16, 1, 127, 128, 254, 4095, 65534] {
            assert_eq!(luma(v, v, v), v);
        }
    }

    #[test]
    fn float_images_are_refused() {
        let image = DynamicImage::ImageRgb32F(image::Rgb32FImage::new(2, 2));
        let e = frame_from_image(image, Path::new("f.tiff"), &mut Frame::default()).unwrap_err();
        assert!(e.to_string().starts_with("f.tiff: floating-point"), "{e}");
    }

    #[test]
    fn alpha_is_dropped() {
        let mut im = image::RgbaImage::new(1, 1);
        im.put_pixel(0, 0, image::Rgba([0, 255, 0, 0]));
        let mut frame = Frame::default();
        frame_from_image(DynamicImage::ImageRgba8(im), Path::new("a.png"), &mut frame).unwrap();
        assert_eq!(frame.pixels, vec![150]);
        let mut im = image::GrayAlphaImage::new(1, 1);
        im.put_pixel(0, 0, image::LumaA([200, 7]));
        frame_from_image(
            DynamicImage::ImageLumaA8(im),
            Path::new("a.png"),
            &mut frame,
        )
        .unwrap();
        assert_eq!(frame.pixels, vec![200]);
    }

    use image::{ImageBuffer, Luma, Rgb};

    /// A test pattern: distinct values in every pixel and channel.
    fn value(x: u32, y: u32, channel: u32, max: u32) -> u32 {
        (x * 37 + y * 11 + channel * 101) * (max / 255) % (max + 1)
    }

    fn grey8() -> image::GrayImage {
        ImageBuffer::from_fn(7, 5, |x, y| Luma([value(x, y, 0, 255) as u8]))
    }

    fn grey16() -> ImageBuffer<Luma<u16>, Vec<u16>> {
        ImageBuffer::from_fn(7, 5, |x, y| Luma([value(x, y, 0, 65535) as u16]))
    }

    fn rgb8() -> image::RgbImage {
        ImageBuffer::from_fn(7, 5, |x, y| {
            Rgb([0, 1, 2].map(|c| value(x, y, c, 255) as u8))
        })
    }

    fn rgb16() -> ImageBuffer<Rgb<u16>, Vec<u16>> {
        ImageBuffer::from_fn(7, 5, |x, y| {
            Rgb([0, 1, 2].map(|c| value(x, y, c, 65535) as u16))
        })
    }

    fn expected_grey(max: u32) -> Vec<u16> {
        (0..5)
            .flat_map(|y| (0..7).map(move |x| value(x, y, 0, max) as u16))
            .collect()
    }

    fn expected_rgb(max: u32) -> Vec<u16> {
        (0..5)
            .flat_map(|y| {
                (0..7).map(move |x| {
                    let [r, g, b] = [0, 1, 2].map(|c| value(x, y, c, max) as u16);
                    luma(r, g, b)
                })
            })
            .collect()
    }

    /// A binary 16-bit PGM (grey) or PPM (RGB) file: big-endian samples after the header.
    fn netpbm16(image: &DynamicImage) -> Vec<u8> {
        let (magic, samples) = match image {
            DynamicImage::ImageLuma16(im) => ("P5", im.as_raw()),
            DynamicImage::ImageRgb16(im) => ("P6", im.as_raw()),
            _ => unreachable!(),
        };
        let mut bytes =
            format!("{magic}\n{} {}\n65535\n", image.width(), image.height()).into_bytes();
        bytes.extend(samples.iter().flat_map(|v| v.to_be_bytes()));
        bytes
    }

    #[test]
    fn pgm_with_a_12_bit_maxval_is_scaled_to_16_bits() {
        let mut bytes = b"P5\n2 1\n4095\n".to_vec();
        bytes.extend([0u16, 4095].iter().flat_map(|v| v.to_be_bytes()));
        let frame = decode_frame(&bytes, "twelve.pgm").unwrap();
        assert_eq!((frame.bit_depth, frame.pixels), (16, vec![0, 65535]));
    }

    #[test]
    fn lossless_formats_read_back_in_8_and_16_bits_grey_and_rgb() {
        let dir = tempfile::tempdir().unwrap();
        for extension in ["png", "pgm", "ppm", "tif"] {
            let cases: [(&str, DynamicImage, u8, Vec<u16>); 4] = [
                ("grey8", grey8().into(), 8, expected_grey(255)),
                ("grey16", grey16().into(), 16, expected_grey(65535)),
                ("rgb8", rgb8().into(), 8, expected_rgb(255)),
                ("rgb16", rgb16().into(), 16, expected_rgb(65535)),
            ];
            for (name, image, bit_depth, pixels) in cases {
                // PGM holds grey only, PPM colour only.
                let is_rgb = name.starts_with("rgb");
                if (extension == "pgm" && is_rgb) || (extension == "ppm" && !is_rgb) {
                    continue;
                }
                let path = dir.path().join(format!("{name}.{extension}"));
                if bit_depth == 16 && extension.starts_with('p') && extension != "png" {
                    // The image crate writes 8-bit PGM/PPM only: write the 16-bit one by hand.
                    std::fs::write(&path, netpbm16(&image)).unwrap();
                } else {
                    image
                        .save(&path)
                        .unwrap_or_else(|e| panic!("{name}.{extension}: {e}"));
                }
                let frame = read_frame(&path).unwrap_or_else(|e| panic!("{e}"));
                assert_eq!((frame.width, frame.height), (7, 5), "{name}.{extension}");
                assert_eq!(frame.bit_depth, bit_depth, "{name}.{extension}");
                assert_eq!(frame.t_s, 0.0);
                assert_eq!(frame.pixels, pixels, "{name}.{extension}");
            }
        }
    }

    #[test]
    fn png_with_alpha_reads_as_grey() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("la16.png");
        let image = ImageBuffer::from_fn(3, 2, |x, y| image::LumaA([(x * 1000 + y) as u16, 5]));
        DynamicImage::ImageLumaA16(image).save(&path).unwrap();
        let frame = read_frame(&path).unwrap();
        assert_eq!(frame.bit_depth, 16);
        assert_eq!(frame.pixels, vec![0, 1000, 2000, 1, 1001, 2001]);

        let path = dir.path().join("rgba8.png");
        let image = ImageBuffer::from_pixel(2, 2, image::Rgba([255u8, 0, 0, 128]));
        DynamicImage::ImageRgba8(image).save(&path).unwrap();
        assert_eq!(read_frame(&path).unwrap().pixels, vec![76; 4]);
    }

    #[test]
    fn jpeg_reads_back_close_to_what_was_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("grey.jpg");
        DynamicImage::ImageLuma8(ImageBuffer::from_pixel(16, 8, Luma([180u8])))
            .save(&path)
            .unwrap();
        let frame = read_frame(&path).unwrap();
        assert_eq!((frame.width, frame.height, frame.bit_depth), (16, 8, 8));
        assert!(
            frame.pixels.iter().all(|&v| v.abs_diff(180) <= 2),
            "{:?}",
            frame.pixels
        );

        let path = dir.path().join("colour.jpeg");
        DynamicImage::ImageRgb8(ImageBuffer::from_pixel(16, 8, Rgb([200u8, 100, 50])))
            .save(&path)
            .unwrap();
        let frame = read_frame(&path).unwrap();
        // 0.299 * 200 + 0.587 * 100 + 0.114 * 50 = 124.2
        assert!(
            frame.pixels.iter().all(|&v| v.abs_diff(124) <= 3),
            "{:?}",
            frame.pixels
        );
    }

    #[test]
    fn the_content_decides_the_format_not_the_extension() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("really-a-png.jpg");
        DynamicImage::ImageLuma8(grey8())
            .save_with_format(&path, ImageFormat::Png)
            .unwrap();
        assert_eq!(read_frame(&path).unwrap().pixels, expected_grey(255));
        // No extension at all.
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(
            decode_frame(&bytes, "frame").unwrap().pixels,
            expected_grey(255)
        );
    }

    /// The error, checking that it names the file.
    fn error_of(path: &Path) -> String {
        let e = read_frame(path).unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with(&path.display().to_string()), "{text}");
        assert_eq!(e.path(), path);
        text
    }

    #[test]
    fn bad_files_give_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("good.png");
        DynamicImage::ImageLuma8(grey8()).save(&png).unwrap();
        let bytes = std::fs::read(&png).unwrap();

        let truncated = dir.path().join("truncated.png");
        std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
        let text = error_of(&truncated);
        assert!(text.contains("PNG"), "{text}");

        let text_file = dir.path().join("notes.png");
        std::fs::write(&text_file, "these are not pixels\n").unwrap();
        let text = error_of(&text_file);
        assert!(text.contains("not a PNG image"), "{text}");

        let empty = dir.path().join("empty.png");
        std::fs::write(&empty, "").unwrap();
        assert!(error_of(&empty).contains("empty file"));

        let missing = dir.path().join("missing.png");
        assert!(error_of(&missing).contains("cannot read"));

        let unknown = dir.path().join("data.bin");
        std::fs::write(&unknown, [7u8; 64]).unwrap();
        assert!(error_of(&unknown).contains("unknown image format"));

        let gif = dir.path().join("anim.gif");
        std::fs::write(&gif, b"GIF89a\x01\x00\x01\x00\x00\x00\x00;").unwrap();
        assert!(error_of(&gif).contains("GIF images are not supported"));

        let zero = dir.path().join("zero.pgm");
        std::fs::write(&zero, b"P5\n0 3\n255\n").unwrap();
        error_of(&zero);

        let directory = dir.path().join("a-directory.png");
        std::fs::create_dir(&directory).unwrap();
        error_of(&directory);
    }

    /// A 1 x 1 TIFF with one 32-bit floating-point sample (SampleFormat 3).
    fn float_tiff() -> Vec<u8> {
        let data_offset = 8 + 2 + 10 * 12 + 4;
        let entries: [(u16, u16, u32); 10] = [
            (256, 3, 1),           // ImageWidth
            (257, 3, 1),           // ImageLength
            (258, 3, 32),          // BitsPerSample
            (259, 3, 1),           // Compression: none
            (262, 3, 1),           // PhotometricInterpretation: black is zero
            (273, 4, data_offset), // StripOffsets
            (277, 3, 1),           // SamplesPerPixel
            (278, 3, 1),           // RowsPerStrip
            (279, 4, 4),           // StripByteCounts
            (339, 3, 3),           // SampleFormat: IEEE floating point
        ];
        let mut bytes = b"II*\0".to_vec();
        bytes.extend(8u32.to_le_bytes());
        bytes.extend(10u16.to_le_bytes());
        for (tag, kind, value) in entries {
            bytes.extend(tag.to_le_bytes());
            bytes.extend(kind.to_le_bytes());
            bytes.extend(1u32.to_le_bytes());
            if kind == 3 {
                bytes.extend((value as u16).to_le_bytes());
                bytes.extend([0, 0]);
            } else {
                bytes.extend(value.to_le_bytes());
            }
        }
        bytes.extend(0u32.to_le_bytes());
        assert_eq!(bytes.len(), data_offset as usize);
        bytes.extend(0.5f32.to_le_bytes());
        bytes
    }

    #[test]
    fn floating_point_tiff_is_refused_clearly() {
        let e = decode_frame(&float_tiff(), "float.tif").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("float.tif: floating-point images are not supported"),
            "{e}"
        );
    }

    #[test]
    fn check_frame_size_says_both_sizes() {
        let camera = CameraModel::canonical();
        let frame = Frame::new(640, 480, 8);
        let e = check_frame_size(&frame, &camera, "f.png").unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "f.png: image is 640 x 480 px, the camera file says {} x {}",
                camera.width_px, camera.height_px
            )
        );
        let right = Frame::new(camera.width_px, camera.height_px, 16);
        check_frame_size(&right, &camera, "f.png").unwrap();
    }

    #[test]
    fn write_frame_png_round_trips_8_and_16_bits_and_refuses_bad_frames() {
        let dir = tempfile::tempdir().unwrap();
        for bit_depth in [1u8, 8, 10, 16] {
            let max = if bit_depth <= 8 { 255 } else { 65535 };
            let mut frame = Frame::new(7, 5, bit_depth);
            for (k, v) in frame.pixels.iter_mut().enumerate() {
                *v = (k as u32 * 7919 % (max + 1)) as u16;
            }
            let path = dir.path().join(format!("f{bit_depth}.png"));
            write_frame_png(&path, &frame).unwrap();
            let back = read_frame(&path).unwrap();
            assert_eq!((back.width, back.height), (7, 5));
            assert_eq!(back.bit_depth, if bit_depth <= 8 { 8 } else { 16 });
            assert_eq!(back.pixels, frame.pixels, "{bit_depth} bits");
        }
        // Only the finished file is left: no temporary file.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4);

        let path = dir.path().join("bad.png");
        let error = |frame: &Frame| {
            let e = write_frame_png(&path, frame).unwrap_err().to_string();
            assert!(e.starts_with(&path.display().to_string()), "{e}");
            assert!(!path.exists());
            e
        };
        let mut too_bright = Frame::new(3, 2, 8);
        too_bright.pixels[4] = 256;
        assert!(error(&too_bright).contains("pixel (1, 1) is 256"));
        assert!(error(&Frame::new(0, 2, 8)).contains("empty frame"));
        let mut short = Frame::new(3, 2, 8);
        short.pixels.pop();
        assert!(error(&short).contains("5 pixel values for 3 x 2 px"));
        assert!(error(&Frame::new(3, 2, 17)).contains("bit depth is 17"));
        let missing_dir = dir.path().join("no-such-dir").join("f.png");
        let e = write_frame_png(&missing_dir, &Frame::new(3, 2, 8)).unwrap_err();
        assert!(e.to_string().contains("no-such-dir"), "{e}");
    }

    /// Mutated and truncated copies of valid files of every format: an image or an error naming the file, and never
    /// a decoder panic (which `decode_frame` would turn into an "internal error").
    #[test]
    fn mutated_files_never_panic() {
        let dir = tempfile::tempdir().unwrap();
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for (name, image) in [
            ("m.png", DynamicImage::from(rgb16())),
            ("m.tif", DynamicImage::from(grey16())),
            ("m.pgm", DynamicImage::from(grey8())),
            ("m.jpg", DynamicImage::from(rgb8())),
        ] {
            let path = dir.path().join(name);
            image.save(&path).unwrap();
            let valid = std::fs::read(&path).unwrap();
            let mut inputs: Vec<Vec<u8>> = (0..valid.len()).map(|n| valid[..n].to_vec()).collect();
            for _ in 0..300 {
                let mut bytes = valid.clone();
                for _ in 0..1 + next() % 4 {
                    let at = (next() % bytes.len() as u64) as usize;
                    bytes[at] = next() as u8;
                }
                inputs.push(bytes);
            }
            for bytes in inputs {
                if let Err(e) = decode_frame(&bytes, name) {
                    let text = e.to_string();
                    assert!(text.starts_with(name), "{text}");
                    assert!(!text.contains("internal error"), "{text}");
                }
            }
        }
    }
}
