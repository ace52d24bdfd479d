//! [`BagMeasurementSource`]: recorded blob centroids (`roitrack_msgs/msg/BlobMeasurements`) replayed from a ROS 2 bag.

use std::collections::VecDeque;
use std::path::Path;

use roitrack_core::Measurement;
use roitrack_formats::{FormatError, MeasurementChecks, MeasurementField};

use crate::msg::BLOB_MEASUREMENTS;
use crate::reader::{Cdr, TopicMessages, open_topic, read_bag_bytes};

/// Fewest bytes a measurement takes in a message (an id and three float64): bounds the array lengths a corrupt
/// message may claim before anything is allocated for them.
const MIN_BYTES_PER_MEASUREMENT: usize = 4 + 3 * 8;

/// The blob centroids of one `roitrack_msgs/msg/BlobMeasurements` topic of a ROS 2 bag (a `.mcap` file or a rosbag2
/// folder holding one), as the measurements CSV gives them: an iterator of [`Measurement`]s in the order they were
/// written, each at `header.stamp + dt_s`, so that a bag written by `track --mcap` tracks as its measurements file.
///
/// Checked, each error naming the bag, the topic, the message (its index on the topic) and the field: the topic is
/// in the bag and of that type; the arrays `point_ids`, `u_px`, `v_px`, `dt_s` have one entry per centroid and
/// `sigma_px` one or none; then the [`MeasurementChecks`] of a measurements CSV: times and centroids are finite;
/// with [`with_known_ids`](Self::with_known_ids), every id is the target's; with
/// [`with_image_size`](Self::with_image_size), every centroid is on the image; times never go back. `sigma_px` is read and checked (finite, positive) but not used: the estimator has its own noise model.
///
/// ```no_run
/// use roitrack_ros::BagMeasurementSource;
///
/// let source = BagMeasurementSource::open("run.mcap", "/roitrack/measurements").unwrap().with_known_ids([1, 2, 3]);
/// for m in source {
///     let m = m.unwrap();
///     println!("point {} at {} s: ({}, {}) px", m.id, m.t_s, m.u_px, m.v_px);
/// }
/// ```
pub struct BagMeasurementSource {
    messages: TopicMessages,
    decoded: VecDeque<Measurement>,
    /// Index on the topic of the next message to decode.
    message_index: usize,
    checks: MeasurementChecks,
    done: bool,
}

impl std::fmt::Debug for BagMeasurementSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagMeasurementSource")
            .field("bag", &self.messages.bag)
            .field("topic", &self.messages.topic)
            .field("message_index", &self.message_index)
            .finish_non_exhaustive()
    }
}

impl BagMeasurementSource {
    /// Opens `bag` and checks that `topic` is a `roitrack_msgs/msg/BlobMeasurements` topic of it.
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
            messages: open_topic(bag.as_ref(), bytes, topic, &[BLOB_MEASUREMENTS])?,
            decoded: VecDeque::new(),
            message_index: 0,
            checks: MeasurementChecks::new(),
            done: false,
        })
    }

    /// Makes an id outside `ids` (the target's point ids) an error (see [`MeasurementChecks::with_known_ids`]).
    #[must_use]
    pub fn with_known_ids(mut self, ids: impl IntoIterator<Item = u32>) -> Self {
        self.checks = self.checks.with_known_ids(ids);
        self
    }

    /// Makes a centroid off an image of `width_px` x `height_px` an error, as in a measurements CSV (see
    /// [`MeasurementChecks::with_image_size`]).
    #[must_use]
    pub fn with_image_size(mut self, width_px: u32, height_px: u32) -> Self {
        self.checks = self.checks.with_image_size(width_px, height_px);
        self
    }

    /// The bag, as named by the caller.
    pub fn bag(&self) -> &Path {
        &self.messages.bag
    }

    fn next_measurement(&mut self) -> Result<Option<Measurement>, FormatError> {
        while self.decoded.is_empty() {
            let Some(data) = self.messages.next_message()? else {
                return Ok(None);
            };
            let index = self.message_index;
            self.message_index += 1;
            decode(&data, &mut self.decoded).map_err(|(field, e)| {
                self.messages
                    .error(format!("message {index}, field {field}: {e}"))
            })?;
            self.check(index)?;
        }
        Ok(self.decoded.pop_front())
    }

    /// Checks the centroids of message `index` just decoded; an error names the message's array and entry.
    fn check(&mut self, index: usize) -> Result<(), FormatError> {
        for (k, m) in self.decoded.iter().enumerate() {
            self.checks.check(m).map_err(|problem| {
                let array = match problem.field() {
                    MeasurementField::Time => "dt_s",
                    MeasurementField::Id => "point_ids",
                    MeasurementField::U => "u_px",
                    MeasurementField::V => "v_px",
                };
                self.messages
                    .error(format!("message {index}, field {array}[{k}]: {problem}"))
            })?;
        }
        Ok(())
    }
}

