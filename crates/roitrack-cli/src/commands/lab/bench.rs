//! `roitrack lab bench`: a quick measurement (about 10 s) of the hot paths and of the real-time loop.
//!
//! **Hot paths**, on the built-in scene of docs/model.md (inputs and timer shared with the criterion benches of
//! `cargo bench -p roitrack-bench`, see [`roitrack_bench`]): each item is timed for `--item-ms` in batches of calls
//! lasting at least 5 µs (a sub-µs item is called many times per clock reading); the figures are the median and the
//! 99th percentile over batches of batch time / batch size, in µs (for a batch of one call, the p99 is per call; for
//! larger batches it is the p99 of a batch's mean).
//!
//! **Real-time loop**, free-running on pre-rendered ROIs of the orthoglide scenario (rendering does not count): ROI
//! throughput with an estimate every 10 ROIs and at every ROI, and the ROI-to-estimate latency with the camera paced at
//! 20 kHz.
//!
//! With `--json`, one JSON object with these stable keys (times in µs, rates in ROIs/s; a figure that could not be
//! measured is `null`):
//!
//! - `jacobian_residual_w16_us_median`, `jacobian_residual_w16_us_p99`: exact Jacobian + residual (accumulated as
//!   normal equations) of a 16-measurement window;
//! - `control_step_w16_us_median`, `control_step_w16_us_p99`: one control step (VVS, exact Jacobian, 1 iteration,
//!   gain 1, degeneracy gate 3e-3, so with the conditioning figure) on 16 measurements;
//! - `control_step_w32_us_median`, `control_step_w32_us_p99`: the same on 32 measurements;
//! - `gauss_newton_solve_us_median`, `gauss_newton_solve_us_p99`: Levenberg-Marquardt of the 12 parameters to
//!   convergence on 32 measurements, from 1 mm / 0.5° / 0.1 m/s / 0.1 rad/s off the truth;
//!   `gauss_newton_iterations`: the iterations it takes;
//! - `static_pose_us_median`, `static_pose_us_p99`: the static pose from scratch, 16 points, no prior, refined to
//!   convergence; `static_pose_iterations`: the iterations of that refinement;
//! - `centroid_24_us_median`, `centroid_24_us_p99`: blob centroid of a 24x24 8-bit ROI (6 mm blob), default options
//!   (with the symmetry check); `centroid_24_moments_us_median`, `centroid_24_moments_us_p99`: the same without it;
//! - `render_roi_us_median`, `render_roi_us_p99`: the simulator's rendering of that ROI (one blob, noise drawn);
//! - `kalman_update_us_median`, `kalman_update_us_p99`: one measurement into the default Kalman filter on a running
//!   track of the bench scene (oscillating about the bench pose), with an estimate period so long that none is due:
//!   prediction, update and window bookkeeping, the per-measurement cost of tracking (target 1 µs);
//!   `kalman_update_constant_acceleration_us_median`, `kalman_update_constant_acceleration_us_p99`: the same with the
//!   constant-acceleration model (18 states, the frame tracker's default);
//! - `estimate_handle_read_ns_median`, `estimate_handle_read_ns_p99`: one read of the newest estimate with its
//!   covariance through the lock-free handle a control thread holds (`roitrack::servo::handle`), nothing publishing,
//!   in ns;
//! - `item_ms`: the timing budget of each of those items (ms);
//! - `loop_k10_rois_per_s`, `loop_k1_rois_per_s`: free-running loop throughput with an estimate every 10 ROIs and at
//!   every ROI (best of `--repeats`); `loop_k10_dropped`, `loop_k1_dropped`: ROIs dropped in those runs;
//!   `loop_k10_rejected`, `loop_k1_rejected`: ROIs whose centroid was rejected;
//! - `latency_us_p50`, `latency_us_p99`: ROI-to-estimate latency with the camera paced at `paced_hz` (median over
//!   `--repeats` of each run's quantile); `paced_rois_per_s`, `paced_dropped`, `paced_late`: that run's throughput,
//!   drops and late ROIs;
//! - `rois_per_run`: ROIs per loop run;
//! - `track_library_meas_per_s`: measurements/s of the library's `track` over the orthoglide scenario's 19,655
//!   simulated measurements in memory (default Kalman filter, an estimate every 10, every estimate collected; best of
//!   `--repeats`): the call the Python package's `roitrack.track` makes ([`roitrack::bench::track_bench`]);
//! - `rig4_meas_per_s`, `rig4_running_meas_per_s`: measurements/s fused on one thread from a rig of 4 ROI cameras at
//!   4 kHz each (the random scenario, seed 2, 4 s, 62,330 measurements in memory; every clock but the first to be
//!   learnt), over the whole run and after its first second (best of `--repeats`; [`roitrack::bench::rig_bench`]);
//! - `fake_camera_rois`, `fake_camera_rois_per_s`, `fake_camera_latency_us_p50`, `fake_camera_latency_us_p99`,
//!   `fake_camera_grab_us_p50`, `fake_camera_grab_us_p99`, `fake_camera_moved_fraction`: with `--fake-camera S`
//!   (binary built with the feature `genicam`), the loop through Aravis' fake GigE camera on 127.0.0.1 for S s of the
//!   orthoglide scenario: ROIs read, ROIs/s, latency from buffer timestamp to estimate, the grab (window moved,
//!   trigger, buffer in hand), the fraction of buffers from the window asked for; `null` without `--fake-camera`.
//!
//! Keys are only ever added, never renamed or removed.

