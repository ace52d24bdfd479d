//! `roitrack demo`: the main job, end to end from pixels (see [`roitrack::demo`]): prints the table of
//! accuracy, writes the figures (after the paper's figures 5-7), the simulated inputs and ground truth, and every
//! estimate.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use anyhow::Result;
use clap::Args;
use roitrack::Measurement;
use roitrack::demo::{self, Demo, DemoEstimator, DemoOptions, DemoRun, Source};
use roitrack::formats::EstimateWriter;
use roitrack::image::RoiImage;

use super::simulate::write_run;
use crate::args::{ScenarioArg, ScheduleOrderArg};

/// Run a built-in scenario end to end from rendered ROIs through the two-thread loop; print the accuracy of the
/// default estimator, the paper's scheme and the static baseline; write plots and estimates.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Which scenario.
    #[arg(long, value_enum, default_value = "orthoglide")]
    pub scenario: ScenarioArg,
    /// Output folder: inputs, ground truth, estimates, figures.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Seed of the simulation (motion, pixel noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Pace the camera at the ROI rate (4 kHz, real time) instead of running free.
    #[arg(long)]
    pub paced: bool,
    /// Order in which the scheduler reads the points: bit-reversed, row-major, or active (most informative next).
    #[arg(long, value_enum, default_value = "bitrev")]
    pub order: ScheduleOrderArg,
    /// Print one JSON object per row instead of a table.
    #[arg(long)]
    pub json: bool,
    /// The scenario on your own rig.
    #[command(flatten)]
    pub rig: crate::args::RigArgs,
    #[command(flatten)]
    pub ros: crate::ros::McapArgs,
    #[command(flatten)]
    pub ros2: crate::ros2_args::Ros2Args,
}

/// The longest scenario the demo runs (s): it holds the run, its six trackings and their figures in memory, which grow
/// with the simulated time (measured in docs/results.md, "Design measurements behind the code"), so that it stays under
/// about a gigabyte.
const MAX_DEMO_DURATION_S: f64 = 120.0;

/// The files a demo writes into its folder: the simulated run, each estimator's estimates, the figures.
fn output_files() -> Vec<String> {
    let mut files: Vec<String> = super::simulate::RUN_FILES.map(String::from).to_vec();
    for estimator in demo::lineup() {
        for suffix in ["poses.tum", "twists.csv", "diagnostics.csv"] {
            files.push(format!("{}_{suffix}", estimator.stem));
        }
    }
    for stem in ["fig5_trajectory", "fig6_position", "fig7_velocity"] {
        files.extend(["png", "svg"].map(|ext| format!("{stem}.{ext}")));
    }
    files
}

/// Refuses, before anything is read or written, outputs (the folder's files, the bag and its partial name) that are
/// the rig's camera or target file (also through links) or each other.
fn check_paths(args: &DemoArgs) -> Result<()> {
    let inputs: Vec<(&str, &std::path::Path)> = [
        ("--camera", &args.rig.camera),
        ("--target", &args.rig.target),
    ]
    .into_iter()
    .filter_map(|(name, path)| path.as_deref().map(|p| (name, p)))
    .collect();
    let mut outputs: Vec<(String, PathBuf)> = output_files()
        .into_iter()
        .map(|f| (format!("--out's {f}"), args.out.join(f)))
        .collect();
    if let Some(mcap) = &args.ros.mcap {
        outputs.push(("--mcap".into(), mcap.clone()));
        outputs.push((
            "--mcap's partial bag".into(),
            roitrack::formats::partial_path(mcap),
        ));
    }
    let outputs: Vec<(&str, &std::path::Path)> = outputs
        .iter()
        .map(|(n, p)| (n.as_str(), p.as_path()))
        .collect();
    Ok(roitrack::formats::check_output_paths(&inputs, &outputs)?)
}

