//! `cargo bench --bench time_to_walk -- [OPTIONS]`: how long each algorithm takes to walk Minitaur.
//!
//! Every (algorithm, seed) trains with its preset on Minitaur's default task until held-out
//! episodes (the report's protocol: 50 reset seeds no run trains or evaluates on, deterministic
//! actions) show, separately:
//! - `return-10`: a mean return above 10 (about 1 m/s held for 10 s);
//! - `beats-matched`: a mean return above the controller's at the policy's own speed (the
//!   controller commanded whatever achieves that speed on its grid; a policy faster than the
//!   controller can run is compared with the controller's best speed instead);
//! - `beats-best`: a mean return above the controller's best working speed.
//!
//! Held-out episodes are played after every in-training evaluation whose mean return is at
//! least 1 (`GATE`); the time they take is not counted. The time reported is the run's own wall
//! time (acting, learning and its in-training evaluations) at that evaluation. A run stops when
//! all three are reached, or at `--minutes` of training, or at `--steps`.
//!
//! With `--env minitaur-command` it measures instead how long each algorithm takes to follow
//! commands as the controller does, on the straight commands of the controller's range
//! ([`TRACKED_SPEEDS`]; every contender on the same held-out episodes, `evaluation::tracking`):
//! - `within-2x-controller`: no held-out episode falls at any of these commands, and at every
//!   command the mean RMS speed error is at most twice the controller's;
//! - `tracks-like-controller`: no falls, and at every command a mean RMS speed error no larger
//!   than the controller's.
//!
//! These checks play far more episodes, so they come at most every `--check-every` steps
//! (default 250k there), after an in-training evaluation of at least [`TRACKING_GATE`].
//!
//! Options: `--env minitaur` `--algos ppo,td3,sac` `--seeds 3` (seeds 0..n) `--minutes 15`
//! `--steps 1000000` `--episodes 50` (held-out episodes per check and command) `--check-every N`
//! `--jobs 1` (runs at a time) `--threads N` (per run; default 2 when runs go one at a time, 1
//! otherwise) `--set key=value,...` (hyperparameter overrides for every run)
//! `--out target/bench-time-to-walk`.
//! Writes `<out>/time-to-walk.csv` (`time-to-track.csv` on a command task; one row per run and
//! threshold), `<out>/checks.csv` (every held-out check) and the run directories
//! `<out>/runs/<algo>-seed<k>/`.
//!
//! Without `--bench` (as `cargo test --all-targets` runs it): PPO, one seed, 4096 steps, 2
//! held-out episodes, to test the whole path.
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use locobench::agents::Algo;
use locobench::controller::baseline::{baseline_controller_for, baseline_env_like};
use locobench::controller::command::Command;
use locobench::envs::EnvConfig;
use locobench::evaluation::stats::quantile;
use locobench::evaluation::tracking::{tracking_grid, TrackingPoint};
use locobench::evaluation::{HeldOutCheck, Protocol, WalkingCheck, DEFAULT_EPISODES};
use locobench::io::write_bytes_atomic;
use locobench::policy::{AgentPolicy, Policy};
use locobench::train::config::build_config;
use locobench::train::provenance::Stretch;
use locobench::train::{train, EvaluationEvent, EvaluationHook, RunControl};

/// In-training evaluations below this mean return are not checked on held-out episodes.
const GATE: f64 = 1.0;
/// The same on a command task, whose returns are larger (a standing robot earns the yaw term).
const TRACKING_GATE: f64 = 5.0;
/// The return threshold (the "walking": about 1 m/s for the whole 10 s episode).
const RETURN_THRESHOLD: f64 = 10.0;
/// The straight commands the tracking checks play (m/s): the controller's working range.
const TRACKED_SPEEDS: [f64; 4] = [0.25, 0.5, 1.0, 1.5];

struct Options {
    env: String,
    algos: Vec<String>,
    seeds: u64,
    minutes: f64,
    steps: u64,
    episodes: usize,
    jobs: usize,
    out: PathBuf,
    set: Vec<(String, String)>,
    gate: Option<f64>,
    check_every: Option<u64>,
    threads: Option<usize>,
}