use std::time::Duration;

use anyhow::Result;
use clap::Args;
use roitrack::bench::loop_bench::{LoopBench, LoopFigures, PACED_HZ};
use roitrack::bench::rig_bench::RigBench;
use roitrack::bench::track_bench::TrackLibraryBench;
use roitrack::bench::{HotPaths, Item, Timing, time_all, time_item};

/// `--fake-camera S`: the loop through Aravis' fake GigE camera on 127.0.0.1 (orthoglide, seed 1, 4 kHz ROI slots, a
/// 32 px window, Mono8, software trigger, free-running); see `live::bench_fake_camera`.
#[derive(Debug, Clone, Copy)]
#[cfg_attr(not(feature = "genicam"), allow(dead_code))]
pub struct FakeCameraFigures {
    pub rois: u64,
    pub rois_per_s: f64,
    /// Latency from buffer timestamp to estimate (µs).
    pub latency_p50_us: f64,
    pub latency_p99_us: f64,
    /// The grab: window moved, triggered, buffer in hand (µs).
    pub grab_p50_us: f64,
    pub grab_p99_us: f64,
    pub moved_fraction: f64,
}

/// Time the hot paths (median, p99) and the real-time loop (throughput, latency).
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Print one JSON object with stable keys instead of a table.
    #[arg(long)]
    pub json: bool,
    /// ROIs per loop run (at most 10 million: 40 minutes at 4 kHz).
    #[arg(long, default_value_t = DEFAULT_ROIS, value_parser = crate::ranges::count(1..=10_000_000, "40 minutes at 4 kHz"))]
    pub rois: usize,
    /// Runs of each configuration (the best throughput and the median latencies are reported), at most 1,000.
    #[arg(long, default_value_t = DEFAULT_REPEATS, value_parser = crate::ranges::count(1..=1000, "a median of a thousand is steady"))]
    pub repeats: usize,
    /// Timing budget of each hot-path item (ms). Default: 400 ms, scaled down with the loop's work when `--rois` x
    /// `--repeats` is below the default 16,000 x 3 (at least 10 ms), so a short run stays short.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=600_000))]
    pub item_ms: Option<u64>,
    /// Also run the loop through Aravis' fake GigE camera on 127.0.0.1 for this many seconds of the orthoglide
    /// scenario (ROIs/s, latency from buffer timestamp to estimate). Default: not run.
    #[cfg(feature = "genicam")]
    #[arg(long, value_name = "S", value_parser = crate::ranges::positive_up_to(3600.0, " s", "an hour"))]
    pub fake_camera: Option<f64>,
}

const DEFAULT_ROIS: usize = 16_000;
const DEFAULT_REPEATS: usize = 3;
/// Timing budget of each hot-path item at the default loop size (ms).
const DEFAULT_ITEM_MS: f64 = 400.0;

impl BenchArgs {
    fn item_budget(&self) -> Duration {
        let ms = match self.item_ms {
            Some(ms) => ms as f64,
            None => {
                let work = (self.rois * self.repeats.max(1)) as f64
                    / (DEFAULT_ROIS * DEFAULT_REPEATS) as f64;
                (DEFAULT_ITEM_MS * work.min(1.0)).max(10.0)
            }
        };
        Duration::from_secs_f64(ms / 1e3)
    }
}

