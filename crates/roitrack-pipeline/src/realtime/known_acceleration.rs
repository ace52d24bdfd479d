//! The third queue of the loop: the accelerations a control thread commands, told to the tracker before the
//! measurements that follow them ([`known_acceleration_channel`]).

use roitrack_core::Acceleration;

/// A known acceleration of the target (camera frame) from `t_s` on, on the loop's clock (the ROIs' and the
/// measurements' times): what a controller commands, handed to the loop's tracker through a
/// [`known_acceleration_channel`].
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_core::Acceleration;
/// use roitrack_pipeline::realtime::TimedAcceleration;
///
/// // 20 m/s² along the optical axis from 10 ms on.
/// let linear_mps2 = Vector3::new(0.0, 0.0, 20.0);
/// let input = TimedAcceleration { t_s: 0.010, acceleration: Acceleration { linear_mps2, angular_radps2: Vector3::zeros() } };
/// assert_eq!(input.acceleration.linear_mps2.z, 20.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedAcceleration {
    /// From when it holds (s, the loop's clock): the instant the commanded force acts.
    pub t_s: f64,
    /// The target's acceleration (camera frame); it holds until the next input's time.
    pub acceleration: Acceleration,
}

/// The smallest ring a [`known_acceleration_channel`] is given, whatever its caller asks: a ring of none would queue
/// nothing, and with two one input can wait for the estimation thread while the next is queued behind it.
const MIN_KNOWN_ACCELERATION_SLOTS: usize = 2;

/// A lock-free, allocation-free single-producer single-consumer channel of known accelerations, from a control thread
/// (the [`KnownAccelerationSender`]) to the loop's estimation thread (the [`KnownAccelerationReceiver`] given to
/// [`super::run_loop_with_hooks`]), which tells its tracker each input ([`roitrack_estimators::Estimator::set_known_acceleration`]) before the
/// measurements it pushes next. The ring holds `capacity` inputs (at least 2), allocated here and never again.
///
/// When the ring is full (the estimation thread held back longer than `capacity` inputs take to come), the newest input
/// is what matters: the sender keeps the newest one it could not queue, replacing any older one it was keeping (counted
/// in [`KnownAccelerationSender::superseded`]), and queues it first when room frees. An input replaced so is lost: the
/// input before it holds over its interval, as if the command had not changed then; the inputs already queued are
/// kept, in order (the tracker takes inputs in time order only).
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_core::Acceleration;
/// use roitrack_pipeline::realtime::known_acceleration_channel;
///
/// let (mut sender, mut receiver) = known_acceleration_channel(2);
/// let push = |z| Acceleration { linear_mps2: Vector3::new(0.0, 0.0, z), angular_radps2: Vector3::zeros() };
/// for (k, z) in [1.0, 2.0, 3.0, 4.0].into_iter().enumerate() {
///     sender.send(k as f64 * 1e-3, push(z));
/// }
/// // The ring held the first two; of the two that found it full, the newest is kept, the other superseded.
/// assert_eq!(sender.superseded(), 1);
/// let queued: Vec<f64> = std::iter::from_fn(|| receiver.pop()).map(|i| i.acceleration.linear_mps2.z).collect();
/// assert_eq!(queued, [1.0, 2.0]);
/// sender.flush();
/// assert_eq!(receiver.pop().unwrap().acceleration.linear_mps2.z, 4.0);
/// assert!(receiver.pop().is_none());
/// ```
pub fn known_acceleration_channel(
    capacity: usize,
) -> (KnownAccelerationSender, KnownAccelerationReceiver) {
    let (tx, rx) = rtrb::RingBuffer::new(capacity.max(MIN_KNOWN_ACCELERATION_SLOTS));
    (
        KnownAccelerationSender {
            tx,
            held: None,
            superseded: 0,
        },
        KnownAccelerationReceiver { rx },
    )
}

/// The control thread's end of a [`known_acceleration_channel`]: never blocks, never allocates.
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_core::Acceleration;
/// use roitrack_pipeline::realtime::known_acceleration_channel;
///
/// let (mut sender, _receiver) = known_acceleration_channel(64);
/// sender.send(0.001, Acceleration { linear_mps2: Vector3::x(), angular_radps2: Vector3::zeros() });
/// assert_eq!((sender.superseded(), sender.holds_back()), (0, false));
/// ```
pub struct KnownAccelerationSender {
    tx: rtrb::Producer<TimedAcceleration>,
    /// The newest input the ring had no room for: queued before any later one.
    held: Option<TimedAcceleration>,
    superseded: usize,
}

impl KnownAccelerationSender {
    /// Hands the target's `acceleration` (camera frame) from `t_s` (the loop's clock) on to the estimation thread.
    /// Inputs go in time order (the tracker refuses one older than the newest it has, and counts it in
    /// [`super::LoopReport::refused_known_accelerations`]); a full ring keeps the newest (see [`known_acceleration_channel`]).
    pub fn send(&mut self, t_s: f64, acceleration: Acceleration) {
        self.flush();
        let input = TimedAcceleration { t_s, acceleration };
        if self.held.is_some() {
            // Still no room: this input replaces the one kept back, which no later input can now precede.
            self.superseded += 1;
            self.held = Some(input);
            return;
        }
        if let Err(rtrb::PushError::Full(input)) = self.tx.push(input) {
            self.held = Some(input);
        }
    }

    /// Queues the input kept back for want of room, if there is room now: a sender with nothing new to say calls it
    /// so that its last input is not left waiting for the next.
    pub fn flush(&mut self) {
        if let Some(input) = self.held
            && self.tx.push(input).is_ok()
        {
            self.held = None;
        }
    }

    /// Inputs lost because the ring was full and a newer input replaced them.
    pub fn superseded(&self) -> usize {
        self.superseded
    }

    /// Whether an input waits for room in the ring ([`Self::flush`]).
    pub fn holds_back(&self) -> bool {
        self.held.is_some()
    }
}

/// The estimation thread's end of a [`known_acceleration_channel`], given to [`super::run_loop_with_hooks`].
///
/// ```
/// use nalgebra::Vector3;
/// use roitrack_core::Acceleration;
/// use roitrack_pipeline::realtime::known_acceleration_channel;
///
/// let (mut sender, mut receiver) = known_acceleration_channel(8);
/// assert!(receiver.pop().is_none());
/// sender.send(0.5, Acceleration { linear_mps2: Vector3::x(), angular_radps2: Vector3::zeros() });
/// assert_eq!(receiver.pop().unwrap().t_s, 0.5);
/// ```
pub struct KnownAccelerationReceiver {
    rx: rtrb::Consumer<TimedAcceleration>,
}

impl KnownAccelerationReceiver {
    /// The oldest input queued, if any.
    pub fn pop(&mut self) -> Option<TimedAcceleration> {
        self.rx.pop().ok()
    }
}