/// The benches to run: the one asked for, or both smoke runs.
fn parse_options() -> Result<Vec<Options>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !args.iter().any(|a| a == "--bench") {
        let smoke = |env: &str, out: &str| -> Result<Options> {
            Ok(Options { env: env.into(), out: PathBuf::from(out), ..smoke_options()? })
        };
        return Ok(vec![
            smoke("minitaur", "target/bench-time-to-walk-smoke")?,
            smoke("minitaur-command", "target/bench-time-to-walk-smoke-command")?,
        ]);
    }
    parse_bench_options(args).map(|o| vec![o])
}

/// A short run of one PPO seed that checks every evaluation (as `cargo test --all-targets` runs it).
fn smoke_options() -> Result<Options> {
    Ok(Options {
        env: "minitaur".into(),
        algos: vec!["ppo".into()],
        seeds: 1,
        minutes: 5.0,
        steps: 4096,
        episodes: 2,
        jobs: 1,
        out: PathBuf::from("target/bench-time-to-walk-smoke"),
        set: locobench::train::config::split_pairs("num_steps=256,eval_every=2048,eval_episodes=2")?,
        // Every evaluation is checked, so that the check itself is exercised.
        gate: Some(f64::NEG_INFINITY),
        check_every: None,
        threads: None,
    })
}

fn parse_bench_options(args: Vec<String>) -> Result<Options> {
    let mut o = Options {
        env: "minitaur".into(),
        algos: vec!["ppo".into(), "td3".into(), "sac".into()],
        seeds: 3,
        minutes: 15.0,
        steps: 1_000_000,
        episodes: DEFAULT_EPISODES,
        jobs: 1,
        out: PathBuf::from("target/bench-time-to-walk"),
        set: Vec::new(),
        gate: None,
        check_every: None,
        threads: None,
    };
    let mut it = args.iter().filter(|a| *a != "--bench");
    while let Some(flag) = it.next() {
        let mut value = || it.next().with_context(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--env" => o.env = value()?.to_string(),
            "--algos" => o.algos = value()?.split(',').map(str::to_string).collect(),
            "--seeds" => o.seeds = value()?.parse().context("--seeds")?,
            "--minutes" => o.minutes = value()?.parse().context("--minutes")?,
            "--steps" => o.steps = value()?.parse().context("--steps")?,
            "--episodes" => o.episodes = value()?.parse().context("--episodes")?,
            "--check-every" => o.check_every = Some(value()?.parse().context("--check-every")?),
            "--jobs" => o.jobs = value()?.parse().context("--jobs")?,
            "--out" => o.out = PathBuf::from(value()?),
            "--threads" => o.threads = Some(value()?.parse().context("--threads")?),
            "--set" => o.set = locobench::train::config::split_pairs(value()?)?,
            other => bail!("unknown option {other} (see the comment at the top of benches/time_to_walk.rs)"),
        }
    }
    for a in &o.algos {
        Algo::parse(a)?;
    }
    if o.jobs == 0 || o.seeds == 0 || o.episodes == 0 {
        bail!("--jobs, --seeds and --episodes must be at least 1");
    }
    if !matches!(o.env.as_str(), "minitaur" | "minitaur-command") {
        bail!("--env takes minitaur or minitaur-command, not '{}'", o.env);
    }
    Ok(o)
}

/// What one held-out check found: which thresholds it passes, its `checks.csv` fields and its
/// fields in the summary when it is the first to pass a threshold.
struct Outcome {
    passed: Vec<bool>,
    check_fields: String,
    hit_fields: String,
}

/// How a policy is checked: against the controller's returns (`minitaur`) or its tracking
/// (a command task).
#[derive(Clone)]
enum Checker {
    Walking { check: WalkingCheck, best: f64 },
    Tracking { env: EnvConfig, protocol: Protocol, controller: Vec<TrackingPoint> },
}

impl Checker {
    fn new(o: &Options) -> Result<Checker> {
        let env = EnvConfig::new(&o.env);
        let protocol = Protocol { episodes: o.episodes, seed: 0 };
        let started = Instant::now();
        if locobench::envs::command::is_command_task(&o.env) {
            let cfg = baseline_env_like(&env)?;
            let mut c = baseline_controller_for(&cfg.name, Command::straight(0.0, 0.0), None)?;
            let controller = tracking_grid(&cfg, c.as_mut(), &TRACKED_SPEEDS, &[0.0], protocol)?;
            println!(
                "controller tracking: {:.0} s; RMS speed error {}",
                started.elapsed().as_secs_f64(),
                rms_list(&controller)
            );
            return Ok(Checker::Tracking { env, protocol, controller });
        }
        let check = WalkingCheck::new(&env, protocol, 2)?;
        let (best_command, best) = check.controller_best().context("the controller works at no speed")?;
        println!(
            "controller grid: {:.0} s; best {best:.2} at {best_command:.2} m/s commanded, top speed {:.2} m/s",
            started.elapsed().as_secs_f64(),
            check.controller_top_speed().unwrap_or(0.0)
        );
        Ok(Checker::Walking { check, best })
    }

