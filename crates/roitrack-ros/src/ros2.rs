//! [`Ros2Publisher`] (feature `ros2`): the bag's estimate topics published live on the ROS 2 DDS bus, as a ROS 2
//! node named `roitrack` (through `ros2-client` on RustDDS, pure Rust: no ROS install), so that a robot's
//! controller, `ros2 topic echo` and RViz subscribe to them while roitrack tracks.

use std::net::IpAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering, fence};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use roitrack_core::CameraModel;
use roitrack_estimators::Estimate;
use roitrack_formats::FormatError;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile, WriteError,
    qos::{Durability, History, Reliability, WhenFull},
};

use crate::input_counts::InputCounts;
use crate::output::Output;
use crate::{BagOptions, BagWriter, topics};

/// The ROS 2 node's name (its namespace is [`Ros2Options::namespace`]).
pub const NODE_NAME: &str = "roitrack";

/// The highest DDS domain id: RTPS puts domain `d` on UDP ports from `7400 + 250 d`, which must fit in 16 bits.
pub const MAX_DOMAIN_ID: u16 = 232;

/// Estimates in flight between the tracking thread and the publishing thread; when it is this far behind, further
/// estimates are dropped (counted in [`Ros2Report::dropped`]), never waited for.
const IN_FLIGHT: usize = 1024;
/// How long the publishing thread sleeps when no estimate has come for [`POLL_FOR`], unless woken by the next one
/// (a hand-over wakes it only then: it announced the sleep).
const IDLE_SLEEP: Duration = Duration::from_millis(20);
/// While estimates come (one within [`POLL_FOR`]), the publishing thread looks at the ring this often, on a timer,
/// rather than being woken by each hand-over: the tracking thread then makes no system call per estimate.
const POLL_INTERVAL: Duration = Duration::from_micros(50);
/// How long after the last estimate the publishing thread keeps polling before it announces a long sleep: longer
/// than the time between two estimates of a tracker at 50 Hz or faster, so that a steady stream never finds it
/// asleep; a slower one (a 30 Hz frame camera) wakes it at each estimate, which then costs little beside tracking.
const POLL_FOR: Duration = Duration::from_millis(20);
/// How long before the next estimate is due (the last one's time plus the time between estimates) the publishing
/// thread starts looking at the ring every [`POLL_INTERVAL`]; until then it sleeps.
const POLL_LEAD: Duration = Duration::from_micros(300);
/// The history depth of the estimate topics' writers. ROS 2's sensor-data profile keeps 5, but RustDDS sends from a
/// thread of its own, out of the writer's history: with 5, a burst of estimates (or that thread held up for a few
/// milliseconds) lost samples before they were sent (measured in docs/results.md, "Design measurements behind the
/// code"). History is not a QoS that subscribers are matched on: each keeps its own depth.
const ESTIMATE_DEPTH: usize = 100;
/// The depth of `/tf`'s QoS, tf2's own broadcaster's: reliable, volatile, keep last 100.
const TF_DEPTH: usize = 100;
/// After every estimate topic has a subscriber, how long [`Ros2Options::wait_for_subscribers_s`] waits more for the
/// subscribers' side of the discovery (their matching of roitrack's writers) to complete.
const SETTLE: Duration = Duration::from_millis(300);

/// Where and how the node publishes (by default: domain 0, no namespace, no wait).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Ros2Options {
    /// The DDS domain (`ROS_DOMAIN_ID`, 0 to [`MAX_DOMAIN_ID`]): only participants of the same domain see each other.
    pub domain_id: u16,
    /// The node's namespace, also put before every topic (`/robot1`: `/robot1/roitrack/pose`, `/robot1/tf`); empty
    /// or `/` for none.
    pub namespace: String,
    /// Before the first estimate, wait up to this long (s) for a subscriber on every estimate topic (pose, twist,
    /// odometry, tf, status), so that it receives the run from its start; `None`: no wait.
    pub wait_for_subscribers_s: Option<f64>,
    /// The addresses of the local network interfaces DDS uses (multicast discovery and the locators it announces),
    /// each on an interface that is up; empty: every interface that is up.
    pub interfaces: Vec<IpAddr>,
}

