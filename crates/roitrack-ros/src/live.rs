//! [`LiveServer`]: the bag's topics served live over the Foxglove WebSocket protocol while tracking, and [`Pacer`],
//! which replays a recording at its own speed so that a viewer can follow it.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use roitrack_core::{CameraModel, Measurement, MotionState, Target};
use roitrack_estimators::Estimate;
use roitrack_formats::FormatError;
use roitrack_image::Frame;

use crate::output::{LiveChannels, Output};
use crate::{BagOptions, BagWriter, topics};

/// The address a live server listens on unless told otherwise: Foxglove's default, on the loopback interface only.
pub const DEFAULT_LIVE_ADDRESS: &str = "127.0.0.1:8765";

/// The WebSocket subprotocol of the Foxglove SDK's server (Foxglove's app offers it; older clients
/// `foxglove.websocket.v1`, which this server does not speak).
pub const LIVE_SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// Estimates handed over together: one wake-up of the publishing thread per batch rather than per estimate.
const BATCH: usize = 32;
/// A batch is handed over after this long even if it is not full, so that a paced run is seen without delay.
const BATCH_AGE: Duration = Duration::from_millis(20);
/// Batches in flight to the publishing thread; when it is this far behind, further batches are dropped.
const IN_FLIGHT: usize = 16;
/// Messages the server queues for each client before dropping that client's oldest.
const CLIENT_BACKLOG: usize = 4096;

/// Why a live server could not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The address is taken, not local, or not allowed.
    #[error("cannot listen on {address}: {message}")]
    Listen {
        /// The address asked for.
        address: SocketAddr,
        /// Why it could not be listened on.
        message: String,
    },
    /// The server's thread could not be started.
    #[error("cannot start the server's thread: {0}")]
    Thread(#[from] std::io::Error),
    /// The channels could not be set up (a frame id that is empty or holds a NUL).
    #[error(transparent)]
    Channels(#[from] FormatError),
}

// Estimates travel unboxed, by batches in a `Vec`: boxing each would cost an allocation per estimate.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
enum Item {
    Estimate(Estimate),
    Frame(Box<Frame>, Option<MotionState>, Vec<Measurement>),
}

/// What the server's listener sees of the clients.
#[derive(Debug, Default)]
struct Clients {
    /// Subscriptions, all clients and topics together.
    subscriptions: AtomicUsize,
    /// Set when a client subscribes to the camera info: it is sent again with the next estimate.
    camera_info_wanted: AtomicBool,
}

impl foxglove::websocket::ServerListener for Clients {
    fn on_subscribe(
        &self,
        _client: foxglove::websocket::Client,
        channel: foxglove::websocket::ChannelView,
    ) {
        self.subscriptions.fetch_add(1, Ordering::SeqCst);
        if channel.topic() == topics::CAMERA_INFO {
            self.camera_info_wanted.store(true, Ordering::SeqCst);
        }
    }

    fn on_unsubscribe(
        &self,
        _client: foxglove::websocket::Client,
        _channel: foxglove::websocket::ChannelView,
    ) {
        self.subscriptions.fetch_sub(1, Ordering::SeqCst);
    }
}

/// What a live server did: estimates and frames given to it, those left out while no client listened, those dropped
/// because its publishing thread was behind (a client's own queue drops more if the client reads slowly; the server
/// does not count those), and those published.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LiveReport {
    /// Estimates and frames given to the server.
    pub handed: u64,
    /// Of those, left out because no client subscribed to any topic at the time.
    pub unseen: u64,
    /// Of those, dropped before serialisation (the publishing thread was behind).
    pub dropped: u64,
    /// Estimates and frames serialised and published (none while no client subscribes to anything).
    pub published: u64,
}

/// The bag's topics served live over the Foxglove WebSocket protocol (subprotocol `foxglove.sdk.v1`): open
/// `ws://ADDRESS` in Foxglove (Open connection, Foxglove WebSocket) while roitrack tracks.
///
/// Every message is the one [`BagWriter`] writes to the bag, byte for byte (CDR with its `ros2msg` schema, the log
/// time its header stamp): `/roitrack/pose`, `/roitrack/twist`, `/roitrack/odometry`, `/tf`, `/roitrack/status`,
/// `/roitrack/camera_info` (sent again to each client that subscribes to it), and with frames `/roitrack/image` and
/// `/roitrack/annotations`.
///
/// The server runs on threads of its own (a one-worker tokio runtime for the sockets, a publishing thread for the
/// serialisation). [`publish_estimate`](Self::publish_estimate) and [`publish_frame`](Self::publish_frame) never
/// block: while a client subscribes, they copy the item into a batch and hand full batches (or batches 20 ms old) over
/// a bounded queue, dropping the batch if the publishing thread is behind; while none does, they do nothing. A slow client
/// loses its oldest messages (the server keeps 4,096 for each), never holding the others or the tracker back.
///
/// ```no_run
/// use roitrack_ros::{BagOptions, LiveServer};
/// use roitrack_core::CameraModel;
///
/// let address = "127.0.0.1:8765".parse().unwrap();
/// let mut live =
///     LiveServer::start(address, &BagOptions::default(), Some(CameraModel::canonical()), None).unwrap();
/// println!("open ws://{} in Foxglove", live.address());
/// live.wait_for_subscriber(std::time::Duration::from_secs(30));
/// // ... live.publish_estimate(&estimate) for each estimate ...
/// let report = live.finish().unwrap();
/// println!("{} dropped", report.dropped);
/// ```
pub struct LiveServer {
    address: SocketAddr,
    name: PathBuf,
    clients: Arc<Clients>,
    sender: Option<SyncSender<Vec<Item>>>,
    pending: Vec<Item>,
    pending_since: Instant,
    handed: u64,
    unseen: u64,
    dropped: u64,
    thread: Option<JoinHandle<Result<u64, FormatError>>>,
    server: Option<foxglove::WebSocketServerHandle>,
    runtime: Option<tokio::runtime::Runtime>,
}

