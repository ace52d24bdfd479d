//! What publishing on the ROS 2 DDS bus costs beside tracking (feature `ros2`; docs/ros2.md gives the figures and
//! the command), measured in one run: a simulated orthoglide run (4 kHz ROIs, an estimate every `--every`
//! measurements) is tracked live, its measurements paced on the wall clock at their own times, in blocks of
//! `--block` estimates that alternately publish every estimate to a `Ros2Publisher` and do not (so that the two
//! share the machine's load as it varies). It prints, per estimate:
//!
//! - the tracking time without publishing and with it (the tracking thread's busy time: the estimator, and with
//!   publishing the hand-over, `publish_estimate`: a copy into a ring, and a wake-up only if the publishing thread
//!   announced a long sleep), and their ratio: what publishing costs the tracking;
//! - the hand-over alone, median and p99;
//! - the CPU time of the publishing threads (roitrack's and RustDDS's), from `/proc/self/task/*/stat` (Linux): what
//!   publishing costs the machine, on the other core;
//! - and the estimates published and dropped, for the subscriber's count to be compared with.
//!
//! With `--handed-out FILE`, each published estimate's stamp (ns) and the wall clock at its hand-over (ns since the
//! Unix epoch), one pair a line: against the subscriber's `taken_ns`, the latency from the hand-over.
//!
//! Run it where a subscriber listens (docs/ros2.md: in a network namespace of its own, beside
//! `crates/roitrack-ros/tests/ros2_subscriber.py`), with `--wait-s` so that it waits for it:
//!
//! ```text
//! cargo run --release -p roitrack-ros --features ros2 --example ros2_cost -- --every 10 --duration-s 10 --wait-s 20
//! ```

use std::cell::Cell;
use std::time::{Duration, Instant};

use roitrack_estimators::{Tracker, TrackerConfig, track};
use roitrack_ros::BagOptions;
use roitrack_ros::ros2::{Ros2Options, Ros2Publisher};
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};

/// Each thread's name and CPU time (s) so far, from `/proc/self/task/*/stat`, the busiest first.
fn threads_cpu_s() -> Vec<(String, f64)> {
    let mut threads: Vec<(String, f64)> = std::fs::read_dir("/proc/self/task")
        .map(|tasks| {
            tasks
                .flatten()
                .filter_map(|task| {
                    let stat = std::fs::read_to_string(task.path().join("stat")).ok()?;
                    let name = stat[stat.find('(')? + 1..stat.rfind(')')?].to_string();
                    let rest = &stat[stat.rfind(')')? + 2..];
                    let fields: Vec<&str> = rest.split_whitespace().collect();
                    let ticks = fields[11].parse::<f64>().ok()? + fields[12].parse::<f64>().ok()?;
                    Some((name, ticks / 100.0))
                })
                .collect()
        })
        .unwrap_or_default();
    threads.sort_by(|a, b| b.1.total_cmp(&a.1));
    threads
}

/// The value of option `name`, if given.
fn text_argument(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .map(|i| args[i + 1].clone())
}

fn argument(name: &str, default: f64) -> f64 {
    let args: Vec<String> = std::env::args().collect();
    args.iter().position(|a| a == name).map_or(default, |i| {
        args[i + 1]
            .parse()
            .unwrap_or_else(|_| panic!("{name}: a number"))
    })
}

/// What the tracking thread did in the blocks of one kind (publishing or not).
#[derive(Debug, Default)]
struct Blocks {
    estimates: u64,
    busy: Duration,
}

impl Blocks {
    fn us_per_estimate(&self) -> f64 {
        self.busy.as_secs_f64() * 1e6 / self.estimates.max(1) as f64
    }
}

/// The CPU time (s) of the threads whose names start with one of `prefixes`.
fn cpu_of(prefixes: &[&str]) -> f64 {
    threads_cpu_s()
        .iter()
        .filter(|(name, _)| prefixes.iter().any(|p| name.starts_with(p)))
        .map(|(_, s)| s)
        .sum()
}

/// The threads that publish: roitrack's publishing thread and RustDDS's (its event loop, "RustDDS Participant").
const PUBLISHING_THREADS: [&str; 2] = ["roitrack-ros2", "RustDDS"];

