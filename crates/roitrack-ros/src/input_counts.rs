//! [`InputCounts`]: what a node took from the bus and what it left out, by reason, shared between the threads that
//! take the messages and the one that publishes `/roitrack/status` (each status carries them, [`status_keys`]).

use std::sync::atomic::{AtomicU64, Ordering};

/// Why a node left an input message out, whole: one counter each in [`InputCounts`] and in the status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LeftOut {
    /// An image that came before any camera info: the node had no camera to track it with.
    NoCameraInfo,
    /// An image encoding (or a compressed image's format) the node does not read.
    Encoding,
    /// An image of another size than the camera's.
    Size,
    /// A message that does not decode: its CDR cut short or inconsistent (a step shorter than a row, data shorter
    /// than the step times the height, arrays of different lengths, a non-finite value, big-endian CDR), a camera
    /// info that gives no camera, a sample DDS could not hand over.
    Malformed,
    /// Centroids that decode but fail the checks of a measurements file's rows: a point id not of the target, a
    /// centroid off the image, a time going back.
    Invalid,
    /// An image whose stamp is not finite or does not come after the previous image's.
    StampOrder,
    /// A frame that starts before the previous frame's last measured blob was read (a rolling shutter's readout not
    /// over), which the frame tracker refuses.
    TooClose,
}

impl LeftOut {
    /// Every reason, in the order of the status's keys.
    pub const ALL: [LeftOut; 7] = [
        LeftOut::NoCameraInfo,
        LeftOut::Encoding,
        LeftOut::Size,
        LeftOut::Malformed,
        LeftOut::Invalid,
        LeftOut::StampOrder,
        LeftOut::TooClose,
    ];

    /// The reason's key in the status (`left_out_` and its name).
    pub fn key(self) -> &'static str {
        match self {
            LeftOut::NoCameraInfo => "left_out_no_camera_info",
            LeftOut::Encoding => "left_out_encoding",
            LeftOut::Size => "left_out_size",
            LeftOut::Malformed => "left_out_malformed",
            LeftOut::Invalid => "left_out_invalid",
            LeftOut::StampOrder => "left_out_stamp_order",
            LeftOut::TooClose => "left_out_too_close",
        }
    }

    fn index(self) -> usize {
        LeftOut::ALL
            .iter()
            .position(|&r| r == self)
            .expect("every reason is in ALL")
    }
}

/// The status key of the messages a node took from its input topic (images or centroid messages), left out or not.
pub const INPUT_MESSAGES_KEY: &str = "input_messages";

/// The keys [`InputCounts`] adds to each `/roitrack/status` of a node: [`INPUT_MESSAGES_KEY`], then each reason of
/// [`LeftOut::ALL`].
///
/// ```
/// assert_eq!(roitrack_ros::status_keys().count(), 8);
/// ```
pub fn status_keys() -> impl Iterator<Item = &'static str> {
    std::iter::once(INPUT_MESSAGES_KEY).chain(LeftOut::ALL.iter().map(|r| r.key()))
}

/// The messages a node took and those it left out, by reason; counted by the threads that take them and read by the
/// publishing thread for each status (`Arc`-shared, lock-free).
///
/// ```
/// use roitrack_ros::{InputCounts, LeftOut};
///
/// let counts = InputCounts::default();
/// counts.taken();
/// counts.taken();
/// counts.left_out(LeftOut::Encoding);
/// assert_eq!((counts.messages(), counts.count(LeftOut::Encoding), counts.total_left_out()), (2, 1, 1));
/// ```
#[derive(Debug, Default)]
pub struct InputCounts {
    messages: AtomicU64,
    left_out: [AtomicU64; LeftOut::ALL.len()],
}

impl InputCounts {
    /// Counts a message taken from the input topic.
    pub fn taken(&self) {
        self.messages.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts a message left out, for `why`.
    pub fn left_out(&self, why: LeftOut) {
        self.left_out[why.index()].fetch_add(1, Ordering::Relaxed);
    }

    /// The messages taken so far.
    pub fn messages(&self) -> u64 {
        self.messages.load(Ordering::Relaxed)
    }

    /// The messages left out for `why` so far.
    pub fn count(&self, why: LeftOut) -> u64 {
        self.left_out[why.index()].load(Ordering::Relaxed)
    }

    /// The messages left out so far, whatever the reason.
    pub fn total_left_out(&self) -> u64 {
        LeftOut::ALL.iter().map(|&r| self.count(r)).sum()
    }

    /// The values of [`status_keys`], in their order.
    pub fn values(&self) -> impl Iterator<Item = u64> + '_ {
        std::iter::once(self.messages()).chain(LeftOut::ALL.iter().map(|&r| self.count(r)))
    }

    /// `key count` of every reason with a count, for a log line (`left_out_size 1, left_out_too_close 2`), or `none`.
    pub fn summary(&self) -> String {
        let parts: Vec<String> = LeftOut::ALL
            .iter()
            .filter(|&&r| self.count(r) > 0)
            .map(|&r| format!("{} {}", r.key(), self.count(r)))
            .collect();
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    }
}