/// Why the publisher could not start (before any estimate was handed over).
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// A domain id beyond [`MAX_DOMAIN_ID`].
    #[error("domain id {0}: DDS domains are 0 to {MAX_DOMAIN_ID}")]
    Domain(u16),
    /// No network interface that is up (with an address, or with one of [`Ros2Options::interfaces`]).
    #[error("{0}")]
    Interface(String),
    /// A namespace ROS 2 does not accept.
    #[error("namespace {namespace:?}: {message}")]
    Namespace {
        /// The namespace given.
        namespace: String,
        /// Why ROS 2 refuses it.
        message: String,
    },
    /// The DDS participant, the node or a topic could not be created: no usable network interface, the domain's
    /// ports taken, ...
    #[error("cannot start the ROS 2 node on domain {domain_id}: {message}")]
    Start {
        /// The DDS domain the node was to join.
        domain_id: u16,
        /// What RustDDS or ros2-client said.
        message: String,
    },
    /// What a node needed from the bus did not come (a camera info).
    #[error("{0}")]
    Input(String),
    /// A topic or its writer could not be created, or a frame id is empty or holds a NUL.
    #[error(transparent)]
    Topics(#[from] FormatError),
    /// The publishing thread could not be started.
    #[error("cannot start the publishing thread: {0}")]
    Thread(#[from] std::io::Error),
}

/// What a publisher did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ros2Report {
    /// Estimates handed over.
    pub handed: u64,
    /// Of those, dropped before publishing because the publishing thread was behind.
    pub dropped: u64,
    /// Estimates published (five messages each, and the camera info with the first).
    pub published: u64,
    /// Messages of a reliable topic (`/tf`, the camera info) that DDS refused because a subscriber had not
    /// acknowledged enough earlier ones (the send window was full): not published, never waited for.
    pub refused: u64,
    /// Whether every estimate topic had a subscriber when the wait for them ended (always `false` without a wait).
    pub subscribed_at_start: bool,
}

/// The QoS of a topic: the sensor-data profile's best effort and volatile durability for the estimates and the
/// status, which a tracker outdates at once (keep last 100 rather than 5: RustDDS sends from its own thread out of
/// the writer's history, and a burst must not overwrite estimates before they are sent; history is not matched on);
/// reliable and transient local (keep last 1, latched: a late subscriber gets it) for the camera info; reliable and
/// volatile (keep last 100) for `/tf`, tf2's own broadcaster's QoS, since tf2's listeners (RViz's too) request
/// reliable and DDS does not match them with a best-effort writer. A reliable writer never waits: a message that the
/// send window has no room for is refused and counted.
///
/// ```
/// use roitrack_ros::ros2::qos_of;
/// use ros2_client::qos::{Durability, Reliability};
///
/// assert_eq!(qos_of("/roitrack/pose").reliability, Reliability::BestEffort);
/// assert_eq!(qos_of("/roitrack/camera_info").durability, Durability::TransientLocal);
/// ```
pub fn qos_of(topic: &str) -> QosProfile {
    let base = QosProfile::subscription_default();
    if topic == topics::CAMERA_INFO {
        base.reliability_reliable(WhenFull::Fail)
            .durability(Durability::TransientLocal)
            .history(History::KeepLast { depth: 1 })
    } else if topic == topics::TF {
        base.reliability_reliable(WhenFull::Fail)
            .history(History::KeepLast { depth: TF_DEPTH })
    } else {
        base.reliability(Reliability::BestEffort)
            .history(History::KeepLast {
                depth: ESTIMATE_DEPTH,
            })
    }
}

/// The namespace as ROS 2 writes it: `""` for none, else `/a/b` (a leading slash, none trailing).
pub(crate) fn normalised_namespace(namespace: &str) -> String {
    let trimmed = namespace.trim().trim_end_matches('/');
    match trimmed {
        "" => String::new(),
        t if t.starts_with('/') => t.to_string(),
        t => format!("/{t}"),
    }
}