impl std::fmt::Debug for LiveServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveServer")
            .field("address", &self.address)
            .field("handed", &self.handed)
            .field("dropped", &self.dropped)
            .finish_non_exhaustive()
    }
}

impl LiveServer {
    /// Starts serving on `address` (port 0: a free port, see [`address`](Self::address)). `camera`, if given, is
    /// served on `/roitrack/camera_info`; `target`, if given, is projected into each frame's annotations. Fails,
    /// before anything is served, if the address cannot be listened on (taken, not a local address).
    pub fn start(
        address: SocketAddr,
        options: &BagOptions,
        camera: Option<CameraModel>,
        target: Option<Target>,
    ) -> Result<Self, LiveError> {
        let context = foxglove::Context::new();
        let clients = Arc::new(Clients::default());
        let name = PathBuf::from(format!("ws://{address}"));
        // The channels first: a bad frame id is refused before the port is taken.
        let writer = BagWriter::with_output(
            name.clone(),
            Output::Live(LiveChannels::new(context.clone())),
            options,
            camera,
        )?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("roitrack-foxglove")
            .enable_all()
            .build()?;
        let server = foxglove::WebSocketServer::new()
            .name("roitrack")
            // The server joins host and port with a colon: an IPv6 address goes in brackets.
            .bind(
                match address {
                    SocketAddr::V4(a) => a.ip().to_string(),
                    SocketAddr::V6(a) => format!("[{}]", a.ip()),
                },
                address.port(),
            )
            .context(&context)
            .message_backlog_size(CLIENT_BACKLOG)
            .listener(clients.clone());
        // Started from within our runtime, the server runs its tasks on it.
        let server = runtime
            .block_on(server.start())
            .map_err(|e| LiveError::Listen {
                address,
                message: match e {
                    foxglove::FoxgloveError::Bind(io) => io.to_string(),
                    other => other.to_string(),
                },
            })?;
        let address = SocketAddr::new(address.ip(), server.port());
        let name = PathBuf::from(format!("ws://{address}"));
        let (sender, receiver) = sync_channel(IN_FLIGHT);
        let publishing = clients.clone();
        let thread = std::thread::Builder::new()
            .name("roitrack-live".into())
            .spawn(move || run(writer, target, publishing, receiver))?;
        Ok(Self {
            address,
            name,
            clients,
            sender: Some(sender),
            pending: Vec::with_capacity(BATCH),
            pending_since: Instant::now(),
            handed: 0,
            unseen: 0,
            dropped: 0,
            thread: Some(thread),
            server: Some(server),
            runtime: Some(runtime),
        })
    }

    /// The address served (with the port chosen when 0 was asked for).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// The number of subscriptions of all clients together.
    pub fn subscriptions(&self) -> usize {
        self.clients.subscriptions.load(Ordering::SeqCst)
    }

    /// Waits until a client subscribes to a topic, at most `timeout`, then a moment more (100 ms) for the client's
    /// other subscriptions; says whether one did.
    pub fn wait_for_subscriber(&self, timeout: Duration) -> bool {
        let start = Instant::now();
        while self.subscriptions() == 0 {
            if start.elapsed() >= timeout {
                return false;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_millis(100));
        true
    }

    fn hand_over(&mut self, item: Item, now: bool) -> Result<(), FormatError> {
        self.handed += 1;
        // Nobody to show it to: not even handed over (an atomic load is all a run without a viewer pays).
        if self.subscriptions() == 0 {
            self.unseen += 1;
            return Ok(());
        }
        if self.pending.is_empty() {
            self.pending_since = Instant::now();
        }
        self.pending.push(item);
        if now || self.pending.len() >= BATCH || self.pending_since.elapsed() >= BATCH_AGE {
            self.flush()?;
        }
        Ok(())
    }

    /// Hands the pending items over without waiting: dropped if the publishing thread is behind.
    fn flush(&mut self) -> Result<(), FormatError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let batch = std::mem::replace(&mut self.pending, Vec::with_capacity(BATCH));
        let count = batch.len() as u64;
        let result = match &self.sender {
            Some(sender) => sender.try_send(batch),
            None => Err(TrySendError::Disconnected(batch)),
        };
        match result {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => {
                self.dropped += count;
                Ok(())
            }
            Err(TrySendError::Disconnected(_)) => {
                self.dropped += count;
                // The publishing thread stopped: its error says why.
                Err(self.join().err().unwrap_or_else(|| {
                    FormatError::new(
                        &self.name,
                        "the live server's publishing thread has stopped",
                    )
                }))
            }
        }
    }