pub fn run(args: &DemoArgs) -> Result<()> {
    let options = DemoOptions {
        scenario: args.scenario.into(),
        seed: args.seed,
        paced: args.paced,
        order: args.order.into(),
    };
    let scenario = demo_scenario(args, &options)?;
    check_paths(args)?;
    let demo = Demo::with_scenario(options, scenario)?;
    write_run(&demo.run, &args.out)?;
    // What a `simulate` run left in the folder (a ROI recording, frames) would not match the demo's measurements: it
    // goes at the commit, with the rest of the folder's change.
    super::simulate::remove_other_runs_files(&args.out, false, false)?;
    let lineup = demo::lineup();
    let slots = demo.slots();
    print_demo_header(&demo, lineup.len(), &args.out);
    let bar = indicatif::ProgressBar::new((slots * lineup.len()) as u64).with_style(
        indicatif::ProgressStyle::with_template("{bar:40} {percent:>3}% ROIs {msg} ({elapsed})")
            .expect("valid progress template"),
    );
    let mut sinks = DefaultRunSinks::open(args, &demo)?;
    let mut runs = Vec::new();
    for (k, estimator) in lineup.iter().enumerate() {
        // A signal stops the demo here, between two estimators' runs (a second or so after it came), through the
        // error path: no output changes, and the bag of the default estimator's run, if written, is kept as
        // NAME.partial.mcap (src/signals.rs).
        crate::signals::check(&args.out)?;
        bar.set_message(estimator.label);
        let from_images = with_progress(&bar, k * slots, |done| {
            if k > 0 {
                demo.from_images(estimator, Some(done))
                    .map_err(anyhow::Error::from)
            } else {
                sinks.observed_run(&demo, estimator, done)
            }
        })?;
        bar.set_position(((k + 1) * slots) as u64);
        write_estimates(&args.out, estimator.stem, &from_images.scored.estimates)?;
        sinks.finish(&from_images)?;
        runs.push(from_images);
        runs.push(demo.from_centroids(estimator)?);
    }
    bar.finish_and_clear();
    let series: Vec<_> = runs
        .iter()
        .filter(|r| r.source == Source::Images)
        .map(|r| r.track_series())
        .collect();
    let figures = super::plot::write_figure_files(
        &args.out,
        &roitrack::plot::render_figures(demo.scenario.kind.name(), &demo.truth_series(), &series)?,
    )?;
    if args.json {
        for r in &runs {
            println!("{}", demo::json(r));
        }
    } else {
        print!("{}", demo::table(&runs));
        println!(
            "images: rendered ROIs through the two-thread loop (us/step includes rendering); centroids: ideal \
             centroids with the image side's measured noise, {:.4} px.",
            demo.simulation.noise_px
        );
    }
    eprintln!(
        "roitrack demo: wrote {} figures and the estimates of each estimator to {}",
        figures.len(),
        args.out.display()
    );
    Ok(())
}

/// The scenario of `options` on the rig the options give, refused if it lasts over [`MAX_DEMO_DURATION_S`]. The
/// duration is checked before the scenario's image margin, which samples the whole motion (a day's run: two
/// minutes before this refusal).
fn demo_scenario(args: &DemoArgs, options: &DemoOptions) -> Result<roitrack::sim::Scenario> {
    args.rig.scenario_within(
        roitrack::sim::Scenario::new(options.scenario, options.seed),
        |scenario| {
            if scenario.duration_s > MAX_DEMO_DURATION_S {
                anyhow::bail!(
                    "the demo's scenario lasts {:.0} s (--duration-s, --speed-scale): the demo holds its whole run in \
                     memory (about 7 MB per simulated second), so it runs at most {MAX_DEMO_DURATION_S} s; \
                     `roitrack simulate` streams longer runs to files for `roitrack track`",
                    scenario.duration_s
                );
            }
            Ok(())
        },
    )
}

/// What the demo runs, on stderr before it starts: the scenario, the ROI slots, the estimators, the image side's
/// centroid error, the output folder.
fn print_demo_header(demo: &Demo, estimators: usize, out: &std::path::Path) {
    let accuracy = &demo.accuracy;
    eprintln!(
        "roitrack demo: {} scenario, {:.3} s, {} ROI slots at {} Hz, {} estimators from rendered ROIs (two threads) \
         and from ideal centroids; centroid error of the image side over {} ROIs: bias {:+.4}/{:+.4} px, std \
         {:.4}/{:.4} px (u/v); output in {}",
        demo.scenario.kind.name(),
        demo.scenario.duration_s,
        demo.slots(),
        demo.simulation.rate_hz,
        estimators,
        accuracy.count,
        accuracy.bias_u_px,
        accuracy.bias_v_px,
        accuracy.std_u_px,
        accuracy.std_v_px,
        out.display()
    );
}