    fn thresholds(&self) -> &'static [&'static str] {
        match self {
            Checker::Walking { .. } => &["return-10", "beats-matched", "beats-best"],
            Checker::Tracking { .. } => &["within-2x-controller", "tracks-like-controller"],
        }
    }

    fn gate(&self) -> f64 {
        match self {
            Checker::Walking { .. } => GATE,
            Checker::Tracking { .. } => TRACKING_GATE,
        }
    }

    fn default_check_every(&self) -> u64 {
        match self {
            Checker::Walking { .. } => 0,
            Checker::Tracking { .. } => 250_000,
        }
    }

    fn file(&self) -> &'static str {
        match self {
            Checker::Walking { .. } => "time-to-walk.csv",
            Checker::Tracking { .. } => "time-to-track.csv",
        }
    }

    /// The columns after `algo,seed,step,training_s,eval_mean` in `checks.csv`, and after
    /// `algo,seed,threads,threshold,reached,step,training_s` in the summary.
    fn columns(&self) -> (&'static str, &'static str) {
        match self {
            Checker::Walking { .. } => (
                "heldout_return,heldout_low,heldout_high,speed,falls,episodes,controller_command,controller_matched,controller_return,beats_matched",
                "heldout_return,heldout_low,heldout_high,speed,falls,episodes,controller_command,controller_matched,controller_return",
            ),
            Checker::Tracking { .. } => (
                "falls,episodes,speed_rms,controller_speed_rms,worst_rms_ratio",
                "falls,episodes,speed_rms,controller_speed_rms,worst_rms_ratio",
            ),
        }
    }

    fn check(&mut self, policy: &mut dyn Policy) -> Result<Outcome> {
        match self {
            Checker::Walking { check, best } => {
                let c = check.check(policy)?;
                let passed = vec![c.mean_return > RETURN_THRESHOLD, c.beats_controller(), c.mean_return > *best];
                Ok(Outcome { passed, check_fields: walking_fields(&c, true), hit_fields: walking_fields(&c, false) })
            }
            Checker::Tracking { env, protocol, controller } => {
                let points = tracking_grid(env, policy, &TRACKED_SPEEDS, &[0.0], *protocol)?;
                let falls: usize = points.iter().map(TrackingPoint::falls).sum();
                let episodes: usize = points.iter().map(|p| p.episodes.len()).sum();
                let worst = points
                    .iter()
                    .zip(controller.iter())
                    .map(|(p, c)| p.speed_rms().estimate / c.speed_rms().estimate)
                    .fold(0.0f64, |a, r| if r.is_nan() { f64::INFINITY } else { a.max(r) });
                let fields = format!("{falls},{episodes},{},{},{worst:.4}", rms_list(&points), rms_list(controller));
                Ok(Outcome {
                    passed: vec![falls == 0 && worst <= 2.0, falls == 0 && worst <= 1.0],
                    check_fields: fields.clone(),
                    hit_fields: fields,
                })
            }
        }
    }
}

/// Each point's mean RMS speed error as `speed:rms` joined by spaces.
fn rms_list(points: &[TrackingPoint]) -> String {
    points.iter().map(|p| format!("{}:{:.4}", p.speed, p.speed_rms().estimate)).collect::<Vec<_>>().join(" ")
}

/// A walking check's CSV fields (with whether it beats the matched controller, for `checks.csv`).
fn walking_fields(c: &HeldOutCheck, with_beats: bool) -> String {
    let (command, matched, controller_return) = match &c.controller {
        Ok(k) => (format!("{:.3}", k.command), k.matched.to_string(), format!("{:.4}", k.mean_return)),
        Err(_) => Default::default(),
    };
    let mut s = format!(
        "{:.4},{:.4},{:.4},{:.4},{},{},{command},{matched},{controller_return}",
        c.mean_return, c.return_interval.low, c.return_interval.high, c.speed, c.falls, c.episodes
    );
    if with_beats {
        s += &format!(",{}", c.beats_controller());
    }
    s
}