/// The ROS 2 name of a bag topic in a namespace: `/robot1` and `/roitrack/pose` make `/robot1/roitrack/pose`.
///
/// ```
/// use roitrack_ros::ros2::topic_name;
/// assert_eq!(topic_name("robot1/", "/tf"), "/robot1/tf");
/// assert_eq!(topic_name("", "/roitrack/pose"), "/roitrack/pose");
/// ```
pub fn topic_name(namespace: &str, topic: &str) -> String {
    format!("{}{topic}", normalised_namespace(namespace))
}

/// A CDR body already serialised (by [`BagWriter`], without its 4-byte encapsulation header), written as it is:
/// serde's tuple of bytes, which CDR writes without a length or padding (bytes have no alignment).
struct RawCdr(Vec<u8>);

impl serde::Serialize for RawCdr {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut tuple = serializer.serialize_tuple(self.0.len())?;
        for byte in &self.0 {
            tuple.serialize_element(byte)?;
        }
        tuple.end()
    }
}

/// CDR little endian's encapsulation header, which [`BagWriter`] puts before each message and DDS writes itself.
const CDR_LE_HEADER: [u8; 4] = [0, 1, 0, 0];

/// The node's writers, indexed by the channel ids handed out to the bag writer (as MCAP's are).
pub(crate) struct DdsChannels {
    node: Node,
    namespace: String,
    types: Vec<MessageTypeName>,
    publishers: Vec<(String, Publisher<RawCdr>)>,
    refused: Arc<AtomicU64>,
    /// The messages of the estimate being written, by channel, sent together by [`flush`](Self::flush).
    pending: Vec<(u16, RawCdr)>,
}

fn dds_error(message: String) -> mcap::McapError {
    mcap::McapError::Io(std::io::Error::other(message))
}

impl DdsChannels {
    pub(crate) fn add_type(&mut self, full_name: &str) -> mcap::McapResult<u16> {
        let mut parts = full_name.split('/');
        let (Some(package), Some("msg"), Some(name), None) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            return Err(dds_error(format!("{full_name}: not a pkg/msg/Type name")));
        };
        self.types.push(MessageTypeName::new(package, name));
        u16::try_from(self.types.len() - 1).map_err(|_| dds_error("too many types".into()))
    }

    pub(crate) fn add_topic(&mut self, type_id: u16, topic: &str) -> mcap::McapResult<u16> {
        let type_name = self
            .types
            .get(usize::from(type_id))
            .cloned()
            .ok_or_else(|| dds_error(format!("{topic}: no type {type_id}")))?;
        let full = topic_name(&self.namespace, topic);
        let name = Name::parse(&full).map_err(|e| dds_error(format!("topic {full}: {e}")))?;
        let qos = qos_of(topic);
        let dds_topic = self
            .node
            .create_topic(&name, type_name, &qos)
            .map_err(|e| dds_error(format!("cannot create the topic {full}: {e}")))?;
        let publisher = self
            .node
            .create_publisher(&dds_topic, Some(qos))
            .map_err(|e| dds_error(format!("cannot publish {full}: {e}")))?;
        self.publishers.push((full, publisher));
        u16::try_from(self.publishers.len() - 1).map_err(|_| dds_error("too many topics".into()))
    }

    /// Takes one message of the estimate being written; [`flush`](Self::flush) sends them.
    pub(crate) fn write(&mut self, channel_id: u16, data: &[u8]) -> mcap::McapResult<()> {
        let (name, _) = self
            .publishers
            .get(usize::from(channel_id))
            .ok_or(mcap::McapError::UnknownChannel(0, channel_id))?;
        let body = data
            .strip_prefix(&CDR_LE_HEADER)
            .ok_or_else(|| dds_error(format!("{name}: not CDR little endian")))?;
        self.pending.push((channel_id, RawCdr(body.to_vec())));
        Ok(())
    }

    /// Sends the messages taken since the last flush, in order, back to back. Each DDS write wakes RustDDS's
    /// event-loop thread, which sends what is waiting when it runs: messages serialised and sent one at a time
    /// (five an estimate, each after the conversions of the next) woke it up to five times an estimate, written
    /// together they mostly find it once.
    pub(crate) fn flush(&mut self) -> mcap::McapResult<()> {
        for (channel_id, body) in self.pending.drain(..) {
            let (name, publisher) = &self.publishers[usize::from(channel_id)];
            match publisher.publish(body) {
                Ok(()) => {}
                Err(WriteError::WouldBlock { .. }) => {
                    self.refused.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => return Err(dds_error(format!("cannot publish {name}: {e}"))),
            }
        }
        Ok(())
    }
}

