//! SIGINT (Ctrl-C), SIGTERM (`timeout`, systemd, `docker stop`), SIGHUP (a closed terminal) and SIGPIPE (a reader that
//! went away), handled alike on every command.
//!
//! A command that tracks or renders (`track`, `simulate`, `demo`, `detect`, `live`) asks for a graceful stop
//! ([`stop_at_next_estimate`]): the first signal only raises a flag, which the command finds at its next estimate (or
//! ROI, frame, image: [`check`]) and leaves through its error path, so that what is promised is kept (a bag completed
//! up to its last estimate, kept as `NAME.partial.mcap`) and no output is changed. Any other command, and any
//! command at the second signal, ends at once: every temporary is deleted first. Either way the process ends by the
//! signal itself, which a shell reports as status 128 + its number (130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP,
//! 141 for SIGPIPE), and a script or `timeout` sees that it was stopped.

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// The first signal received, 0 before any.
static RECEIVED: AtomicI32 = AtomicI32::new(0);
/// Whether the running command stops at its next estimate at the first signal.
static GRACEFUL: AtomicBool = AtomicBool::new(false);

/// SIGPIPE's number: a reader that went away, which wants no message.
#[cfg(unix)]
pub const SIGPIPE: i32 = signal_hook::consts::SIGPIPE;
#[cfg(not(unix))]
pub const SIGPIPE: i32 = -1;

/// The signals handled, and the name each is told by.
#[cfg(unix)]
const SIGNALS: [(i32, &str); 4] = [
    (signal_hook::consts::SIGINT, "Ctrl-C"),
    (signal_hook::consts::SIGTERM, "SIGTERM"),
    (signal_hook::consts::SIGHUP, "SIGHUP"),
    (signal_hook::consts::SIGPIPE, "SIGPIPE"),
];

/// The signal's name in messages (`Ctrl-C` for SIGINT, as the user knows it).
pub fn name(signal: i32) -> &'static str {
    #[cfg(unix)]
    if let Some((_, name)) = SIGNALS.iter().find(|(s, _)| *s == signal) {
        return name;
    }
    "a signal"
}

/// Installs the handling, first thing in `main` (before any other thread exists): a thread of its own waits for
/// the signals, so that nothing but a flag and a byte written to a pipe happens inside a signal handler.
pub fn install() {
    #[cfg(unix)]
    {
        // Set inside the handler itself, so that a broken pipe is known as such the moment a write fails on it (the
        // waiting thread may be a little later): see the panic hook below.
        for (signal, _) in SIGNALS {
            // SAFETY: not called from a signal handler; the action registered only stores to an atomic.
            let _ = unsafe {
                signal_hook::low_level::register(signal, move || {
                    let _ =
                        RECEIVED.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
                })
            };
        }
        let Ok(mut signals) = signal_hook::iterator::Signals::new(SIGNALS.map(|(s, _)| s)) else {
            eprintln!(
                "roitrack: warning: cannot handle signals: an interrupted run may leave temporaries"
            );
            return;
        };
        let spawned = std::thread::Builder::new()
            .name("roitrack-signals".into())
            .spawn(move || {
                let mut seen = 0;
                for signal in signals.forever() {
                    seen += 1;
                    if seen == 1 && GRACEFUL.load(Ordering::SeqCst) {
                        // The command finds the flag at its next estimate.
                        continue;
                    }
                    end_by(signal);
                }
            });
        if spawned.is_err() {
            eprintln!(
                "roitrack: warning: cannot handle signals: an interrupted run may leave temporaries"
            );
        }
        // A write on a broken pipe fails with an error when SIGPIPE is handled: `println!` then panics. The process
        // ends by the signal instead, quietly, as it did when SIGPIPE killed it.
        let default_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| match received() {
            Some(signal) => end_by(signal),
            None => default_hook(info),
        }));
    }
}

/// Makes the first signal only raise the flag that [`check`] finds: for commands that stop at their next estimate.
pub fn stop_at_next_estimate() {
    GRACEFUL.store(true, Ordering::SeqCst);
}

/// Takes a signal that ended a run as its normal end (a live run, stopped by Ctrl-C): the outputs are then moved into
/// place and the process ends with success. A second signal still ends it at once.
#[cfg_attr(not(feature = "genicam"), allow(dead_code))]
pub fn acknowledge() {
    RECEIVED.store(0, Ordering::SeqCst);
}

/// A flag raised by the first signal (Ctrl-C, SIGTERM, SIGHUP), for a command that looks at a flag rather than calls
/// [`check`]: a live run's camera, the ROS 2 node's look at the bus. A second signal ends the process at once.
#[cfg(any(feature = "genicam", feature = "ros2"))]
pub fn stop_flag() -> std::sync::Arc<AtomicBool> {
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    std::thread::spawn(move || {
        while received().is_none() {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        flag.store(true, Ordering::SeqCst);
    });
    stop
}

/// The first signal received, if any.
pub fn received() -> Option<i32> {
    match RECEIVED.load(Ordering::SeqCst) {
        0 => None,
        signal => Some(signal),
    }
}

/// An error naming `path` if a signal asks the run to stop: what a command returns at its next estimate.
pub fn check(path: &std::path::Path) -> Result<(), roitrack::formats::FormatError> {
    match received() {
        Some(signal) => Err(roitrack::formats::FormatError::new(
            path,
            format!("interrupted ({})", name(signal)),
        )),
        None => Ok(()),
    }
}

/// Ends the process at once by `signal`, its temporaries deleted first.
pub fn end_by(signal: i32) -> ! {
    roitrack::formats::remove_temporaries_before_exit();
    #[cfg(unix)]
    {
        let _ = signal_hook::low_level::emulate_default_handler(signal);
    }
    // Where the signal's own action could not end it (it should not happen), the status a shell would show.
    std::process::exit(128 + signal)
}
