//! ROI recordings: the pixels of every ROI a camera read, with its time and place, so that camera data can be
//! replayed through the tracker (`roitrack track --rois FILE`).
//!
//! A little-endian binary file:
//!
//! ```text
//! magic        16 bytes   "ROITRACK-ROIS-1\n"
//! then records until the end of the file, each:
//!   t_s        f64        exposure midpoint (s); records in time order (not decreasing)
//!   id         u32        the target point the ROI was placed on
//!   x0, y0     u32, u32   top-left pixel of the ROI on the sensor (pixel centres at integer coordinates)
//!   width      u32        ROI width (px), 1..=1024
//!   height     u32        ROI height (px), 1..=1024
//!   bit_depth  u8         8, 10, 12 or 16
//!   pixels     width * height values, row-major: u8 when bit_depth is 8, else u16 (each below 2^bit_depth)
//! ```
//!
//! Errors name the file, the record (as "line": its 1-based index) and the field, with the byte offset.

use std::fs::File;
use std::io::{BufReader, BufWriter, ErrorKind, Read, Write};
use std::path::{Path, PathBuf};

use roitrack_image::{Roi, RoiImage};

use crate::{AtomicFile, FormatError};

/// The file's first 16 bytes.
pub const ROI_RECORDING_MAGIC: &[u8; 16] = b"ROITRACK-ROIS-1\n";
/// Largest ROI side accepted (px).
pub const MAX_ROI_SIDE_PX: u32 = 1024;

/// Streams the recorded [`RoiImage`]s with constant memory (one record at a time).
pub struct RoiRecordingReader<R: Read> {
    reader: R,
    path: PathBuf,
    index: u64,
    offset: u64,
    previous_t_s: Option<f64>,
    known_ids: Option<std::collections::HashSet<u32>>,
    done: bool,
}

impl RoiRecordingReader<BufReader<File>> {
    /// Opens the recording at `path` and reads its header.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|e| FormatError::io(path, "cannot open", e))?;
        Self::from_reader(BufReader::new(file), path)
    }
}

impl<R: Read> RoiRecordingReader<R> {
    /// Reads a recording's header from `reader`; `path` names it in errors.
    pub fn from_reader(mut reader: R, path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let path = path.as_ref().to_path_buf();
        let mut magic = [0u8; 16];
        match reader.read_exact(&mut magic) {
            Ok(()) if &magic == ROI_RECORDING_MAGIC => {}
            Ok(()) | Err(_) => {
                return Err(FormatError::new(
                    &path,
                    "not a roitrack ROI recording (the file must start with \"ROITRACK-ROIS-1\\n\")",
                )
                .with_field("magic"));
            }
        }
        Ok(Self {
            reader,
            path,
            index: 0,
            offset: 16,
            previous_t_s: None,
            known_ids: None,
            done: false,
        })
    }

    /// Makes a record of a point outside `ids` (the target's point ids) an error.
    #[must_use]
    pub fn with_known_ids(mut self, ids: impl IntoIterator<Item = u32>) -> Self {
        self.known_ids = Some(ids.into_iter().collect());
        self
    }

    fn error(&self, field: &str, message: impl Into<String>) -> FormatError {
        FormatError::new(
            &self.path,
            format!("{} (byte {})", message.into(), self.offset),
        )
        .with_line(self.index)
        .with_field(field)
    }

    /// Reads exactly `buf.len()` bytes; `Ok(false)` at a clean end of file before the first byte of a record.
    fn read_field(
        &mut self,
        buf: &mut [u8],
        field: &str,
        first: bool,
    ) -> Result<bool, FormatError> {
        let mut filled = 0;
        while filled < buf.len() {
            match self.reader.read(&mut buf[filled..]) {
                Ok(0) if first && filled == 0 => return Ok(false),
                Ok(0) => return Err(self.error(field, "the record is truncated")),
                Ok(k) => filled += k,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(FormatError::io(&self.path, "cannot read", e)),
            }
        }
        self.offset += buf.len() as u64;
        Ok(true)
    }

    fn read_u32(&mut self, field: &str) -> Result<u32, FormatError> {
        let mut b = [0u8; 4];
        self.read_field(&mut b, field, false)?;
        Ok(u32::from_le_bytes(b))
    }

