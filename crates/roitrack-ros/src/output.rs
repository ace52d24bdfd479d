//! Where a [`BagWriter`](crate::BagWriter)'s serialised messages go: an MCAP file, the channels of a Foxglove live
//! server, or the writers of a ROS 2 node on the DDS bus (feature `ros2`). One writer builds and serialises every
//! message for all three, so that a message of the bag and the same message served live or published are the same
//! bytes.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
#[cfg(feature = "live")]
use std::sync::Arc;

use mcap::McapResult;
use mcap::records::MessageHeader;
use roitrack_formats::{AtomicFile, FormatError};

/// An MCAP file, the channels of a live server or the writers of a ROS 2 node; the calls are those of `mcap::Writer`
/// that the bag uses.
// One per writer, for its whole life: the size of the MCAP variant does not matter.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Output {
    Mcap(McapFile),
    #[cfg(feature = "live")]
    Live(LiveChannels),
    #[cfg(feature = "ros2")]
    Dds(crate::ros2::DdsChannels),
}

/// An MCAP file being written: to a temporary beside its path ([`AtomicFile`]), handed over when closed. Dropped
/// without [`Self::close`] (an error, a panic, an interrupted run), the bag is completed up to its last message and
/// handed over all the same: moved into place at once without an open output set; with one, deleted if the run fails,
/// unless marked with [`roitrack_formats::keep_if_failed`] (then kept as `NAME.partial.mcap`).
pub(crate) struct McapFile {
    path: PathBuf,
    writer: Option<mcap::Writer<BufWriter<AtomicFile>>>,
}

impl McapFile {
    pub(crate) fn new(path: &Path, writer: mcap::Writer<BufWriter<AtomicFile>>) -> Self {
        Self {
            path: path.to_path_buf(),
            writer: Some(writer),
        }
    }

    fn writer(&mut self) -> McapResult<&mut mcap::Writer<BufWriter<AtomicFile>>> {
        self.writer.as_mut().ok_or_else(|| {
            mcap::McapError::Io(std::io::Error::other("the bag was already completed"))
        })
    }

    /// Completes the bag and hands its file over (renamed into place, or staged for the run's commit).
    pub(crate) fn close(&mut self) -> Result<(), FormatError> {
        let Some(mut writer) = self.writer.take() else {
            return Ok(());
        };
        writer
            .finish()
            .map_err(|e| FormatError::new(&self.path, format!("cannot complete the bag: {e}")))?;
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| FormatError::io(&self.path, "cannot write", e.into_error()))?;
        file.finish()
    }
}

impl Drop for McapFile {
    fn drop(&mut self) {
        let _ = self.close();
    }
}

/// The schemas and channels of a live server, indexed by the ids handed out (as MCAP's are).
#[cfg(feature = "live")]
pub(crate) struct LiveChannels {
    context: Arc<foxglove::Context>,
    schemas: Vec<foxglove::Schema>,
    channels: Vec<Arc<foxglove::RawChannel>>,
}

#[cfg(feature = "live")]
impl LiveChannels {
    pub(crate) fn new(context: Arc<foxglove::Context>) -> Self {
        Self {
            context,
            schemas: Vec::new(),
            channels: Vec::new(),
        }
    }
}

#[cfg(feature = "live")]
fn live_error(message: String) -> mcap::McapError {
    mcap::McapError::Io(std::io::Error::other(message))
}

impl Output {
    /// Hands an MCAP file over to its path ([`McapFile::close`]); a live server's or a ROS 2 node's channels have
    /// nothing to close.
    pub(crate) fn close(&mut self) -> Result<(), FormatError> {
        match self {
            Self::Mcap(file) => file.close(),
            #[cfg(feature = "live")]
            Self::Live(_) => Ok(()),
            #[cfg(feature = "ros2")]
            Self::Dds(_) => Ok(()),
        }
    }

    pub(crate) fn add_schema(
        &mut self,
        name: &str,
        encoding: &str,
        data: &[u8],
    ) -> McapResult<u16> {
        match self {
            Self::Mcap(file) => file.writer()?.add_schema(name, encoding, data),
            #[cfg(feature = "live")]
            Self::Live(live) => {
                live.schemas
                    .push(foxglove::Schema::new(name, encoding, data.to_vec()));
                u16::try_from(live.schemas.len() - 1)
                    .map_err(|_| live_error("too many schemas".into()))
            }
            // A ROS 2 topic is typed by its name only: the schema's text is not sent.
            #[cfg(feature = "ros2")]
            Self::Dds(dds) => dds.add_type(name),
        }
    }

    pub(crate) fn add_channel(
        &mut self,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> McapResult<u16> {
        match self {
            Self::Mcap(file) => {
                file.writer()?
                    .add_channel(schema_id, topic, message_encoding, metadata)
            }
            #[cfg(feature = "live")]
            Self::Live(live) => {
                let schema = live
                    .schemas
                    .get(usize::from(schema_id))
                    .cloned()
                    .ok_or_else(|| live_error(format!("{topic}: no schema {schema_id}")))?;
                let channel = live
                    .context
                    .channel_builder(topic)
                    .schema(schema)
                    .message_encoding(message_encoding)
                    .metadata(metadata.clone())
                    .build_raw()
                    .map_err(|e| live_error(format!("cannot serve {topic}: {e}")))?;
                live.channels.push(channel);
                u16::try_from(live.channels.len() - 1)
                    .map_err(|_| live_error("too many channels".into()))
            }
            #[cfg(feature = "ros2")]
            Self::Dds(dds) => dds.add_topic(schema_id, topic),
        }
    }

    pub(crate) fn write_to_known_channel(
        &mut self,
        header: &MessageHeader,
        data: &[u8],
    ) -> McapResult<()> {
        match self {
            Self::Mcap(file) => file.writer()?.write_to_known_channel(header, data),
            #[cfg(feature = "live")]
            Self::Live(live) => {
                let channel = live
                    .channels
                    .get(usize::from(header.channel_id))
                    .ok_or(mcap::McapError::UnknownChannel(0, header.channel_id))?;
                // Never blocks: the server queues the message for each subscribed client, dropping that client's
                // oldest when its queue is full.
                channel.log_with_meta(
                    data,
                    foxglove::PartialMetadata {
                        log_time: Some(header.log_time),
                    },
                );
                Ok(())
            }
            #[cfg(feature = "ros2")]
            Self::Dds(dds) => dds.write(header.channel_id, data),
        }
    }

    /// The messages of one estimate are all written: a DDS output sends them now, back to back (see
    /// `DdsChannels::flush`); the others have written each as it came.
    pub(crate) fn end_of_estimate(&mut self) -> McapResult<()> {
        match self {
            #[cfg(feature = "ros2")]
            Self::Dds(dds) => dds.flush(),
            _ => Ok(()),
        }
    }

    pub(crate) fn finish(&mut self) -> McapResult<()> {
        match self {
            Self::Mcap(file) => file.writer()?.finish().map(|_| ()),
            #[cfg(feature = "live")]
            Self::Live(live) => {
                for channel in &live.channels {
                    channel.close();
                }
                Ok(())
            }
            #[cfg(feature = "ros2")]
            Self::Dds(dds) => dds.flush(),
        }
    }
}
