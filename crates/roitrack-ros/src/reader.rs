//! [`BagFrameSource`]: the image frames of a ROS 2 bag (MCAP storage) as a timed frame stream, and the camera of its
//! CameraInfo.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};

use roitrack_core::CameraModel;
use roitrack_core::camera::PinholeIntrinsics;
use roitrack_formats::{FormatError, FrameInfo};
use roitrack_image::Frame;

/// The image message types [`BagFrameSource`] reads.
pub const IMAGE_TYPES: [&str; 2] = ["sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"];
/// The encodings of `sensor_msgs/msg/Image` it reads (colour made grey by BT.601 luma, as for image files).
pub const IMAGE_ENCODINGS: [&str; 4] = ["mono8", "mono16", "bgr8", "rgb8"];

/// A little-endian CDR reader over one message (after its 4-byte encapsulation header): alignment is relative to
/// the start of the payload, as in ROS 2.
pub(crate) struct Cdr<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cdr<'a> {
    pub(crate) fn new(message: &'a [u8]) -> Result<Self, String> {
        match message {
            [0, 1, _, _, ..] => Ok(Self {
                bytes: &message[4..],
                at: 0,
            }),
            [0, 0, _, _, ..] => Err("big-endian CDR is not supported".into()),
            _ => Err("not a CDR message (no encapsulation header)".into()),
        }
    }

    fn take(&mut self, n: usize, align: usize) -> Result<&'a [u8], String> {
        let start = self.at.next_multiple_of(align);
        let end = start
            .checked_add(n)
            .filter(|&end| end <= self.bytes.len())
            .ok_or_else(|| format!("message ends early ({} bytes)", self.bytes.len() + 4))?;
        self.at = end;
        Ok(&self.bytes[start..end])
    }

    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1, 1)?[0])
    }

    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4, 4)?.try_into().expect("4 bytes"),
        ))
    }

    fn i32(&mut self) -> Result<i32, String> {
        Ok(i32::from_le_bytes(
            self.take(4, 4)?.try_into().expect("4 bytes"),
        ))
    }

    pub(crate) fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(
            self.take(8, 8)?.try_into().expect("8 bytes"),
        ))
    }

    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        let bytes = self.take(n, 1)?;
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec()).map_err(|_| "a string is not UTF-8".to_string())
    }

    fn bytes(&mut self) -> Result<&'a [u8], String> {
        let n = self.u32()? as usize;
        self.take(n, 1)
    }

    /// `std_msgs/Header`: the stamp (s) and the frame id.
    pub(crate) fn header(&mut self) -> Result<(f64, String), String> {
        let sec = self.i32()?;
        let nanosec = self.u32()?;
        Ok((f64::from(sec) + 1e-9 * f64::from(nanosec), self.string()?))
    }
}

fn bag_error(bag: &Path, topic: &str, message: impl Into<String>) -> FormatError {
    FormatError::new(bag, message).with_field(topic.to_string())
}

/// The bytes of the bag's `.mcap` file (see [`mcap_file`]).
pub(crate) fn read_bag_bytes(bag: &Path) -> Result<Vec<u8>, FormatError> {
    let file = mcap_file(bag)?;
    std::fs::read(&file).map_err(|e| FormatError::io(&file, "cannot read", e))
}