    fn read_record(&mut self) -> Result<Option<RoiImage>, FormatError> {
        self.index += 1;
        let mut b8 = [0u8; 8];
        if !self.read_field(&mut b8, "t", true)? {
            return Ok(None);
        }
        let t_s = f64::from_le_bytes(b8);
        if !t_s.is_finite() {
            return Err(self.error("t", format!("time is not finite ({t_s})")));
        }
        if let Some(previous) = self.previous_t_s
            && t_s < previous
        {
            return Err(self.error(
                "t",
                format!("time {t_s} s is before the previous record's {previous} s"),
            ));
        }
        let id = self.read_u32("id")?;
        if let Some(known) = &self.known_ids
            && !known.contains(&id)
        {
            return Err(self.error(
                "id",
                format!("unknown point id {id}: the target has no such point"),
            ));
        }
        let x0 = self.read_u32("x0")?;
        let y0 = self.read_u32("y0")?;
        let width = self.read_u32("width")?;
        let height = self.read_u32("height")?;
        for (field, side) in [("width", width), ("height", height)] {
            if side == 0 || side > MAX_ROI_SIDE_PX {
                return Err(self.error(field, format!("{side} px is not in 1..={MAX_ROI_SIDE_PX}")));
            }
        }
        let mut depth = [0u8; 1];
        self.read_field(&mut depth, "bit_depth", false)?;
        let bit_depth = depth[0];
        if ![8, 10, 12, 16].contains(&bit_depth) {
            return Err(self.error("bit_depth", format!("{bit_depth} is not 8, 10, 12 or 16")));
        }
        let count = (width * height) as usize;
        let bytes_per = if bit_depth == 8 { 1 } else { 2 };
        let mut raw = vec![0u8; count * bytes_per];
        self.read_field(&mut raw, "pixels", false)?;
        let pixels: Vec<u16> = if bit_depth == 8 {
            raw.iter().map(|&v| v as u16).collect()
        } else {
            raw.chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect()
        };
        let max = ((1u32 << bit_depth) - 1) as u16;
        if let Some(i) = pixels.iter().position(|&v| v > max) {
            return Err(self.error(
                "pixels",
                format!(
                    "pixel {i} has value {} above the {bit_depth}-bit maximum {max}",
                    pixels[i]
                ),
            ));
        }
        self.previous_t_s = Some(t_s);
        Ok(Some(RoiImage {
            t_s,
            point_id: id,
            roi: Roi::new(x0, y0, width, height),
            bit_depth,
            pixels,
        }))
    }
}

impl<R: Read> Iterator for RoiRecordingReader<R> {
    type Item = Result<RoiImage, FormatError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let next = self.read_record();
        crate::error::ending_at_end_or_error(&mut self.done, next)
    }
}

/// Writes a recording atomically: the file appears only on [`RoiRecordingWriter::finish`].
pub struct RoiRecordingWriter {
    file: BufWriter<AtomicFile>,
    path: PathBuf,
    previous_t_s: Option<f64>,
}

impl RoiRecordingWriter {
    /// A recording to be written at `path` (atomically: it appears only on [`Self::finish`]).
    pub fn create(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let path = path.as_ref().to_path_buf();
        let mut file = BufWriter::new(AtomicFile::create(&path)?);
        file.write_all(ROI_RECORDING_MAGIC)
            .map_err(|e| FormatError::io(&path, "cannot write", e))?;
        Ok(Self {
            file,
            path,
            previous_t_s: None,
        })
    }

    /// Appends one ROI; refuses what the reader would refuse.
    pub fn write(&mut self, r: &RoiImage) -> Result<(), FormatError> {
        let Roi {
            x0,
            y0,
            width,
            height,
        } = r.roi;
        let bad = |field: &str, message: String| {
            Err(FormatError::new(&self.path, message).with_field(field))
        };
        if !r.t_s.is_finite() || self.previous_t_s.is_some_and(|p| r.t_s < p) {
            return bad(
                "t",
                format!("time {} s is not finite or goes backwards", r.t_s),
            );
        }
        if width == 0 || height == 0 || width > MAX_ROI_SIDE_PX || height > MAX_ROI_SIDE_PX {
            return bad("width", format!("ROI size {width} x {height} out of range"));
        }
        if ![8, 10, 12, 16].contains(&r.bit_depth) {
            return bad(
                "bit_depth",
                format!("{} is not 8, 10, 12 or 16", r.bit_depth),
            );
        }
        if r.pixels.len() != (width * height) as usize {
            return bad(
                "pixels",
                format!("{} pixels for a {width} x {height} ROI", r.pixels.len()),
            );
        }
        let max = ((1u32 << r.bit_depth) - 1) as u16;
        if r.pixels.iter().any(|&v| v > max) {
            return bad(
                "pixels",
                format!("a pixel is above the {}-bit maximum", r.bit_depth),
            );
        }
        let io = |e| FormatError::io(&self.path, "cannot write", e);
        let mut header = Vec::with_capacity(29);
        header.extend_from_slice(&r.t_s.to_le_bytes());
        for v in [r.point_id, x0, y0, width, height] {
            header.extend_from_slice(&v.to_le_bytes());
        }
        header.push(r.bit_depth);
        self.file.write_all(&header).map_err(io)?;
        if r.bit_depth == 8 {
            let bytes: Vec<u8> = r.pixels.iter().map(|&v| v as u8).collect();
            self.file.write_all(&bytes).map_err(io)?;
        } else {
            for v in &r.pixels {
                self.file.write_all(&v.to_le_bytes()).map_err(io)?;
            }
        }
        self.previous_t_s = Some(r.t_s);
        Ok(())
    }