/// What the tracking thread and the publishing thread share.
#[derive(Debug, Default)]
struct Shared {
    /// Set when nothing more will be handed over: the publishing thread then empties the queue and ends.
    closed: AtomicBool,
    published: AtomicU64,
    /// Set by the publishing thread before a long sleep ([`IDLE_SLEEP`]): the next hand-over wakes it.
    asleep: AtomicBool,
}

/// The estimates published live on the ROS 2 DDS bus, as the node `roitrack` in the domain and namespace of
/// [`Ros2Options`]: the topics and types of the bag (docs/ros2.md), each message the one [`BagWriter`] writes to the
/// bag, byte for byte, with the ROS 2 naming of DDS topics (`/roitrack/pose` is the DDS topic `rt/roitrack/pose`
/// of type `geometry_msgs::msg::dds_::PoseWithCovarianceStamped_`) and the QoS of [`qos_of`]. Per estimate:
/// `/roitrack/pose`, `/roitrack/twist`, `/roitrack/odometry`, `/tf`, `/roitrack/status`; the camera info once, with
/// the first estimate, latched for late subscribers.
///
/// The node runs on a thread of its own (with RustDDS's own threads): [`publish_estimate`](Self::publish_estimate)
/// copies the estimate into a ring, never waiting, and makes no system call while estimates come: that thread looks
/// at the ring on a timer, from shortly before the next estimate is due, and is woken by a hand-over only after it
/// announced a long sleep (no estimate for 20 ms). An estimate that finds the ring full (the publishing thread 1,024
/// estimates behind) is dropped and counted.
///
/// ```no_run
/// use roitrack_ros::ros2::{Ros2Options, Ros2Publisher};
/// use roitrack_ros::BagOptions;
/// use roitrack_core::CameraModel;
///
/// let options = Ros2Options { domain_id: 7, ..Ros2Options::default() };
/// let mut publisher =
///     Ros2Publisher::start(&options, &BagOptions::default(), Some(CameraModel::canonical())).unwrap();
/// // ... publisher.publish_estimate(&estimate) for each estimate ...
/// let report = publisher.finish().unwrap();
/// println!("{} estimates published, {} dropped", report.published, report.dropped);
/// ```
pub struct Ros2Publisher {
    queue: rtrb::Producer<Estimate>,
    shared: Arc<Shared>,
    refused: Arc<AtomicU64>,
    handed: u64,
    dropped: u64,
    subscribed_at_start: bool,
    thread: Option<JoinHandle<Result<(), FormatError>>>,
    description: String,
}

impl std::fmt::Debug for Ros2Publisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Publisher")
            .field("node", &self.description)
            .field("handed", &self.handed)
            .field("dropped", &self.dropped)
            .finish_non_exhaustive()
    }
}

/// What the publishing thread says when it has started (or could not).
type Started = Result<bool, Ros2Error>;

impl Ros2Publisher {
    /// Starts the node and its writers (and, with [`Ros2Options::wait_for_subscribers_s`], waits for subscribers).
    /// `camera`, if given, is published on `/roitrack/camera_info`. Fails, before any estimate, with what stopped
    /// it: a bad domain id or namespace, no network interface DDS can use, the domain's ports taken.
    pub fn start(
        options: &Ros2Options,
        bag_options: &BagOptions,
        camera: Option<CameraModel>,
    ) -> Result<Self, Ros2Error> {
        Self::start_with(options, bag_options, camera, None)
    }

    /// [`start`](Self::start) for a node that takes its input from the bus: each status also carries `inputs`, the
    /// messages it took and those it left out by reason ([`status_keys`](crate::status_keys)), as they stand when
    /// the status is published.
    pub fn start_counting_inputs(
        options: &Ros2Options,
        bag_options: &BagOptions,
        camera: Option<CameraModel>,
        inputs: Arc<InputCounts>,
    ) -> Result<Self, Ros2Error> {
        Self::start_with(options, bag_options, camera, Some(inputs))
    }