impl Iterator for BagMeasurementSource {
    type Item = Result<Measurement, FormatError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let item = self.next_measurement().transpose();
        if !matches!(item, Some(Ok(_))) {
            self.done = true;
        }
        item
    }
}

/// Decodes one `BlobMeasurements` into `out`; on an error, the field and what is wrong with it.
pub(crate) fn decode(
    message: &[u8],
    out: &mut VecDeque<Measurement>,
) -> Result<(), (String, String)> {
    let whole = |e: String| ("header".to_string(), e);
    let mut cdr = Cdr::new(message).map_err(whole)?;
    let (stamp_s, _) = cdr.header().map_err(whole)?;
    let room = message.len() / MIN_BYTES_PER_MEASUREMENT;
    let length = |cdr: &mut Cdr<'_>, field: &str| -> Result<usize, (String, String)> {
        let n = cdr.u32().map_err(|e| (field.to_string(), e))? as usize;
        if n > room {
            return Err((
                field.to_string(),
                format!(
                    "{n} entries cannot fit in a message of {} bytes",
                    message.len()
                ),
            ));
        }
        Ok(n)
    };
    let n = length(&mut cdr, "point_ids")?;
    let ids = (0..n)
        .map(|_| cdr.u32())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| ("point_ids".to_string(), e))?;
    let floats = |cdr: &mut Cdr<'_>, field: &str, allow_empty: bool| {
        let count = length(cdr, field)?;
        if count != n && !(allow_empty && count == 0) {
            return Err((
                field.to_string(),
                format!("{count} entries for {n} point ids"),
            ));
        }
        let values = (0..count)
            .map(|_| cdr.f64())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| (field.to_string(), e))?;
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return Err((
                format!("{field}[{k}]"),
                format!("{} is not finite", values[k]),
            ));
        }
        Ok(values)
    };
    let u = floats(&mut cdr, "u_px", false)?;
    let v = floats(&mut cdr, "v_px", false)?;
    let dt = floats(&mut cdr, "dt_s", false)?;
    let sigma = floats(&mut cdr, "sigma_px", true)?;
    if let Some(k) = sigma.iter().position(|&s| s <= 0.0) {
        return Err((
            format!("sigma_px[{k}]"),
            format!("{} is not positive", sigma[k]),
        ));
    }
    for k in 0..n {
        out.push_back(Measurement {
            t_s: stamp_s + dt[k],
            id: ids[k],
            u_px: u[k],
            v_px: v[k],
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BagOptions, BagWriter, msg, topics};

    fn measurement(t_s: f64, id: u32) -> Measurement {
        Measurement {
            t_s,
            id,
            u_px: 100.0 + f64::from(id),
            v_px: 200.25,
        }
    }

    fn bag_of(batches: &[&[Measurement]]) -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.mcap");
        let mut bag = BagWriter::create(&path, &BagOptions::default(), None).unwrap();
        for batch in batches {
            bag.write_measurements(batch).unwrap();
        }
        bag.finish().unwrap();
        std::fs::read(path).unwrap()
    }

    #[test]
    fn measurements_read_back_at_their_times() {
        let a = [
            measurement(1.0, 1),
            measurement(1.0, 2),
            measurement(1.000_25, 3),
        ];
        let b = [measurement(1.123_456_789_012_3, 4)];
        let bytes = bag_of(&[&a, &b]);
        let read: Vec<Measurement> =
            BagMeasurementSource::from_bytes("m.mcap", bytes, topics::MEASUREMENTS)
                .unwrap()
                .with_known_ids([1, 2, 3, 4])
                .map(Result::unwrap)
                .collect();
        assert_eq!(read.len(), 4);
        for (got, want) in read.iter().zip(a.iter().chain(&b)) {
            assert_eq!(
                (got.id, got.u_px, got.v_px),
                (want.id, want.u_px, want.v_px)
            );
            assert!(
                (got.t_s - want.t_s).abs() <= 1e-15,
                "{} {}",
                got.t_s,
                want.t_s
            );
        }
        // Equal times stay equal: they form one readout.
        assert_eq!(read[0].t_s, read[1].t_s);
    }

    #[test]
    fn bad_content_is_an_error_naming_bag_topic_message_and_field() {
        let bytes = bag_of(&[&[measurement(1.0, 1)], &[measurement(2.0, 7)]]);
        let errors: Vec<String> =
            BagMeasurementSource::from_bytes("m.mcap", bytes.clone(), topics::MEASUREMENTS)
                .unwrap()
                .with_known_ids([1, 2])
                .filter_map(Result::err)
                .map(|e| e.to_string())
                .collect();
        assert_eq!(errors.len(), 1);
        assert!(
            errors[0].starts_with("m.mcap")
                && errors[0].contains("/roitrack/measurements")
                && errors[0].contains("message 1, field point_ids[0]: unknown point id 7"),
            "{}",
            errors[0]
        );
        let e = BagMeasurementSource::from_bytes("m.mcap", bytes.clone(), "/nothing").unwrap_err();
        assert!(e.to_string().contains("no such topic"), "{e}");
        let mut truncated = bytes;
        truncated.truncate(truncated.len() - 40);
        let e = BagMeasurementSource::from_bytes("m.mcap", truncated, topics::MEASUREMENTS)
            .unwrap_err();
        assert!(e.to_string().contains("m.mcap"), "{e}");
        // Off the image, and times that go back (messages are read in the order of their stamps, so within one).
        let bytes = bag_of(&[&[measurement(2.0, 1), measurement(1.5, 2)]]);
        let e = BagMeasurementSource::from_bytes("m.mcap", bytes.clone(), topics::MEASUREMENTS)
            .unwrap()
            .with_image_size(64, 64)
            .find_map(Result::err)
            .unwrap();
        assert!(
            e.to_string()
                .contains("message 0, field u_px[0]: 101 px is outside"),
            "{e}"
        );
        let e = BagMeasurementSource::from_bytes("m.mcap", bytes, topics::MEASUREMENTS)
            .unwrap()
            .find_map(Result::err)
            .unwrap();
        assert!(
            e.to_string()
                .contains("message 0, field dt_s[1]: time 1.5 s"),
            "{e}"
        );
    }

    fn encode(message: &msg::BlobMeasurements<'_>) -> Vec<u8> {
        cdr::serialize::<_, _, cdr::CdrLe>(message, cdr::Infinite).unwrap()
    }

    #[test]
    fn malformed_messages_name_the_field() {
        let header = msg::Header {
            stamp: msg::Time { sec: 1, nanosec: 0 },
            frame_id: "camera",
        };
        let decode_err = |m: &msg::BlobMeasurements<'_>| {
            let mut out = VecDeque::new();
            let (field, e) = decode(&encode(m), &mut out).unwrap_err();
            format!("{field}: {e}")
        };
        let good = msg::BlobMeasurements {
            header,
            point_ids: msg::Seq(&[1, 2]),
            u_px: msg::Seq(&[1.0, 2.0]),
            v_px: msg::Seq(&[1.0, 2.0]),
            dt_s: msg::Seq(&[0.0, 1e-4]),
            sigma_px: msg::Seq(&[]),
        };
        let mut out = VecDeque::new();
        decode(&encode(&good), &mut out).unwrap();
        assert_eq!(out.len(), 2);
        let e = decode_err(&msg::BlobMeasurements {
            v_px: msg::Seq(&[1.0]),
            ..good
        });
        assert_eq!(e, "v_px: 1 entries for 2 point ids");
        let e = decode_err(&msg::BlobMeasurements {
            u_px: msg::Seq(&[1.0, f64::NAN]),
            ..good
        });
        assert_eq!(e, "u_px[1]: NaN is not finite");
        let e = decode_err(&msg::BlobMeasurements {
            sigma_px: msg::Seq(&[0.1, -1.0]),
            ..good
        });
        assert_eq!(e, "sigma_px[1]: -1 is not positive");
        let mut short = encode(&good);
        short.truncate(short.len() - 12);
        let (field, e) = decode(&short, &mut out).unwrap_err();
        assert!(field == "dt_s" && e.contains("ends early"), "{field}: {e}");
        // A length no message could hold is refused before anything is allocated.
        let mut huge = encode(&good);
        let at = 4 + 8 + 4 + "camera\0".len() + 1; // encapsulation, stamp, string length, text, padding to 4
        huge[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        let (field, e) = decode(&huge, &mut out).unwrap_err();
        assert!(
            field == "point_ids" && e.contains("cannot fit"),
            "{field}: {e}"
        );
    }
}