    /// Flushes the recording and moves it into place.
    pub fn finish(self) -> Result<(), FormatError> {
        let path = self.path.clone();
        let file = self
            .file
            .into_inner()
            .map_err(|e| FormatError::io(&path, "cannot write", e.into_error()))?;
        file.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(t_s: f64, bit_depth: u8) -> RoiImage {
        RoiImage {
            t_s,
            point_id: 7,
            roi: Roi::new(100, 200, 3, 2),
            bit_depth,
            pixels: vec![0, 1, 2, 200, 255, 17],
        }
    }

    #[test]
    fn round_trip_8_and_12_bits() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rois.bin");
        let mut w = RoiRecordingWriter::create(&path).unwrap();
        let mut deep = record(0.5, 12);
        deep.pixels[1] = 4095;
        w.write(&record(0.25, 8)).unwrap();
        w.write(&deep).unwrap();
        w.finish().unwrap();
        let back: Vec<RoiImage> = RoiRecordingReader::open(&path)
            .unwrap()
            .map(|r| r.unwrap())
            .collect();
        assert_eq!(back, vec![record(0.25, 8), deep]);
    }

    #[test]
    fn malformed_recordings_name_the_record_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rois.bin");
        let mut w = RoiRecordingWriter::create(&path).unwrap();
        w.write(&record(0.25, 8)).unwrap();
        w.write(&record(0.5, 8)).unwrap();
        w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();

        let truncated = dir.path().join("truncated.bin");
        std::fs::write(&truncated, &bytes[..bytes.len() - 2]).unwrap();
        let err = RoiRecordingReader::open(&truncated)
            .unwrap()
            .find_map(|r| r.err())
            .unwrap()
            .to_string();
        assert!(
            err.contains("truncated.bin:2") && err.contains("pixels") && err.contains("truncated"),
            "{err}"
        );

        let bad_magic = dir.path().join("magic.bin");
        std::fs::write(&bad_magic, b"hello").unwrap();
        let err = RoiRecordingReader::open(&bad_magic)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("magic.bin") && err.contains("magic"), "{err}");

        // Second record's time set before the first's.
        let mut backwards = bytes.clone();
        let second = 16 + 29 + 6;
        backwards[second..second + 8].copy_from_slice(&0.1f64.to_le_bytes());
        let p = dir.path().join("backwards.bin");
        std::fs::write(&p, &backwards).unwrap();
        let err = RoiRecordingReader::open(&p)
            .unwrap()
            .find_map(|r| r.err())
            .unwrap()
            .to_string();
        assert!(
            err.contains("backwards.bin:2") && err.contains("'t'"),
            "{err}"
        );

        // A zero width.
        let mut zero = bytes.clone();
        zero[16 + 20..16 + 24].copy_from_slice(&0u32.to_le_bytes());
        let p = dir.path().join("zero.bin");
        std::fs::write(&p, &zero).unwrap();
        let err = RoiRecordingReader::open(&p)
            .unwrap()
            .find_map(|r| r.err())
            .unwrap()
            .to_string();
        assert!(err.contains("zero.bin:1") && err.contains("width"), "{err}");
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        let mut state = 12345u64;
        for len in 0..400 {
            let mut bytes = ROI_RECORDING_MAGIC.to_vec();
            for _ in 0..len {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                bytes.push((state >> 33) as u8);
            }
            let reader = RoiRecordingReader::from_reader(bytes.as_slice(), "fuzz.bin").unwrap();
            for r in reader.take(100) {
                let _ = r;
            }
        }
    }
}