/// A JSON number with `decimals` decimals, `null` if not finite.
fn json_number(x: f64, decimals: usize) -> String {
    if x.is_finite() {
        format!("{x:.decimals$}")
    } else {
        "null".to_string()
    }
}

pub fn run(args: &BenchArgs) -> Result<()> {
    // The hot paths first, on a quiet machine (before the loop's two threads have run).
    let item_budget = args.item_budget();
    let mut hot = HotPaths::new();
    let timings = time_all(&mut hot, item_budget);
    let gauss_newton_iterations = hot.gauss_newton_solve(32).report.iterations;
    let static_pose_iterations = hot.static_pose().map_or(0, |poses| poses.best().iterations);
    let handle_read = estimate_handle_read(item_budget);

    let bench = LoopBench::new(args.rois)?;
    let k10 = bench.measure(10, None, args.repeats)?;
    let k1 = bench.measure(1, None, args.repeats)?;
    // Latency without queueing: the camera paced at 20 kHz (5x the paper), below the loop's capacity.
    let paced = bench.measure(10, Some(PACED_HZ), args.repeats)?;
    let track_library = TrackLibraryBench::orthoglide()?.measure(args.repeats);
    let rig = RigBench::four_cameras()?.measure(args.repeats);
    #[cfg(feature = "genicam")]
    let fake_camera = args
        .fake_camera
        .map(crate::commands::live::bench_fake_camera)
        .transpose()?;
    #[cfg(not(feature = "genicam"))]
    let fake_camera: Option<FakeCameraFigures> = None;
    if args.json {
        let mut fields: Vec<(String, String)> = Vec::new();
        for (item, t) in &timings {
            fields.push((
                format!("{}_us_median", item.key()),
                json_number(t.median_us, 4),
            ));
            fields.push((format!("{}_us_p99", item.key()), json_number(t.p99_us, 4)));
        }
        let mut field = |key: &str, value: String| fields.push((key.to_string(), value));
        field(
            "estimate_handle_read_ns_median",
            json_number(handle_read.median_us * 1e3, 1),
        );
        field(
            "estimate_handle_read_ns_p99",
            json_number(handle_read.p99_us * 1e3, 1),
        );
        field(
            "gauss_newton_iterations",
            gauss_newton_iterations.to_string(),
        );
        field("static_pose_iterations", static_pose_iterations.to_string());
        field("item_ms", json_number(item_budget.as_secs_f64() * 1e3, 1));
        field("loop_k10_rois_per_s", json_number(k10.rois_per_s, 0));
        field("loop_k1_rois_per_s", json_number(k1.rois_per_s, 0));
        field("latency_us_p50", json_number(paced.latency_p50_us, 2));
        field("latency_us_p99", json_number(paced.latency_p99_us, 2));
        field("paced_hz", json_number(PACED_HZ, 0));
        field("paced_rois_per_s", json_number(paced.rois_per_s, 0));
        field("paced_dropped", paced.dropped.to_string());
        field("paced_late", paced.late.to_string());
        field("loop_k10_dropped", k10.dropped.to_string());
        field("loop_k1_dropped", k1.dropped.to_string());
        field("loop_k10_rejected", k10.rejected.to_string());
        field("loop_k1_rejected", k1.rejected.to_string());
        field("rois_per_run", bench.rois().to_string());
        field(
            "track_library_meas_per_s",
            json_number(track_library.meas_per_s, 0),
        );
        field("rig4_meas_per_s", json_number(rig.meas_per_s, 0));
        field(
            "rig4_running_meas_per_s",
            json_number(rig.running_meas_per_s, 0),
        );
        let fake = |f: fn(&FakeCameraFigures) -> f64, decimals| {
            fake_camera
                .as_ref()
                .map_or("null".to_string(), |c| json_number(f(c), decimals))
        };
        field("fake_camera_rois", fake(|c| c.rois as f64, 0));
        field("fake_camera_rois_per_s", fake(|c| c.rois_per_s, 0));
        field("fake_camera_latency_us_p50", fake(|c| c.latency_p50_us, 1));
        field("fake_camera_latency_us_p99", fake(|c| c.latency_p99_us, 1));
        field("fake_camera_grab_us_p50", fake(|c| c.grab_p50_us, 1));
        field("fake_camera_grab_us_p99", fake(|c| c.grab_p99_us, 1));
        field("fake_camera_moved_fraction", fake(|c| c.moved_fraction, 4));
        let body: Vec<String> = fields
            .iter()
            .map(|(key, value)| format!("\"{key}\":{value}"))
            .collect();
        println!("{{{}}}", body.join(","));
    } else {
        print_items(
            &timings,
            item_budget,
            gauss_newton_iterations,
            static_pose_iterations,
            &handle_read,
        );
        println!();
        print_loop(
            &bench,
            &[
                ("free, estimate every 10 ROIs", &k10),
                ("free, estimate every ROI", &k1),
            ],
            &paced,
        );
        println!(
            "\nlibrary track(), orthoglide, {} measurements in memory, Kalman, every 10: {:.0} measurements/s",
            track_library.measurements, track_library.meas_per_s
        );
        println!(
            "rig of 4 ROI cameras, random scenario, {} measurements in memory, clocks to learn: {:.0} measurements/s \
             fused on one thread ({:.0}/s after the first second)",
            rig.measurements, rig.meas_per_s, rig.running_meas_per_s
        );
        if let Some(c) = &fake_camera {
            println!(
                "\nAravis' fake GigE camera on 127.0.0.1, orthoglide, 32x32 Mono8 window, software trigger: {} ROIs, \
                 {:.0} ROIs/s, moved as asked {:.2} %; latency from buffer timestamp to estimate p50/p99 {:.0}/{:.0} \
                 us; grab p50/p99 {:.0}/{:.0} us",
                c.rois,
                c.rois_per_s,
                100.0 * c.moved_fraction,
                c.latency_p50_us,
                c.latency_p99_us,
                c.grab_p50_us,
                c.grab_p99_us
            );
        }
    }
    Ok(())
}