/// Runs `run` while a thread moves `bar` to `base` plus the ROI slots it says are done, every 100 ms.
fn with_progress<T>(
    bar: &indicatif::ProgressBar,
    base: usize,
    run: impl FnOnce(&AtomicUsize) -> T,
) -> T {
    let done = AtomicUsize::new(0);
    let finished = AtomicBool::new(false);
    std::thread::scope(|scope| {
        scope.spawn(|| {
            while !finished.load(Ordering::Relaxed) {
                bar.set_position((base + done.load(Ordering::Relaxed)) as u64);
                std::thread::sleep(Duration::from_millis(100));
            }
        });
        let result = run(&done);
        finished.store(true, Ordering::Relaxed);
        result
    })
}

/// Writes an estimator's estimates into `out` as `<stem>_poses.tum`, `<stem>_twists.csv` and
/// `<stem>_diagnostics.csv`.
fn write_estimates(
    out: &std::path::Path,
    stem: &str,
    estimates: &[roitrack::Estimate],
) -> Result<()> {
    let mut writer = EstimateWriter::create(
        &out.join(format!("{stem}_poses.tum")),
        &out.join(format!("{stem}_twists.csv")),
        Some(&out.join(format!("{stem}_diagnostics.csv"))),
    )?;
    for e in estimates {
        writer.write(e)?;
    }
    writer.finish()?;
    Ok(())
}

/// Where the default estimator's run goes besides its files, each if asked: the bag (--mcap), the live view
/// (--foxglove) and the DDS bus (--ros2). Opened before the runs, so that a live viewer (--foxglove,
/// --foxglove-wait-s) is there from the start; each is finished, and taken, once that run is done.
struct DefaultRunSinks {
    bag: Option<crate::ros::Bag>,
    /// The live view follows the default estimator's run from the loop's estimation thread, as it tracks.
    live: Option<roitrack::ros::LiveServer>,
    /// --ros2 publishes the same run's estimates on the DDS bus, from the estimation thread too.
    ros2: Option<crate::ros2_args::Ros2>,
}

impl DefaultRunSinks {
    fn open(args: &DemoArgs, demo: &Demo) -> Result<Self> {
        let mut bag = Some(args.ros.open_for_rois(Some(&demo.run.camera), None)?);
        let live = bag.as_mut().and_then(|b| b.take_live());
        let ros2 = Some(
            args.ros2
                .start(Some(&demo.run.camera), &args.ros.bag_options())?,
        );
        Ok(DefaultRunSinks { bag, live, ros2 })
    }

    /// The default estimator's run: each estimate to the live view and the DDS bus as the loop makes it, and with
    /// --mcap-rois each ROI to the bag as the camera grabs it (on two threads: an error slot each).
    fn observed_run(
        &mut self,
        demo: &Demo,
        estimator: &DemoEstimator,
        done: &AtomicUsize,
    ) -> Result<DemoRun> {
        let DefaultRunSinks { bag, live, ros2 } = self;
        let (mut live_error, mut roi_error, mut ros2_error) = (None, None, None);
        let wants_rois = bag.as_ref().is_some_and(|b| b.wants_rois());
        let mut on_roi = |image: &RoiImage, measured: Option<&Measurement>| {
            if let (None, Some(bag)) = (&roi_error, bag.as_mut()) {
                roi_error = bag.roi_image(image, measured).err();
            }
        };
        let run = demo.from_images_observed(
            estimator,
            Some(done),
            &mut |e| {
                if let (None, Some(live)) = (&live_error, live.as_mut()) {
                    live_error = live.publish_estimate(e).err();
                }
                if let (None, Some(ros2)) = (&ros2_error, ros2.as_mut()) {
                    ros2_error = ros2.estimate(e).err();
                }
            },
            match wants_rois {
                true => Some(&mut on_roi),
                false => None,
            },
        );
        match live_error.or(roi_error).or(ros2_error) {
            Some(e) => Err(e.into()),
            None => run.map_err(anyhow::Error::from),
        }
    }

    /// After the default estimator's run (`from_images`): its measurements and estimates to the bag, then the bag,
    /// the live view and the DDS node finished. Nothing after the first run: each is taken.
    fn finish(&mut self, from_images: &DemoRun) -> Result<()> {
        if let Some(mut bag) = self.bag.take() {
            let measured = from_images
                .loop_report
                .as_ref()
                .map_or(&[][..], |r| &r.measured);
            bag.run(measured, &from_images.scored.estimates)?;
            bag.finish()?;
        }
        if let Some(live) = self.live.take() {
            crate::ros::finish_live(live)?;
        }
        if let Some(ros2) = self.ros2.take() {
            ros2.finish()?;
        }
        Ok(())
    }
}