    fn start_with(
        options: &Ros2Options,
        bag_options: &BagOptions,
        camera: Option<CameraModel>,
        inputs: Option<Arc<InputCounts>>,
    ) -> Result<Self, Ros2Error> {
        if options.domain_id > MAX_DOMAIN_ID {
            return Err(Ros2Error::Domain(options.domain_id));
        }
        check_interfaces(&options.interfaces)?;
        let namespace = normalised_namespace(&options.namespace);
        let node_name = NodeName::new(
            if namespace.is_empty() {
                "/"
            } else {
                &namespace
            },
            NODE_NAME,
        )
        .map_err(|e| Ros2Error::Namespace {
            namespace: options.namespace.clone(),
            message: e.to_string(),
        })?;
        let description = format!(
            "ROS 2 node {} on domain {}",
            node_name.fully_qualified_name(),
            options.domain_id
        );
        let (queue, receiver) = rtrb::RingBuffer::new(IN_FLIGHT);
        let shared = Arc::new(Shared::default());
        let refused = Arc::new(AtomicU64::new(0));
        let (started_sender, started) = mpsc::sync_channel::<Started>(1);
        let thread = {
            let (options, bag_options) = (options.clone(), bag_options.clone());
            let (shared, refused) = (Arc::clone(&shared), Arc::clone(&refused));
            let description = description.clone();
            std::thread::Builder::new()
                .name("roitrack-ros2".into())
                .spawn(move || {
                    // Before the participant is built: RustDDS's threads, which it starts, inherit the policy.
                    yield_to_the_tracker();
                    let (mut writer, context) = match open(
                        &options,
                        node_name,
                        namespace.clone(),
                        &bag_options,
                        camera,
                        refused,
                        &description,
                    ) {
                        Ok(writer) => writer,
                        Err(e) => {
                            let _ = started_sender.send(Err(e));
                            return Ok(());
                        }
                    };
                    if let Some(inputs) = inputs {
                        writer.count_inputs(inputs);
                    }
                    // RustDDS's threads are started: this one alone looks at the ring on time from now on.
                    poll_on_time();
                    let subscribed =
                        wait_for_subscribers(&context, &namespace, options.wait_for_subscribers_s);
                    let _ = started_sender.send(Ok(subscribed));
                    run(writer, receiver, &shared)
                })?
        };
        let subscribed_at_start = match started.recv() {
            Ok(started) => started?,
            Err(_) => {
                return Err(Ros2Error::Start {
                    domain_id: options.domain_id,
                    message: "the publishing thread ended while starting".into(),
                });
            }
        };
        Ok(Self {
            queue,
            shared,
            refused,
            handed: 0,
            dropped: 0,
            subscribed_at_start,
            thread: Some(thread),
            description,
        })
    }

    /// What is published where: `ROS 2 node /NAMESPACE/roitrack on domain D`.
    pub fn description(&self) -> &str {
        &self.description
    }

    /// Whether every estimate topic had a subscriber when the wait for them ended.
    pub fn subscribed_at_start(&self) -> bool {
        self.subscribed_at_start
    }

    /// Hands an estimate over, and wakes the publishing thread if it announced a long sleep (never waits: dropped,
    /// and counted, if that thread is 1,024 estimates behind); an error only if the publishing thread stopped on one (a time a ROS stamp cannot
    /// hold, a DDS write that failed).
    pub fn publish_estimate(&mut self, estimate: &Estimate) -> Result<(), FormatError> {
        self.handed += 1;
        if self.queue.is_abandoned() {
            self.dropped += 1;
            return Err(self.join().err().unwrap_or_else(|| {
                FormatError::new(&self.description, "the publishing thread has stopped")
            }));
        }
        if self.queue.push(*estimate).is_err() {
            self.dropped += 1;
        }
        // The push before the look at the flag, as the publishing thread's announcement before its last look at the
        // ring: one of the two sees the other.
        fence(Ordering::SeqCst);
        if self.shared.asleep.load(Ordering::Relaxed)
            && let Some(thread) = &self.thread
        {
            thread.thread().unpark();
        }
        Ok(())
    }