/// The `.mcap` file of a bag: the file itself, or the one `.mcap` file of a rosbag2 folder.
pub(crate) fn mcap_file(bag: &Path) -> Result<PathBuf, FormatError> {
    if !bag.is_dir() {
        return Ok(bag.to_path_buf());
    }
    let entries = std::fs::read_dir(bag)
        .map_err(|e| FormatError::io(bag, "cannot list the bag folder", e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    files.sort();
    match files.len() {
        1 => Ok(files.remove(0)),
        0 => Err(FormatError::new(
            bag,
            "a folder without a .mcap file: not a rosbag2 bag in MCAP storage (sqlite3 bags are not read)",
        )),
        n => Err(FormatError::new(
            bag,
            format!("{n} .mcap files: bags split into several files are not read"),
        )),
    }
}

struct Channel {
    id: u16,
    type_name: String,
}

/// The image frames of one topic of a ROS 2 bag (a `.mcap` file or a rosbag2 folder holding one), in the order they
/// were written, each at its header stamp: `sensor_msgs/msg/Image` (mono8, mono16, bgr8, rgb8; colour made grey by
/// BT.601 luma, as image files are) or `sensor_msgs/msg/CompressedImage` (PNG, JPEG, ...; decoded as image files
/// are). [`next_frame`](Self::next_frame) has the shape of [`roitrack_formats::FrameSource::next_frame`], so the
/// frames go through the same frame-stream path as files.
///
/// The bag is read whole into memory, and its frames are decoded one chunk at a time. Errors name the bag and the
/// topic: a bag that is not a complete MCAP file (truncated: no summary), a topic that is not in it or is not of an
/// image type, an unknown encoding, a frame whose size disagrees with the camera info.
///
/// ```no_run
/// use roitrack_ros::BagFrameSource;
///
/// let mut source = BagFrameSource::open("run.mcap", "/camera/image_raw").unwrap();
/// let camera = source.camera_info("/camera/camera_info").unwrap();
/// let mut frame = roitrack_image::Frame::default();
/// while let Some(info) = source.next_frame(&mut frame) {
///     let info = info.unwrap();
///     println!("{} at {} s: {} x {} px", info.name, info.t_s, frame.width, frame.height);
/// }
/// ```
pub struct BagFrameSource {
    messages: TopicMessages,
    index: usize,
    expected_size: Option<(u32, u32)>,
    done: bool,
}

impl std::fmt::Debug for BagFrameSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagFrameSource")
            .field("bag", &self.messages.bag)
            .field("topic", &self.messages.topic)
            .field("index", &self.index)
            .finish_non_exhaustive()
    }
}

fn read_summary(bag: &Path, topic: &str, bytes: &[u8]) -> Result<mcap::read::Summary, FormatError> {
    let read = std::panic::catch_unwind(|| mcap::read::Summary::read(bytes)).map_err(|_| {
        bag_error(
            bag,
            topic,
            "the MCAP reader failed on this file (internal error)",
        )
    })?;
    match read {
        Ok(Some(summary)) => Ok(summary),
        Ok(None) => Err(bag_error(
            bag,
            topic,
            "the MCAP file has no summary: it was not completed (re-index it with `mcap recover`)",
        )),
        Err(e) => Err(bag_error(
            bag,
            topic,
            format!("not a complete MCAP file (truncated, or not MCAP): {e}"),
        )),
    }
}

fn find_channel(
    bag: &Path,
    summary: &mcap::read::Summary,
    topic: &str,
    types: &[&str],
) -> Result<Channel, FormatError> {
    let Some(channel) = summary.channels.values().find(|c| c.topic == topic) else {
        let mut topics: Vec<String> = summary
            .channels
            .values()
            .map(|c| {
                let type_name = c.schema.as_ref().map_or("?", |s| s.name.as_str());
                format!("{} ({type_name})", c.topic)
            })
            .collect();
        topics.sort();
        return Err(bag_error(
            bag,
            topic,
            format!("no such topic; the bag has: {}", topics.join(", ")),
        ));
    };
    let type_name = channel
        .schema
        .as_ref()
        .map_or(String::new(), |s| s.name.clone());
    if !types.contains(&type_name.as_str()) {
        return Err(bag_error(
            bag,
            topic,
            format!("of type {type_name:?}, not {}", types.join(" or ")),
        ));
    }
    if channel.message_encoding != "cdr" {
        return Err(bag_error(
            bag,
            topic,
            format!("message encoding {:?}, not cdr", channel.message_encoding),
        ));
    }
    Ok(Channel {
        id: channel.id,
        type_name,
    })
}

/// The messages of one topic of a bag, read one chunk at a time: what the bag readers of frames and of measurements
/// share.
pub(crate) struct TopicMessages {
    pub(crate) bag: PathBuf,
    pub(crate) topic: String,
    bytes: Vec<u8>,
    summary: mcap::read::Summary,
    channel: Channel,
    /// Chunks not yet read, in file order.
    next_chunk: usize,
    pending: VecDeque<Vec<u8>>,
}

/// The messages of `topic` in the bag whose `.mcap` file holds `bytes` (`bag` names it in errors): the bag's summary
/// read, the topic's channel found and checked to be of one of `types` in CDR, each error naming the bag and the
/// topic.
pub(crate) fn open_topic(
    bag: &Path,
    bytes: Vec<u8>,
    topic: &str,
    types: &[&str],
) -> Result<TopicMessages, FormatError> {
    let summary = read_summary(bag, topic, &bytes)?;
    let channel = find_channel(bag, &summary, topic, types)?;
    Ok(TopicMessages {
        bag: bag.to_path_buf(),
        topic: topic.to_string(),
        bytes,
        summary,
        channel,
        next_chunk: 0,
        pending: VecDeque::new(),
    })
}

