//! What publishing on the ROS 2 DDS bus costs beside tracking (feature `ros2`; docs/ros2.md gives the figures and
//! the command): tracks a simulated orthoglide run (4 kHz ROIs, an estimate every `--every` measurements), then hands
//! its estimates to a `Ros2Publisher` at `--rate-hz`, paced on the wall clock, and prints, per estimate:
//!
//! - the tracking time (one thread, the default estimator);
//! - the hand-over on the tracking thread (`publish_estimate`: a copy into a ring and a wake-up), median and p99;
//! - the CPU time of the whole process while publishing (the publishing thread and RustDDS's threads) less that of the
//!   same paced loop without publishing, from `/proc/self/stat` (Linux);
//! - and the estimates published and dropped, for the subscriber's count to be compared with.
//!
//! Run it where a subscriber listens (docs/ros2.md: in a network namespace of its own, beside
//! `crates/roitrack-ros/tests/ros2_subscriber.py`), with `--wait-s` so that it waits for it:
//!
//! ```text
//! cargo run --release -p roitrack-ros --features ros2 --example ros2_cost -- --rate-hz 400 --every 10 --wait-s 20
//! ```

use std::time::{Duration, Instant};

use roitrack_core::estimator::{TrackerConfig, track_all};
use roitrack_ros::BagOptions;
use roitrack_ros::ros2::{Ros2Options, Ros2Publisher};
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};

/// The process's CPU time (user and system, all threads; s), from `/proc/self/stat` in clock ticks of 10 ms.
fn cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").expect("Linux's /proc/self/stat");
    // The fields after the command's closing parenthesis: utime and stime are the 12th and 13th.
    let rest = &stat[stat.rfind(')').expect("a command name") + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    ticks / 100.0
}

/// Calls `each(k)` for `n` items paced at `rate_hz` on the wall clock (sleeping between them).
fn paced(n: usize, rate_hz: f64, mut each: impl FnMut(usize)) {
    let start = Instant::now();
    for k in 0..n {
        let due = start + Duration::from_secs_f64(k as f64 / rate_hz);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        each(k);
    }
}

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

fn argument(name: &str, default: f64) -> f64 {
    let args: Vec<String> = std::env::args().collect();
    args.iter().position(|a| a == name).map_or(default, |i| {
        args[i + 1]
            .parse()
            .unwrap_or_else(|_| panic!("{name}: a number"))
    })
}

fn main() {
    let rate_hz = argument("--rate-hz", 400.0);
    let every = argument("--every", 10.0) as usize;
    let duration_s = argument("--duration-s", 10.0);
    let wait_s = argument("--wait-s", 0.0);
    let domain_id = argument("--domain", 0.0) as u16;

    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1).with_duration_s(duration_s);
    let run = simulate(&scenario, &SimulationOptions::default()).expect("the simulation");
    let config = TrackerConfig {
        every,
        ..TrackerConfig::default()
    };
    let start = Instant::now();
    let (estimates, _) =
        track_all(&run.camera, &run.target, config, &run.measurements).expect("tracking");
    let tracking_us = start.elapsed().as_secs_f64() * 1e6 / estimates.len() as f64;

    let n = estimates.len();
    // The same paced loop without publishing: what pacing itself costs.
    let cpu0 = cpu_s();
    paced(n, rate_hz, |k| {
        std::hint::black_box(&estimates[k]);
    });
    let baseline_s = cpu_s() - cpu0;

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
    let mut hand_over_us = Vec::with_capacity(n);
    let cpu0 = cpu_s();
    paced(n, rate_hz, |k| {
        let t = Instant::now();
        publisher
            .publish_estimate(&estimates[k])
            .expect("publishing");
        hand_over_us.push(t.elapsed().as_secs_f64() * 1e6);
    });
    // Where the CPU went, by thread, before the publisher's threads end (the tracking thread included: its
    // hand-overs and its pacing).
    let by_thread = threads_cpu_s();
    let report = publisher.finish().expect("the publisher's end");
    let publishing_s = cpu_s() - cpu0;
    hand_over_us.sort_by(f64::total_cmp);
    let quantile = |q: f64| hand_over_us[((n - 1) as f64 * q).round() as usize];
    let per_estimate_us = (publishing_s - baseline_s) * 1e6 / n as f64;
    println!(
        "{n} estimates (every {every} measurements of 4 kHz ROIs) published at {rate_hz} Hz: {} published, {} \
         dropped, {} reliable messages refused",
        report.published, report.dropped, report.refused
    );
    println!("tracking: {tracking_us:.1} us per estimate (one thread)");
    println!(
        "hand-over on the tracking thread: median {:.2} us, p99 {:.2} us ({:.1} % of tracking at the median)",
        quantile(0.5),
        quantile(0.99),
        100.0 * quantile(0.5) / tracking_us
    );
    println!(
        "CPU of publishing, all threads: {per_estimate_us:.1} us per estimate ({:.0} % of tracking; {publishing_s:.2} \
         s less {baseline_s:.2} s of pacing, 10 ms ticks)",
        100.0 * per_estimate_us / tracking_us
    );
    let threads: Vec<String> = by_thread
        .iter()
        .filter(|(_, s)| *s > 0.0)
        .map(|(name, s)| format!("{name} {s:.2} s"))
        .collect();
    println!(
        "CPU by thread over the whole run (tracking included): {}",
        threads.join(", ")
    );
}