    fn join(&mut self) -> Result<(), FormatError> {
        self.shared.closed.store(true, Ordering::Release);
        match self.thread.take() {
            Some(thread) => {
                thread.thread().unpark();
                thread.join().unwrap_or_else(|_| {
                    Err(FormatError::new(
                        &self.description,
                        "the publishing thread panicked",
                    ))
                })
            }
            None => Ok(()),
        }
    }

    /// Publishes what was handed over, stops the node and says what it did.
    pub fn finish(mut self) -> Result<Ros2Report, FormatError> {
        self.join()?;
        Ok(Ros2Report {
            handed: self.handed,
            dropped: self.dropped,
            published: self.shared.published.load(Ordering::Acquire),
            refused: self.refused.load(Ordering::Relaxed),
            subscribed_at_start: self.subscribed_at_start,
        })
    }
}

impl Drop for Ros2Publisher {
    fn drop(&mut self) {
        let _ = self.join();
    }
}

/// Puts the calling thread (and the threads it starts from now on) under Linux's `SCHED_BATCH` policy: a thread woken
/// under it never preempts the thread that woke it. Each hand-over used to wake the publishing thread, which wakes
/// RustDDS's; under the default policy the woken thread often took the tracking thread's core at once, and the
/// tracking waited for five messages to be serialised and sent, which multiplied its busy time per estimate under
/// load. Under `SCHED_BATCH` they run on a free core, or when the tracking thread sleeps. RustDDS's threads, which the
/// publishing thread wakes at each write, keep it; the publishing thread itself returns to the default policy once
/// they are started ([`poll_on_time`]). Their weight is left as it is: a nice value of 10 as
/// well lowered the tracking's cost further under load, but RustDDS then fell behind and lost estimates, uncounted.
/// Both measured with `examples/ros2_cost.rs` (docs/ros2.md, "Cost to the tracking, measured in one run"). Where the
/// policy cannot be set (not Linux), nothing changes.
fn yield_to_the_tracker() {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: sched_setscheduler on the calling thread (pid 0) with a valid parameter; it only reads `param`.
        let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_BATCH, &param) };
    }
}

/// Puts the publishing thread (not RustDDS's threads, started before, which stay under `SCHED_BATCH`) back under the
/// default policy, with a timer slack of 1 µs rather than Linux's 50 µs: it wakes on its own timer to look at the
/// ring ([`POLL_INTERVAL`]), and under `SCHED_BATCH` a timer's wake-up waited for the busy core's time slice (the
/// publish latency's median rose by 300 to 900 µs); woken by its timer rather than by the tracking thread, it no
/// longer needs to yield to it. Measured with `examples/ros2_cost.rs` (docs/ros2.md, "Cost to the tracking, measured in
/// one run"). Where neither can be set (not Linux), nothing changes.
fn poll_on_time() {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: sched_setscheduler on the calling thread (pid 0) with a valid parameter; it only reads `param`.
        let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
        const TIMER_SLACK_NS: libc::c_ulong = 1_000;
        // SAFETY: PR_SET_TIMERSLACK on the calling thread, with an integer argument.
        let _ = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, TIMER_SLACK_NS, 0, 0, 0) };
    }
}

/// The IPv4 addresses of the network interfaces that are up (DDS, RustDDS's transport, speaks IPv4).
fn addresses_up() -> Vec<IpAddr> {
    netdev::get_interfaces()
        .iter()
        .filter(|interface| interface.is_up())
        .flat_map(|interface| interface.ipv4.iter().map(|net| IpAddr::V4(net.addr())))
        .collect()
}