impl TopicMessages {
    /// The next message's data, in the order of the messages' log times within each chunk; `None` at the end of
    /// the bag.
    pub(crate) fn next_message(&mut self) -> Result<Option<Vec<u8>>, FormatError> {
        while self.pending.is_empty() {
            let Some(chunk) = self.summary.chunk_indexes.get(self.next_chunk) else {
                return Ok(None);
            };
            self.next_chunk += 1;
            let mut in_chunk = chunk_messages(
                &self.bag,
                &self.summary,
                &self.bytes,
                chunk,
                &self.topic,
                self.channel.id,
            )?;
            // A chunk holds its messages in the order they were written; a writer may interleave channels, so order
            // by log time (a stable sort keeps equal times as written).
            in_chunk.sort_by_key(|(log_time, _)| *log_time);
            self.pending
                .extend(in_chunk.into_iter().map(|(_, data)| data));
        }
        Ok(self.pending.pop_front())
    }

    /// An error about the topic, naming the bag and the topic.
    pub(crate) fn error(&self, message: impl Into<String>) -> FormatError {
        bag_error(&self.bag, &self.topic, message)
    }
}

impl BagFrameSource {
    /// Opens `bag` and checks that `topic` is one of its image topics.
    pub fn open(bag: impl AsRef<Path>, topic: &str) -> Result<Self, FormatError> {
        let bag = bag.as_ref();
        Self::from_bytes(bag, read_bag_bytes(bag)?, topic)
    }

    /// [`open`](Self::open) on the bytes of a `.mcap` file; `bag` names it in errors.
    pub fn from_bytes(
        bag: impl AsRef<Path>,
        bytes: Vec<u8>,
        topic: &str,
    ) -> Result<Self, FormatError> {
        Ok(Self {
            messages: open_topic(bag.as_ref(), bytes, topic, &IMAGE_TYPES)?,
            index: 0,
            expected_size: None,
            done: false,
        })
    }

    /// The camera of the bag's first `sensor_msgs/msg/CameraInfo` on `topic` (plumb_bob, rational_polynomial,
    /// equidistant or no distortion); from then
    /// on, every frame must have its size.
    pub fn camera_info(&mut self, topic: &str) -> Result<CameraModel, FormatError> {
        let TopicMessages {
            bag,
            summary,
            bytes,
            ..
        } = &self.messages;
        let camera = camera_info_in(bag, summary, bytes, topic)?;
        self.expected_size = Some((camera.width_px, camera.height_px));
        Ok(camera)
    }

    /// Requires every frame to be `width` x `height` px (the camera's size, from a camera file).
    pub fn expect_size(&mut self, width: u32, height: u32) {
        self.expected_size = Some((width, height));
    }

    /// The topic of the camera info beside an image topic: `/ns/image_raw` -> `/ns/camera_info`, as ROS cameras
    /// publish them.
    pub fn camera_info_topic_of(image_topic: &str) -> String {
        match image_topic.rsplit_once('/') {
            Some((namespace, _)) => format!("{namespace}/camera_info"),
            None => "camera_info".to_string(),
        }
    }

    /// Whether the bag has a topic.
    pub fn has_topic(&self, topic: &str) -> bool {
        self.messages
            .summary
            .channels
            .values()
            .any(|c| c.topic == topic)
    }

    /// Reads the next frame into `frame` (its pixel buffer reused), sets its `t_s` to the header stamp and says
    /// which frame it is; `None` after the last frame or after an error.
    pub fn next_frame(&mut self, frame: &mut Frame) -> Option<Result<FrameInfo, FormatError>> {
        if self.done {
            return None;
        }
        let result = self.read_next(frame);
        if !matches!(result, Ok(Some(_))) {
            self.done = true;
        }
        result.transpose()
    }