/// The first held-out check that passed a threshold.
#[derive(Clone)]
struct Hit {
    step: u64,
    training_s: f64,
    fields: String,
}

/// What one run's hook keeps between evaluations.
#[derive(Default)]
struct RunState {
    /// Time spent in held-out checks so far (s), which the run's wall time includes.
    checking_s: f64,
    hits: Vec<Option<Hit>>,
    last_step: u64,
    last_training_s: f64,
    last_checked: Option<u64>,
    checks: Vec<String>,
}

/// Trains one run, checking held-out episodes as it goes.
fn run_one(o: &Options, algo: &str, seed: u64, threads: usize, checker: Checker) -> Result<RunState> {
    let env = EnvConfig::new(&o.env);
    let mut overrides = o.set.clone();
    overrides.push(("total_steps".into(), o.steps.to_string()));
    let cfg = build_config(&env.name, Algo::parse(algo)?, &overrides)?;
    Protocol { episodes: o.episodes, seed: 0 }.check_disjoint(seed, cfg.total_steps, cfg.eval_episodes)?;
    let thresholds = checker.thresholds().len();
    let state = Arc::new(Mutex::new(RunState { hits: vec![None; thresholds], ..Default::default() }));
    let (gate, every) = (o.gate.unwrap_or(checker.gate()), o.check_every.unwrap_or(checker.default_check_every()));
    let checker = Arc::new(Mutex::new(checker));
    let (hook_state, algo_name, cap_s) = (Arc::clone(&state), algo.to_string(), o.minutes * 60.0);
    let hook = EvaluationHook(Arc::new(move |ev: &EvaluationEvent<'_>| -> Result<bool> {
        let started = Instant::now();
        let mut s = hook_state.lock().unwrap();
        let training_s = ev.wall_time - s.checking_s;
        (s.last_step, s.last_training_s) = (ev.step, training_s);
        let due = s.last_checked.is_none_or(|at| ev.step >= at + every);
        if ev.evaluation.mean() >= gate && due {
            s.last_checked = Some(ev.step);
            let mut policy = AgentPolicy { agent: ev.agent, label: algo_name.clone() };
            let c = checker.lock().unwrap().check(&mut policy)?;
            s.checks.push(format!(
                "{algo_name},{seed},{},{training_s:.1},{:.4},{}",
                ev.step,
                ev.evaluation.mean(),
                c.check_fields
            ));
            for (t, passed) in c.passed.iter().enumerate() {
                if s.hits[t].is_none() && *passed {
                    s.hits[t] = Some(Hit { step: ev.step, training_s, fields: c.hit_fields.clone() });
                }
            }
        }
        s.checking_s += started.elapsed().as_secs_f64();
        Ok(s.hits.iter().all(Option::is_some) || training_s >= cap_s)
    }));
    let control = RunControl { threads, on_evaluation: Some(hook), ..Default::default() };
    let run_dir = o.out.join("runs").join(format!("{algo}-seed{seed}"));
    train(env, cfg, seed, &run_dir, None, true, &control)?;
    let s = std::mem::take(&mut *state.lock().unwrap());
    Ok(s)
}

fn result_rows(checker: &Checker, algo: &str, seed: u64, threads: usize, s: &RunState) -> Vec<String> {
    let empty = ",".repeat(checker.columns().1.matches(',').count());
    checker
        .thresholds()
        .iter()
        .zip(&s.hits)
        .map(|(name, hit)| match hit {
            Some(h) => format!("{algo},{seed},{threads},{name},true,{},{:.1},{}", h.step, h.training_s, h.fields),
            None => format!("{algo},{seed},{threads},{name},false,{},{:.1},{empty}", s.last_step, s.last_training_s),
        })
        .collect()
}

