//! The sweep run: its options, each case simulated and its grid searched on threads of their own ([`sweep`]).

use std::collections::HashSet;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use roitrack_estimators::{TrackerConfig, track_all};
use roitrack_sim::{SimulatedRun, SimulationOptions, simulate};
use serde::Serialize;

use super::case::{Case, Purpose, cases};
use super::goal::BOUND_FACTOR;
use super::grid::{Grid, GridIndex};
use super::results::{CaseResult, HandTuned, RunSummary, Visited};
use crate::ExperimentError;
use roitrack_demo::scoring::{Scored, score};

/// What the sweep runs.
///
/// ```
/// use roitrack_experiments::adaptive::SweepOptions;
///
/// let full = SweepOptions::full();
/// assert_eq!((full.cases.len(), full.max_duration_s), (22, None));
/// let quick = SweepOptions::quick();
/// assert!(quick.cases.len() < full.cases.len() && quick.max_duration_s.is_some());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepOptions {
    /// The cases run, in order.
    pub cases: Vec<Case>,
    /// The hand-tuned filter's grid, searched on the accuracy cases.
    pub grid: Grid,
    /// Scenarios cut to at most this long (s); `None`: whole.
    pub max_duration_s: Option<f64>,
    /// Cases run at once. Default: the machine's cores.
    pub threads: usize,
    /// Whether this is the quick mode (for the description).
    pub quick: bool,
}

impl Default for SweepOptions {
    fn default() -> Self {
        Self::full()
    }
}

impl SweepOptions {
    /// Every case of [`cases`], whole, on [`Grid::full`].
    pub fn full() -> Self {
        Self {
            cases: cases(),
            grid: Grid::full(),
            max_duration_s: None,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            quick: false,
        }
    }

    /// For tests: 5 accuracy cases (4 kHz at 0.1 px, still, random, wide-angle, 2x3) and 2 calibration cases (static
    /// at 0.3 px, spin at 1 px), cut to 0.6 s, on [`Grid::quick`].
    pub fn quick() -> Self {
        const QUICK: [&str; 7] = [
            "4 kHz, 0.1 px",
            "still 1.6 m",
            "random 2.5 m/s, 7 rad/s",
            "wide-angle 1280x1024",
            "2x3 target",
            "static, 0.3 px",
            "spin, 1 px",
        ];
        Self {
            cases: cases()
                .into_iter()
                .filter(|c| QUICK.contains(&c.name))
                .collect(),
            grid: Grid::quick(),
            max_duration_s: Some(0.6),
            quick: true,
            ..Self::full()
        }
    }

    /// Every case simulated with these seeds instead of its own, its figures pooled over them (the lag: the largest
    /// over the seeds).
    ///
    /// ```
    /// use roitrack_experiments::adaptive::SweepOptions;
    ///
    /// let options = SweepOptions::full().with_seeds(&[2, 3]);
    /// assert!(options.cases.iter().all(|c| c.seeds == [2, 3]));
    /// ```
    pub fn with_seeds(mut self, seeds: &[u64]) -> Self {
        for case in &mut self.cases {
            case.seeds = seeds.to_vec();
        }
        self
    }
}

/// Why the sweep could not run.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The grid is invalid: what is wrong with which axis.
    #[error("invalid grid: {0}")]
    Grid(String),
    /// Zero threads asked for.
    #[error("the sweep needs at least one thread")]
    NoThreads,
    /// A case has no seed.
    #[error("case {case} has no seed to simulate")]
    NoSeeds {
        /// The case's name.
        case: &'static str,
    },
    /// A case's simulation or tracking failed.
    #[error("case {case}: {source}")]
    Case {
        /// The case's name.
        case: &'static str,
        /// What failed.
        #[source]
        source: ExperimentError,
    },
}

/// The sweep's results.
#[derive(Debug, Clone, Serialize)]
pub struct Sweep {
    /// What was run.
    pub options: SweepOptions,
    /// One per case, in the options' order.
    pub cases: Vec<CaseResult>,
    /// Wall time of the sweep (s).
    pub seconds: f64,
}