    fn read_next(&mut self, frame: &mut Frame) -> Result<Option<FrameInfo>, FormatError> {
        let Some(data) = self.messages.next_message()? else {
            return Ok(None);
        };
        let index = self.index;
        self.index += 1;
        let TopicMessages {
            bag,
            topic,
            channel,
            ..
        } = &self.messages;
        let name = format!("message {index} of {topic}");
        let at = |e: String| self.messages.error(format!("{name}: {e}"));
        let t_s = if channel.type_name == IMAGE_TYPES[0] {
            decode_image(&data, frame).map_err(|e| at(e.to_string()))?
        } else {
            let (t_s, format, bytes) = compressed_image(&data).map_err(at)?;
            let pseudo_path =
                PathBuf::from(format!("{}:{topic} {name} ({format})", bag.display(),));
            let decoded = roitrack_formats::decode_frame(bytes, &pseudo_path)?;
            *frame = decoded;
            t_s
        };
        if let Some((width, height)) = self.expected_size
            && (frame.width, frame.height) != (width, height)
        {
            return Err(at(format!(
                "the image is {} x {} px, the camera info says {width} x {height} px",
                frame.width, frame.height
            )));
        }
        frame.t_s = t_s;
        Ok(Some(FrameInfo { index, name, t_s }))
    }
}

/// The camera of the first `sensor_msgs/msg/CameraInfo` on `topic` of `bag` (a `.mcap` file or a rosbag2 folder):
/// size, intrinsics and distortion, as [`BagFrameSource::camera_info`] reads it; for a bag without frames (a replay
/// of its measurements).
///
/// ```no_run
/// let camera = roitrack_ros::read_camera_info("run.mcap", "/roitrack/camera_info").unwrap();
/// println!("{} x {} px", camera.width_px, camera.height_px);
/// ```
pub fn read_camera_info(bag: impl AsRef<Path>, topic: &str) -> Result<CameraModel, FormatError> {
    let bag = bag.as_ref();
    let bytes = read_bag_bytes(bag)?;
    let summary = read_summary(bag, topic, &bytes)?;
    camera_info_in(bag, &summary, &bytes, topic)
}

fn camera_info_in(
    bag: &Path,
    summary: &mcap::read::Summary,
    bytes: &[u8],
    topic: &str,
) -> Result<CameraModel, FormatError> {
    let channel = find_channel(bag, summary, topic, &["sensor_msgs/msg/CameraInfo"])?;
    let mut message = None;
    for chunk in &summary.chunk_indexes {
        let messages = chunk_messages(bag, summary, bytes, chunk, topic, channel.id)?;
        if let Some((_, data)) = messages.into_iter().next() {
            message = Some(data);
            break;
        }
    }
    let message = message.ok_or_else(|| bag_error(bag, topic, "no message on the topic"))?;
    camera_from_info(&message).map_err(|e| bag_error(bag, topic, format!("camera info: {e}")))
}

/// The messages of one channel in one chunk: (log time, data), in the chunk's order. The chunk index is checked
/// first (mcap 0.26 slices the file by it unchecked, and panics on an index whose offset and length overflow), and
/// the reading runs under `catch_unwind`, so that a corrupt bag gives an error naming it, never a crash.
fn chunk_messages(
    bag: &Path,
    summary: &mcap::read::Summary,
    bytes: &[u8],
    chunk: &mcap::records::ChunkIndex,
    topic: &str,
    channel_id: u16,
) -> Result<Vec<(u64, Vec<u8>)>, FormatError> {
    let fits = chunk
        .chunk_start_offset
        .checked_add(chunk.chunk_length)
        .is_some_and(|end| end <= bytes.len() as u64 && chunk.chunk_start_offset + 9 <= end);
    if !fits {
        return Err(bag_error(
            bag,
            topic,
            format!(
                "a chunk index points outside the file (offset {}, length {}, file {} bytes)",
                chunk.chunk_start_offset,
                chunk.chunk_length,
                bytes.len()
            ),
        ));
    }
    let read = || -> Result<Vec<(u64, Vec<u8>)>, String> {
        let messages = summary
            .stream_chunk(bytes, chunk)
            .map_err(|e| format!("cannot read a chunk: {e}"))?;
        let mut out = Vec::new();
        for message in messages {
            let message = message.map_err(|e| format!("cannot read a message: {e}"))?;
            if message.channel.id == channel_id {
                out.push((message.log_time, message.data.into_owned()));
            }
        }
        Ok(out)
    };
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(read))
        .unwrap_or_else(
            |_| Err("the MCAP reader failed on this chunk (internal error)".to_string()),
        )
        .map_err(|e| bag_error(bag, topic, e))
}