fn summarize(checker: &Checker, results: &[(String, u64, RunState)]) {
    println!(
        "\n{:<6} {:<22} {:>8} {:>24} {:>28}",
        "algo", "threshold", "reached", "minutes (min-median-max)", "steps (min-median-max)"
    );
    let mut algos: Vec<&str> = results.iter().map(|r| r.0.as_str()).collect();
    algos.dedup();
    for algo in algos {
        let runs: Vec<&RunState> = results.iter().filter(|r| r.0 == algo).map(|r| &r.2).collect();
        for (t, name) in checker.thresholds().iter().enumerate() {
            let hits: Vec<&Hit> = runs.iter().filter_map(|s| s.hits[t].as_ref()).collect();
            let spread = |mut v: Vec<f64>, unit: &str| -> String {
                if v.is_empty() {
                    return "-".into();
                }
                v.sort_by(f64::total_cmp);
                format!("{:.1}{unit} - {:.1}{unit} - {:.1}{unit}", v[0], quantile(&v, 0.5), v[v.len() - 1])
            };
            println!(
                "{algo:<6} {name:<22} {:>8} {:>24} {:>28}",
                format!("{}/{}", hits.len(), runs.len()),
                spread(hits.iter().map(|h| h.training_s / 60.0).collect(), ""),
                spread(hits.iter().map(|h| h.step as f64 / 1000.0).collect(), "k")
            );
        }
    }
}

/// Writes the summary and `checks.csv` for the runs finished so far (sorted by algorithm as
/// given, then seed).
fn write_results(
    o: &Options,
    checker: &Checker,
    header: &str,
    threads: usize,
    results: &mut [(String, u64, RunState)],
) -> Result<()> {
    results.sort_by_key(|r| (o.algos.iter().position(|x| *x == r.0), r.1));
    let (check_columns, hit_columns) = checker.columns();
    let mut summary = format!("{header}algo,seed,threads,threshold,reached,step,training_s,{hit_columns}\n");
    let mut checks = format!("{header}algo,seed,step,training_s,eval_mean,{check_columns}\n");
    for (algo, seed, s) in results.iter() {
        for row in result_rows(checker, algo, *seed, threads, s) {
            summary += &(row + "\n");
        }
        for row in &s.checks {
            checks += &(row.clone() + "\n");
        }
    }
    write_bytes_atomic(&o.out.join(checker.file()), summary.as_bytes())?;
    write_bytes_atomic(&o.out.join("checks.csv"), checks.as_bytes())
}

fn main() -> Result<()> {
    locobench::runtime::configure_process();
    for o in parse_options()? {
        run_bench(&o)?;
    }
    Ok(())
}

fn run_bench(o: &Options) -> Result<()> {
    std::fs::create_dir_all(&o.out)?;
    let checker = Checker::new(o)?;
    let threads = o.threads.unwrap_or(if o.jobs == 1 { 2 } else { 1 });
    let queue: Mutex<VecDeque<(String, u64)>> =
        Mutex::new(o.algos.iter().flat_map(|a| (0..o.seeds).map(move |s| (a.clone(), s))).collect());
    let header = {
        let machine = Stretch::here(0, threads, option_env!("LOCOBENCH_GIT_COMMIT"));
        format!(
            "# machine: {} ({}), {} run(s) at a time, {} thread(s) each; commit {}; command: cargo bench --bench time_to_walk -- {}\n",
            machine.cpu_model,
            machine.simd,
            o.jobs,
            threads,
            machine.git_commit,
            std::env::args().skip(1).filter(|a| a != "--bench").collect::<Vec<_>>().join(" ")
        )
    };
    let results: Mutex<Vec<(String, u64, RunState)>> = Mutex::new(Vec::new());
    let failures: Mutex<Vec<String>> = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..o.jobs {
            scope.spawn(|| loop {
                let Some((algo, seed)) = queue.lock().unwrap().pop_front() else { break };
                println!("training {algo} seed {seed}");
                match run_one(o, &algo, seed, threads, checker.clone()) {
                    Ok(s) => {
                        let mut results = results.lock().unwrap();
                        results.push((algo, seed, s));
                        // Rewritten after every run, so that a stopped bench keeps what finished.
                        if let Err(e) = write_results(o, &checker, &header, threads, &mut results) {
                            failures.lock().unwrap().push(format!("writing results: {e:#}"));
                        }
                    }
                    Err(e) => failures.lock().unwrap().push(format!("{algo} seed {seed}: {e:#}")),
                }
            });
        }
    });
    let results = results.into_inner().unwrap();
    summarize(&checker, &results);
    println!("written {}", o.out.join(checker.file()).display());
    let failures = failures.into_inner().unwrap();
    if !failures.is_empty() {
        bail!("runs failed:\n{}", failures.join("\n"));
    }
    Ok(())
}