    /// Hands an estimate over (never waits); an error only if the publishing thread stopped on one (a time a ROS
    /// stamp cannot hold).
    pub fn publish_estimate(&mut self, estimate: &Estimate) -> Result<(), FormatError> {
        self.hand_over(Item::Estimate(*estimate), false)
    }

    /// Hands a frame over (never waits), with the state of its estimate if it has one and the centroids measured in
    /// it; see [`BagWriter::write_frame`].
    pub fn publish_frame(
        &mut self,
        frame: Frame,
        state: Option<&MotionState>,
        measured: &[Measurement],
    ) -> Result<(), FormatError> {
        self.hand_over(
            Item::Frame(Box::new(frame), state.copied(), measured.to_vec()),
            true,
        )
    }

    fn join(&mut self) -> Result<u64, FormatError> {
        self.sender = None;
        match self.thread.take() {
            Some(thread) => thread.join().unwrap_or_else(|_| {
                Err(FormatError::new(
                    &self.name,
                    "the live server's publishing thread panicked",
                ))
            }),
            None => Ok(0),
        }
    }

    /// Publishes what is pending (waiting for the publishing thread this once), lets a connected client receive
    /// the last messages (a quarter of a second), and stops the server.
    pub fn finish(mut self) -> Result<LiveReport, FormatError> {
        let last = std::mem::take(&mut self.pending);
        if !last.is_empty()
            && let Some(sender) = &self.sender
        {
            // The publishing thread drains its queue, so this wait is short; if it stopped, its error is below.
            let _ = sender.send(last);
        }
        let published = self.join();
        if self.server.as_ref().is_some_and(|s| s.client_count() > 0) {
            std::thread::sleep(Duration::from_millis(250));
        }
        self.stop();
        Ok(LiveReport {
            handed: self.handed,
            unseen: self.unseen,
            dropped: self.dropped,
            published: published?,
        })
    }

    fn stop(&mut self) {
        if let Some(server) = self.server.take() {
            // Dropping the shutdown handle ends the clients' tasks at once.
            drop(server.stop());
        }
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_timeout(Duration::from_secs(1));
        }
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        let _ = self.join();
        self.stop();
    }
}

fn run(
    mut writer: BagWriter,
    target: Option<Target>,
    clients: Arc<Clients>,
    receiver: Receiver<Vec<Item>>,
) -> Result<u64, FormatError> {
    let mut published = 0;
    for item in receiver.into_iter().flatten() {
        // Nothing to serialise while no client listens.
        if clients.subscriptions.load(Ordering::Relaxed) == 0 {
            continue;
        }
        if clients.camera_info_wanted.swap(false, Ordering::SeqCst) {
            writer.resend_camera_info();
        }
        match item {
            Item::Estimate(estimate) => writer.write_estimate(&estimate)?,
            Item::Frame(frame, state, measured) => {
                let projection = state.as_ref().zip(target.as_ref());
                writer.write_frame(&frame, projection, &measured)?;
            }
        }
        published += 1;
    }
    writer.finish()?;
    Ok(published)
}

/// Replays a recording at its own speed: [`wait_until`](Self::wait_until) an item's time sleeps until that time,
/// counted from the first item's, has passed on the wall clock (divided by the speed factor: 2 plays twice as
/// fast). An item already late is not waited for, and the lateness is not made up by hurrying later ones.
///
/// ```
/// let mut pacer = roitrack_ros::Pacer::new(10.0).unwrap();
/// let start = std::time::Instant::now();
/// pacer.wait_until(5.0); // the first item: no wait
/// pacer.wait_until(5.5); // 0.5 s of recording at 10 times its speed: 50 ms after the first
/// assert!(start.elapsed() >= std::time::Duration::from_millis(50));
/// assert!(roitrack_ros::Pacer::new(0.0).is_none());
/// ```
#[derive(Debug, Clone, Copy)]
pub struct Pacer {
    factor: f64,
    origin: Option<(f64, Instant)>,
}

impl Pacer {
    /// A pacer at `factor` times the recording's speed (finite and positive; else `None`).
    pub fn new(factor: f64) -> Option<Self> {
        (factor.is_finite() && factor > 0.0).then_some(Self {
            factor,
            origin: None,
        })
    }

    /// Sleeps until the wall time of `t_s` (s, the recording's clock); the first call sets the origin.
    pub fn wait_until(&mut self, t_s: f64) {
        let Some((t0_s, wall0)) = self.origin else {
            self.origin = Some((t_s, Instant::now()));
            return;
        };
        let due_s = (t_s - t0_s) / self.factor;
        if !due_s.is_finite() || due_s <= 0.0 {
            return;
        }
        let due = wall0 + Duration::from_secs_f64(due_s.min(1e9));
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
    }
}