/// One read of the estimate handle (`roitrack::servo::handle`) with a covariance-carrying estimate published once:
/// what a user's control thread pays per read.
fn estimate_handle_read(budget: Duration) -> Timing {
    let (mut publisher, reader) = roitrack::servo::handle::estimate_channel();
    publisher.publish(&roitrack::estimators::Estimate::bench());
    time_item(|| reader.read(), budget)
}

/// The loop table.
fn print_loop(bench: &LoopBench, free: &[(&str, &LoopFigures)], paced: &LoopFigures) {
    println!(
        "real-time loop, free-running on {} pre-rendered 32x32 ROIs (orthoglide), two threads:",
        bench.rois()
    );
    println!(
        "{:<34} {:>10} {:>15} {:>15} {:>8} {:>5} {:>9}",
        "", "ROIs/s", "latency p50 us", "latency p99 us", "dropped", "late", "rejected"
    );
    let paced_name = format!("paced {} kHz, estimate every 10", PACED_HZ / 1e3);
    for (name, f) in free.iter().copied().chain([(paced_name.as_str(), paced)]) {
        println!(
            "{name:<34} {:>10.0} {:>15.2} {:>15.2} {:>8} {:>5} {:>9}",
            f.rois_per_s, f.latency_p50_us, f.latency_p99_us, f.dropped, f.late, f.rejected
        );
    }
    println!(
        "Free-running latencies include queueing (the camera keeps up to 16 ROIs queued); the paced run's do not."
    );
}

/// The hot-path table.
fn print_items(
    timings: &[(Item, Timing)],
    budget: Duration,
    gauss_newton_iterations: usize,
    static_pose_iterations: usize,
    handle_read: &Timing,
) {
    println!(
        "hot paths, built-in scene (docs/model.md), one thread, {:.0} ms each:",
        budget.as_secs_f64() * 1e3
    );
    println!(
        "{:<46} {:>11} {:>11} {:>7} {:>8}",
        "", "median us", "p99 us", "batch", "batches"
    );
    for (item, t) in timings {
        let note = match item {
            Item::GaussNewtonSolve => format!(" ({gauss_newton_iterations} iterations)"),
            Item::StaticPose => format!(" ({static_pose_iterations} iterations)"),
            _ => String::new(),
        };
        println!(
            "{:<46} {:>11.4} {:>11.4} {:>7} {:>8}{note}",
            item.label(),
            t.median_us,
            t.p99_us,
            t.batch_size,
            t.batches
        );
    }
    println!(
        "{:<46} {:>11.4} {:>11.4} {:>7} {:>8}",
        "estimate handle, one read with covariance",
        handle_read.median_us,
        handle_read.p99_us,
        handle_read.batch_size,
        handle_read.batches
    );
    println!(
        "Items under 5 us are timed in batches: their p99 is that of a batch's mean. \
         Criterion: cargo bench -p roitrack-bench."
    );
}