fn main() {
    let every = argument("--every", 10.0) as usize;
    let duration_s = argument("--duration-s", 10.0);
    let wait_s = argument("--wait-s", 0.0);
    let domain_id = argument("--domain", 0.0) as u16;
    let block = argument("--block", 100.0) as u64;
    // Each published estimate's stamp (ns) and the wall clock (ns since the Unix epoch) at its hand-over, written to
    // this file: against the subscriber's `taken_ns`, the latency from the hand-over (the DDS source timestamp that
    // the subscriber's own figure starts from is the publishing thread's write, later).
    let handed_out = text_argument("--handed-out");

    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1).with_duration_s(duration_s);
    let run = simulate(&scenario, &SimulationOptions::default()).expect("the simulation");
    let config = TrackerConfig {
        every,
        ..TrackerConfig::default()
    };
    let mut tracker =
        Tracker::new(run.camera.clone(), run.target.clone(), config).expect("the tracker");
    let options = Ros2Options {
        domain_id,
        wait_for_subscribers_s: (wait_s > 0.0).then_some(wait_s),
        ..Ros2Options::default()
    };
    let mut publisher =
        Ros2Publisher::start(&options, &BagOptions::default(), Some(run.camera.clone()))
            .expect("the ROS 2 node");
    if wait_s > 0.0 && !publisher.subscribed_at_start() {
        eprintln!("no subscriber on every estimate topic: publishing anyway");
    }

    // The measurements at their own times on the wall clock; the tracking thread's busy time is from each
    // measurement's release to the next call for one (the estimator, and the hand-over if the block publishes).
    let t0 = run.measurements[0].t_s;
    let start = Instant::now();
    let busy = Cell::new(Duration::ZERO);
    let released: Cell<Option<Instant>> = Cell::new(None);
    let paced = run.measurements.iter().map(|m| {
        if let Some(released) = released.get() {
            busy.set(busy.get() + released.elapsed());
        }
        let due = start + Duration::from_secs_f64(m.t_s - t0);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        released.set(Some(Instant::now()));
        Ok::<_, std::convert::Infallible>(*m)
    });
    let (mut quiet, mut publishing) = (Blocks::default(), Blocks::default());
    let mut hand_over_us = Vec::new();
    let mut handed_ns: Vec<(i64, i64)> = Vec::new();
    let mut estimates = 0u64;
    // The busy time already given to an estimate: each estimate's share (since the previous one) goes to its block.
    let mut counted = Duration::ZERO;
    let publishing_cpu0 = cpu_of(&PUBLISHING_THREADS);
    track(
        &mut tracker,
        paced,
        |e| -> Result<(), roitrack_formats::FormatError> {
            let k = estimates / block;
            estimates += 1;
            let publishes = k % 2 == 1;
            if publishes && handed_out.is_some() {
                let wall = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .unwrap_or_default();
                handed_ns.push(((e.t_ref_s * 1e9).round() as i64, wall.as_nanos() as i64));
            }
            let t = Instant::now();
            if publishes {
                publisher.publish_estimate(e)?;
                hand_over_us.push(t.elapsed().as_secs_f64() * 1e6);
            }
            let total = busy.get() + released.get().map_or(Duration::ZERO, |r| r.elapsed());
            let share = total - counted;
            counted = total;
            // The first block warms up (the track's start) and counts in neither.
            if k > 0 {
                let blocks = if publishes {
                    &mut publishing
                } else {
                    &mut quiet
                };
                blocks.estimates += 1;
                blocks.busy += share;
            }
            Ok(())
        },
    )
    .expect("tracking");
    // Paced, the publishing threads keep up: their CPU time now is that of every estimate (read while they live).
    let publishing_cpu_s = cpu_of(&PUBLISHING_THREADS) - publishing_cpu0;
    let threads: Vec<String> = threads_cpu_s()
        .iter()
        .filter(|(_, s)| *s > 0.0)
        .map(|(name, s)| format!("{name} {s:.2} s"))
        .collect();
    let report = publisher.finish().expect("the publisher's end");
    if let Some(path) = &handed_out {
        let lines: Vec<String> = handed_ns
            .iter()
            .map(|(stamp, wall)| format!("{stamp} {wall}"))
            .collect();
        std::fs::write(path, lines.join("\n") + "\n").expect("--handed-out");
    }
    hand_over_us.sort_by(f64::total_cmp);
    let quantile = |q: f64| hand_over_us[((hand_over_us.len() - 1) as f64 * q).round() as usize];
    let (without, with) = (quiet.us_per_estimate(), publishing.us_per_estimate());
    println!(
        "{estimates} estimates (every {every} measurements of 4 kHz ROIs, paced at their times), in blocks of {block} \
         publishing or not: {} handed over, {} published, {} dropped, {} reliable messages refused",
        report.handed, report.published, report.dropped, report.refused
    );
    println!(
        "tracking: {without:.2} us per estimate without publishing ({} estimates), {with:.2} us with it ({}): \
         publishing costs the tracking {:.1} %",
        quiet.estimates,
        publishing.estimates,
        100.0 * (with - without) / without
    );
    println!(
        "hand-over on the tracking thread: median {:.2} us, p99 {:.2} us",
        quantile(0.5),
        quantile(0.99),
    );
    println!(
        "CPU of the publishing threads (roitrack's and RustDDS's, on the other core): {:.1} us per estimate published \
         ({publishing_cpu_s:.2} s, 10 ms ticks)",
        publishing_cpu_s * 1e6 / report.published.max(1) as f64
    );
    println!(
        "CPU by thread over the whole run (tracking and simulation included): {}",
        threads.join(", ")
    );
}