/// Refuses a start with no network interface up (DDS would then publish to nobody, silently), or with an address
/// asked for that no interface that is up has.
pub(crate) fn check_interfaces(wanted: &[IpAddr]) -> Result<(), Ros2Error> {
    let up = addresses_up();
    let list = |addresses: &[IpAddr]| {
        addresses
            .iter()
            .map(IpAddr::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    if up.is_empty() {
        return Err(Ros2Error::Interface(
            "no network interface is up with an IPv4 address: DDS would reach no one (in a network namespace, \
             `ip link set lo up` first)"
                .into(),
        ));
    }
    let missing: Vec<IpAddr> = wanted.iter().filter(|a| !up.contains(a)).copied().collect();
    if !missing.is_empty() {
        return Err(Ros2Error::Interface(format!(
            "no network interface that is up has the address {} (those up: {})",
            list(&missing),
            list(&up)
        )));
    }
    Ok(())
}

/// The node, its writers and the bag writer that feeds them (on the publishing thread).
fn open(
    options: &Ros2Options,
    node_name: NodeName,
    namespace: String,
    bag_options: &BagOptions,
    camera: Option<CameraModel>,
    refused: Arc<AtomicU64>,
    description: &str,
) -> Result<(BagWriter, Context), Ros2Error> {
    let start_error = |message: String| Ros2Error::Start {
        domain_id: options.domain_id,
        message,
    };
    let mut participant = DomainParticipantBuilder::new(options.domain_id);
    if !options.interfaces.is_empty() {
        participant = participant.with_only_networks(options.interfaces.iter().copied());
    }
    let participant = participant
        .build()
        .map_err(|e| start_error(e.to_string()))?;
    let context =
        Context::from_domain_participant(participant).map_err(|e| start_error(e.to_string()))?;
    let node = context
        .new_node(node_name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| start_error(e.to_string()))?;
    let channels = DdsChannels {
        node,
        namespace,
        types: Vec::new(),
        publishers: Vec::new(),
        refused,
        pending: Vec::new(),
    };
    let writer = BagWriter::with_output(
        description.into(),
        Output::Dds(channels),
        bag_options,
        camera,
    )?;
    Ok((writer, context))
}

/// The topics published per estimate.
const ESTIMATE_TOPICS: [&str; 5] = [
    topics::POSE,
    topics::TWIST,
    topics::ODOMETRY,
    topics::TF,
    topics::STATUS,
];

/// Waits for a subscriber on every estimate topic, at most `wait_s`, then [`SETTLE`] more; says whether every one
/// had one.
fn wait_for_subscribers(context: &Context, namespace: &str, wait_s: Option<f64>) -> bool {
    let Some(wait_s) = wait_s else {
        return false;
    };
    let dds_names: Vec<String> = ESTIMATE_TOPICS
        .iter()
        .map(|topic| format!("rt{}", topic_name(namespace, topic)))
        .collect();
    let participant = context.domain_participant();
    let start = Instant::now();
    let timeout = Duration::from_secs_f64(wait_s.clamp(0.0, 1e6));
    loop {
        let readers = participant.discovered_readers();
        let all = dds_names.iter().all(|name| {
            readers
                .iter()
                .any(|r| &r.subscription_topic_data.topic_name == name)
        });
        if all {
            std::thread::sleep(SETTLE);
            return true;
        }
        if start.elapsed() >= timeout {
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn run(
    mut writer: BagWriter,
    mut queue: rtrb::Consumer<Estimate>,
    shared: &Shared,
) -> Result<(), FormatError> {
    let mut last_estimate: Option<Instant> = None;
    // The time between two estimates, from their own times (the camera's clock, not when this thread happened to
    // look): it follows a shorter one at once, a longer one slowly, so that a stream that speeds up is not slept
    // through; a pause longer than POLL_FOR is not the stream's rate and is left out.
    let mut expected_gap: Option<Duration> = None;
    let mut previous_t_s: Option<f64> = None;
    loop {
        // Read before emptying the queue: what was handed over before the close is published too.
        let last = shared.closed.load(Ordering::Acquire);
        let mut came = false;
        while let Ok(estimate) = queue.pop() {
            writer.write_estimate(&estimate)?;
            shared.published.fetch_add(1, Ordering::Release);
            came = true;
            let gap_s = previous_t_s.map_or(f64::NAN, |t| estimate.t_ref_s - t);
            previous_t_s = Some(estimate.t_ref_s);
            if gap_s > 0.0 && gap_s < POLL_FOR.as_secs_f64() {
                let gap = Duration::from_secs_f64(gap_s);
                expected_gap = Some(
                    expected_gap.map_or(gap, |e| if gap < e { gap } else { e + (gap - e) / 8 }),
                );
            }
        }
        if came {
            last_estimate = Some(Instant::now());
        }
        if last {
            // Dropping the node and its participant tells the subscribers that the writers are gone.
            writer.finish()?;
            return Ok(());
        }
        // While a stream of estimates comes: asleep until shortly before the next one is due, then a look every
        // POLL_INTERVAL. Estimates further apart than POLL_FOR (or the first two) wake this thread instead.
        if let (Some(since), Some(gap)) = (last_estimate.map(|t| t.elapsed()), expected_gap)
            && since < POLL_FOR
        {
            let until_due = gap.saturating_sub(since + POLL_LEAD);
            std::thread::park_timeout(until_due.max(POLL_INTERVAL));
            continue;
        }
        // Announce the long sleep, then look at the ring once more: an estimate handed over before the hand-over
        // could see the announcement is there now, and one handed over after it wakes this thread.
        shared.asleep.store(true, Ordering::Relaxed);
        fence(Ordering::SeqCst);
        if queue.is_empty() && !shared.closed.load(Ordering::Acquire) {
            std::thread::park_timeout(IDLE_SLEEP);
        }
        shared.asleep.store(false, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn namespaces_are_normalised_and_prefix_every_topic() {
        for (given, expected) in [
            ("", ""),
            ("/", ""),
            ("robot1", "/robot1"),
            ("/robot1/", "/robot1"),
            (" /a/b ", "/a/b"),
        ] {
            assert_eq!(normalised_namespace(given), expected, "{given:?}");
        }
        assert_eq!(topic_name("/robot1", topics::TF), "/robot1/tf");
    }

    #[test]
    fn the_estimates_are_best_effort_and_the_camera_info_latched() {
        for topic in [
            topics::POSE,
            topics::TWIST,
            topics::ODOMETRY,
            topics::STATUS,
        ] {
            let qos = qos_of(topic);
            assert_eq!(qos.reliability, Reliability::BestEffort, "{topic}");
            assert_eq!(qos.durability, Durability::Volatile, "{topic}");
        }
        let info = qos_of(topics::CAMERA_INFO);
        assert!(matches!(info.reliability, Reliability::Reliable { .. }));
        assert_eq!(info.durability, Durability::TransientLocal);
        let tf = qos_of(topics::TF);
        assert!(matches!(tf.reliability, Reliability::Reliable { .. }));
        assert_eq!(tf.durability, Durability::Volatile);
    }

    #[test]
    fn an_address_no_interface_has_is_refused_before_starting() {
        // 192.0.2.0/24 is TEST-NET-1, reserved for documentation: no machine has it.
        let options = Ros2Options {
            interfaces: vec!["192.0.2.1".parse().unwrap()],
            ..Ros2Options::default()
        };
        let error = Ros2Publisher::start(&options, &BagOptions::default(), None).unwrap_err();
        assert!(error.to_string().contains("192.0.2.1"), "{error}");
    }

    #[test]
    fn a_domain_beyond_232_and_a_bad_namespace_are_refused_before_starting() {
        let options = Ros2Options {
            domain_id: 233,
            ..Ros2Options::default()
        };
        let error = Ros2Publisher::start(&options, &BagOptions::default(), None).unwrap_err();
        assert!(error.to_string().contains("233"), "{error}");
        let options = Ros2Options {
            namespace: "/robot-1".into(),
            ..Ros2Options::default()
        };
        let error = Ros2Publisher::start(&options, &BagOptions::default(), None).unwrap_err();
        assert!(error.to_string().contains("robot-1"), "{error}");
    }

    #[test]
    fn a_raw_body_is_written_as_it_is() {
        let body = vec![1u8, 0, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0, 0, 0, 240, 63];
        let mut bytes = Vec::new();
        cdr::serialize_into::<_, _, _, cdr::CdrLe>(
            &mut bytes,
            &RawCdr(body.clone()),
            cdr::Infinite,
        )
        .unwrap();
        assert_eq!(&bytes[4..], &body[..]);
    }
}