/// Decodes a `sensor_msgs/msg/Image` into `frame`; its stamp (s).
pub(crate) fn decode_image(message: &[u8], frame: &mut Frame) -> Result<f64, ImageFault> {
    let mut cdr = Cdr::new(message)?;
    let (t_s, _) = cdr.header()?;
    let height = cdr.u32()?;
    let width = cdr.u32()?;
    let encoding = cdr.string()?;
    let big_endian = cdr.u8()? != 0;
    let step = cdr.u32()? as usize;
    let data = cdr.bytes()?;
    let channels = match encoding.as_str() {
        "mono8" => 1,
        "mono16" => 2,
        "bgr8" | "rgb8" => 3,
        other => {
            return Err(ImageFault::Encoding(format!(
                "image encoding {other:?} is not read (expected {})",
                IMAGE_ENCODINGS.join(", ")
            )));
        }
    };
    if width == 0 || height == 0 {
        return Err(format!("empty image: {width} x {height} px").into());
    }
    let row_bytes = width as usize * channels;
    if step < row_bytes || data.len() < step * (height as usize - 1) + row_bytes {
        return Err(format!(
            "{} bytes of data for {width} x {height} px {encoding} with a step of {step}",
            data.len()
        )
        .into());
    }
    let luma = |r: u8, g: u8, b: u8| -> u16 {
        (0.299 * f64::from(r) + 0.587 * f64::from(g) + 0.114 * f64::from(b)).round() as u16
    };
    frame.pixels.clear();
    for row in data.chunks(step).take(height as usize) {
        let row = &row[..row_bytes];
        match encoding.as_str() {
            "mono8" => frame.pixels.extend(row.iter().map(|&v| u16::from(v))),
            "mono16" => frame.pixels.extend(row.chunks_exact(2).map(|p| {
                if big_endian {
                    u16::from_be_bytes([p[0], p[1]])
                } else {
                    u16::from_le_bytes([p[0], p[1]])
                }
            })),
            "rgb8" => frame
                .pixels
                .extend(row.chunks_exact(3).map(|p| luma(p[0], p[1], p[2]))),
            _ => frame
                .pixels
                .extend(row.chunks_exact(3).map(|p| luma(p[2], p[1], p[0]))),
        }
    }
    frame.width = width;
    frame.height = height;
    frame.bit_depth = if encoding == "mono16" { 16 } else { 8 };
    Ok(t_s)
}

/// Why an image message could not be decoded: an encoding not read, or anything else wrong with it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ImageFault {
    /// An encoding [`decode_image`] does not read.
    Encoding(String),
    /// CDR cut short, an empty image, data that does not fit its step, width and height.
    Malformed(String),
}

impl From<String> for ImageFault {
    fn from(message: String) -> Self {
        Self::Malformed(message)
    }
}

impl std::fmt::Display for ImageFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Encoding(m) | Self::Malformed(m) => f.write_str(m),
        }
    }
}

/// A `sensor_msgs/msg/CompressedImage`: its stamp (s), format and the compressed bytes.
pub(crate) fn compressed_image(message: &[u8]) -> Result<(f64, String, &[u8]), String> {
    let mut cdr = Cdr::new(message)?;
    let (t_s, _) = cdr.header()?;
    let format = cdr.string()?;
    Ok((t_s, format, cdr.bytes()?))
}