/// Runs every case of `options` (see the [module docs](super)), cases in parallel on `options.threads` threads.
/// `progress`, when given, counts the cases done.
///
/// ```
/// use std::sync::atomic::{AtomicUsize, Ordering};
/// use roitrack_experiments::adaptive::{Purpose, SweepOptions, sweep};
///
/// let mut options = SweepOptions::quick();
/// options.cases.retain(|c| c.purpose == Purpose::Calibration);
/// options.max_duration_s = Some(0.3);
/// let done = AtomicUsize::new(0);
/// let result = sweep(&options, Some(&done)).unwrap();
/// assert_eq!(done.load(Ordering::Relaxed), 2);
/// // Calibration cases search no grid: the default and the told-the-truth filters only.
/// assert!(result.cases.iter().all(|c| c.best.is_none() && c.visited.len() == 1));
/// ```
pub fn sweep(options: &SweepOptions, progress: Option<&AtomicUsize>) -> Result<Sweep, SweepError> {
    options.grid.validate().map_err(SweepError::Grid)?;
    if options.threads == 0 {
        return Err(SweepError::NoThreads);
    }
    if let Some(case) = options.cases.iter().find(|c| c.seeds.is_empty()) {
        return Err(SweepError::NoSeeds { case: case.name });
    }
    let start = Instant::now();
    // The longest cases first, so that the last to finish is a short one.
    let cost = |c: &Case| {
        let duration = c.scenario(c.seeds[0]).duration_s;
        let duration = options.max_duration_s.map_or(duration, |m| duration.min(m));
        let runs = match c.purpose {
            Purpose::Accuracy => 30.0,
            Purpose::Calibration => 2.0,
        };
        duration * c.rate_hz * c.seeds.len() as f64 * runs
    };
    let mut order: Vec<usize> = (0..options.cases.len()).collect();
    order.sort_by(|&a, &b| cost(&options.cases[b]).total_cmp(&cost(&options.cases[a])));
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Result<CaseResult, SweepError>)>> = Mutex::new(Vec::new());
    let workers = options.threads.min(order.len());
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&index) = order.get(k) else {
                        break;
                    };
                    let case = &options.cases[index];
                    let result = run_case(case, options).map_err(|source| SweepError::Case {
                        case: case.name,
                        source,
                    });
                    let failed = result.is_err();
                    results
                        .lock()
                        .expect("no worker panics holding the lock")
                        .push((index, result));
                    if let Some(done) = progress {
                        done.fetch_add(1, Ordering::Relaxed);
                    }
                    if failed {
                        next.store(order.len(), Ordering::Relaxed);
                        break;
                    }
                }
            });
        }
    });
    let mut results = results.into_inner().expect("the workers have ended");
    results.sort_by_key(|(index, _)| *index);
    let cases = results
        .into_iter()
        .map(|(_, r)| r)
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Sweep {
        options: options.clone(),
        cases,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// What the search minimises: the pooled position RMSE, infinite when some seed gave no estimate.
fn objective(summary: &RunSummary) -> f64 {
    if summary.runs_without_estimates == 0 && summary.position_rmse_mm.is_finite() {
        summary.position_rmse_mm
    } else {
        f64::INFINITY
    }
}

/// Simulates a case's seeds, searches the grid (accuracy cases), and runs the default filter.
fn run_case(case: &Case, options: &SweepOptions) -> Result<CaseResult, ExperimentError> {
    let start = Instant::now();
    let runs: Vec<SimulatedRun> = case
        .seeds
        .iter()
        .map(|&seed| {
            let mut scenario = case.scenario(seed);
            if let Some(max) = options.max_duration_s {
                scenario.duration_s = scenario.duration_s.min(max);
            }
            let sim = SimulationOptions {
                seed,
                noise_px: case.noise_px,
                rate_hz: case.rate_hz,
                ..SimulationOptions::default()
            };
            simulate(&scenario, &sim)
        })
        .collect::<Result<_, _>>()?;
    let track = |config: TrackerConfig| -> Result<Vec<Option<Scored>>, ExperimentError> {
        runs.iter()
            .map(|run| {
                let start = Instant::now();
                let (estimates, _) =
                    track_all(&run.camera, &run.target, config, &run.measurements)?;
                let seconds = start.elapsed().as_secs_f64();
                if estimates.is_empty() {
                    Ok(None)
                } else {
                    Ok(Some(score(run, estimates, seconds)?))
                }
            })
            .collect()
    };
    let grid = &options.grid;
    let run_at = |at: GridIndex| -> Result<RunSummary, ExperimentError> {
        RunSummary::of(&runs, &track(grid.tuning(at, case.noise_px).config())?)
    };
    let mut visited: Vec<Visited> = Vec::new();
    let mut note = |at: GridIndex, summary: &RunSummary| {
        visited.push(Visited {
            tuning: grid.tuning(at, case.noise_px),
            position_rmse_mm: summary.position_rmse_mm,
            runs_without_estimates: summary.runs_without_estimates,
        });
    };
    let truth_at = grid.truth_index();
    let truth_summary = run_at(truth_at)?;
    note(truth_at, &truth_summary);
    let told_truth = HandTuned {
        tuning: grid.tuning(truth_at, case.noise_px),
        on_edge: grid.on_edge(truth_at),
        summary: truth_summary.clone(),
    };
    let best = if case.purpose == Purpose::Accuracy {
        let mut best = (truth_at, truth_summary);
        for at in grid.coarse().into_iter().filter(|&p| p != truth_at) {
            let summary = run_at(at)?;
            note(at, &summary);
            if objective(&summary) < objective(&best.1) {
                best = (at, summary);
            }
        }
        let mut tried: HashSet<GridIndex> = grid.coarse().into_iter().collect();
        for _ in 0..grid.max_rounds {
            let mut moved = false;
            for at in grid.neighbours(best.0) {
                if !tried.insert(at) {
                    continue;
                }
                let summary = run_at(at)?;
                note(at, &summary);
                if objective(&summary) < objective(&best.1) {
                    best = (at, summary);
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
        Some(HandTuned {
            tuning: grid.tuning(best.0, case.noise_px),
            on_edge: grid.on_edge(best.0),
            summary: best.1,
        })
    } else {
        None
    };
    let default_scored = track(TrackerConfig::default())?;
    let default = RunSummary::of(&runs, &default_scored)?;
    let nominal_mm = best.as_ref().map(|b| b.summary.position_rmse_mm);
    let beyond_bound = nominal_mm.map(|nominal| {
        let bound_m = BOUND_FACTOR * nominal * 1e-3;
        default_scored
            .iter()
            .flatten()
            .flat_map(|s| s.estimates.iter().zip(&s.errors.position_m))
            .filter(|(e, error)| e.status.is_vouched_for() && error.norm() > bound_m)
            .count()
    });
    Ok(CaseResult {
        case: case.clone(),
        measurements: runs.iter().map(|r| r.measurements.len()).sum(),
        default,
        told_truth,
        best,
        visited,
        nominal_mm,
        beyond_bound,
        seconds: start.elapsed().as_secs_f64(),
    })
}