/// The camera of a `sensor_msgs/msg/CameraInfo`: size, `k` (fx, skew, cx, fy, cy) and its distortion (plumb_bob,
/// rational_polynomial, equidistant, or none).
pub(crate) fn camera_from_info(message: &[u8]) -> Result<CameraModel, String> {
    let mut cdr = Cdr::new(message)?;
    let (_, frame_id) = cdr.header()?;
    let height = cdr.u32()?;
    let width = cdr.u32()?;
    let model = cdr.string()?;
    let count = cdr.u32()? as usize;
    if count > 64 {
        return Err(format!("{count} distortion coefficients"));
    }
    let d = (0..count)
        .map(|_| cdr.f64())
        .collect::<Result<Vec<_>, _>>()?;
    let k = (0..9).map(|_| cdr.f64()).collect::<Result<Vec<_>, _>>()?;
    let distortion = roitrack_core::camera::Distortion::from_model(&model, &d)
        .map_err(|e| format!("{e}: give --camera"))?;
    let intrinsics = PinholeIntrinsics {
        fx_px: k[0],
        skew_px: k[1],
        cx_px: k[2],
        fy_px: k[4],
        cy_px: k[5],
    };
    let name = if frame_id.is_empty() {
        "camera".to_string()
    } else {
        frame_id
    };
    CameraModel::new(name, width, height, intrinsics, distortion).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg;

    fn serialise<T: serde::Serialize>(value: &T) -> Vec<u8> {
        cdr::serialize::<_, _, cdr::CdrLe>(value, cdr::Infinite).unwrap()
    }

    fn image(encoding: &str, width: u32, height: u32, step: u32, data: &[u8]) -> Vec<u8> {
        serialise(&msg::Image {
            header: msg::Header {
                stamp: msg::Time {
                    sec: 3,
                    nanosec: 500_000_000,
                },
                frame_id: "cam",
            },
            height,
            width,
            encoding,
            is_bigendian: 0,
            step,
            data: msg::Bytes(data),
        })
    }

    #[test]
    fn images_of_every_encoding_decode_to_grey_frames() {
        let mut frame = Frame::default();
        // Two rows of two pixels, rows padded to a step of 8 bytes.
        let t = decode_image(
            &image("mono8", 2, 2, 8, &[1, 2, 0, 0, 0, 0, 0, 0, 3, 4]),
            &mut frame,
        )
        .unwrap();
        assert_eq!(
            (t, frame.width, frame.height, frame.bit_depth),
            (3.5, 2, 2, 8)
        );
        assert_eq!(frame.pixels, [1, 2, 3, 4]);
        decode_image(&image("mono16", 1, 1, 2, &[0x34, 0x12]), &mut frame).unwrap();
        assert_eq!((frame.pixels[0], frame.bit_depth), (0x1234, 16));
        decode_image(&image("rgb8", 2, 1, 6, &[255, 0, 0, 9, 9, 9]), &mut frame).unwrap();
        assert_eq!(frame.pixels, [76, 9]);
        decode_image(&image("bgr8", 1, 1, 3, &[0, 0, 255]), &mut frame).unwrap();
        assert_eq!(frame.pixels, [76]);
        let e = decode_image(&image("yuv422", 1, 1, 2, &[0, 0]), &mut frame).unwrap_err();
        assert!(
            matches!(&e, ImageFault::Encoding(m) if m.contains("\"yuv422\" is not read")),
            "{e}"
        );
        let e = decode_image(&image("mono8", 4, 4, 4, &[0; 15]), &mut frame).unwrap_err();
        assert!(
            matches!(&e, ImageFault::Malformed(m) if m.contains("15 bytes of data")),
            "{e}"
        );
        let mut truncated = image("mono8", 2, 2, 2, &[1, 2, 3, 4]);
        truncated.truncate(20);
        assert!(
            decode_image(&truncated, &mut frame)
                .unwrap_err()
                .to_string()
                .contains("ends early")
        );
    }

    #[test]
    fn a_camera_info_written_by_the_writer_reads_back() {
        let camera = CameraModel::canonical();
        let i = camera.intrinsics;
        let message = serialise(&msg::CameraInfo {
            header: msg::Header {
                stamp: msg::Time::default(),
                frame_id: "cam",
            },
            height: camera.height_px,
            width: camera.width_px,
            distortion_model: "plumb_bob",
            d: camera.distortion.coefficients().to_vec(),
            k: msg::Fixed([
                i.fx_px, i.skew_px, i.cx_px, 0.0, i.fy_px, i.cy_px, 0.0, 0.0, 1.0,
            ]),
            r: msg::Fixed([0.0; 9]),
            p: msg::Fixed([0.0; 12]),
            binning_x: 0,
            binning_y: 0,
            roi: msg::RegionOfInterest::default(),
        });
        let read = camera_from_info(&message).unwrap();
        assert_eq!(read.intrinsics, camera.intrinsics);
        assert_eq!(read.distortion, camera.distortion);
        assert_eq!(
            (read.width_px, read.height_px),
            (camera.width_px, camera.height_px)
        );
    }

    #[test]
    fn the_camera_info_topic_is_beside_the_image_topic() {
        assert_eq!(
            BagFrameSource::camera_info_topic_of("/cam/image_raw"),
            "/cam/camera_info"
        );
    }
}
