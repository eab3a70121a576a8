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
//! Options: `--algos ppo,td3,sac` `--seeds 3` (seeds 0..n) `--minutes 15` `--steps 1000000`
//! `--episodes 50` (held-out episodes per check) `--jobs 1` (runs at a time) `--threads N` (per
//! run; default 2 when runs go one at a time, 1 otherwise) `--set key=value,...` (hyperparameter
//! overrides for every run) `--out target/bench-time-to-walk`.
//! Writes `<out>/time-to-walk.csv` (one row per run and threshold), `<out>/checks.csv` (every
//! held-out check) and the run directories `<out>/runs/<algo>-seed<k>/`.
//!
//! Without `--bench` (as `cargo test --all-targets` runs it): PPO, one seed, 4096 steps, 2
//! held-out episodes, to test the whole path.
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use locobench::agents::Algo;
use locobench::envs::EnvConfig;
use locobench::evaluation::stats::quantile;
use locobench::evaluation::{HeldOutCheck, Protocol, WalkingCheck, DEFAULT_EPISODES};
use locobench::io::write_bytes_atomic;
use locobench::policy::AgentPolicy;
use locobench::train::config::build_config;
use locobench::train::provenance::Stretch;
use locobench::train::{train, EvaluationEvent, EvaluationHook, RunControl};

/// In-training evaluations below this mean return are not checked on held-out episodes.
const GATE: f64 = 1.0;
/// The return threshold (the "walking": about 1 m/s for the whole 10 s episode).
const RETURN_THRESHOLD: f64 = 10.0;
const THRESHOLDS: [&str; 3] = ["return-10", "beats-matched", "beats-best"];

struct Options {
    algos: Vec<String>,
    seeds: u64,
    minutes: f64,
    steps: u64,
    episodes: usize,
    jobs: usize,
    out: PathBuf,
    set: Vec<(String, String)>,
    gate: f64,
    threads: Option<usize>,
}

fn parse_options() -> Result<Options> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !args.iter().any(|a| a == "--bench") {
        return Ok(Options {
            algos: vec!["ppo".into()],
            seeds: 1,
            minutes: 5.0,
            steps: 4096,
            episodes: 2,
            jobs: 1,
            out: PathBuf::from("target/bench-time-to-walk-smoke"),
            set: locobench::train::config::split_pairs("num_steps=256,eval_every=2048,eval_episodes=2")?,
            // Every evaluation is checked, so that the check itself is exercised.
            gate: f64::NEG_INFINITY,
            threads: None,
        });
    }
    let mut o = Options {
        algos: vec!["ppo".into(), "td3".into(), "sac".into()],
        seeds: 3,
        minutes: 15.0,
        steps: 1_000_000,
        episodes: DEFAULT_EPISODES,
        jobs: 1,
        out: PathBuf::from("target/bench-time-to-walk"),
        set: Vec::new(),
        gate: GATE,
        threads: None,
    };
    let mut it = args.iter().filter(|a| *a != "--bench");
    while let Some(flag) = it.next() {
        let mut value = || it.next().with_context(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--algos" => o.algos = value()?.split(',').map(str::to_string).collect(),
            "--seeds" => o.seeds = value()?.parse().context("--seeds")?,
            "--minutes" => o.minutes = value()?.parse().context("--minutes")?,
            "--steps" => o.steps = value()?.parse().context("--steps")?,
            "--episodes" => o.episodes = value()?.parse().context("--episodes")?,
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
    Ok(o)
}

/// The first held-out check that passed a threshold.
#[derive(Clone)]
struct Hit {
    step: u64,
    training_s: f64,
    check: HeldOutCheck,
}

/// What one run's hook keeps between evaluations.
#[derive(Default)]
struct RunState {
    /// Time spent in held-out checks so far (s), which the run's wall time includes.
    checking_s: f64,
    hits: [Option<Hit>; 3],
    last_step: u64,
    last_training_s: f64,
    checks: Vec<String>,
}

fn passes(threshold: usize, c: &HeldOutCheck, controller_best: f64) -> bool {
    match threshold {
        0 => c.mean_return > RETURN_THRESHOLD,
        1 => c.beats_controller(),
        _ => c.mean_return > controller_best,
    }
}

/// The controller a check was compared with, as CSV fields (empty when there was none).
fn controller_fields(c: &HeldOutCheck) -> (String, String, String) {
    match &c.controller {
        Ok(k) => (format!("{:.3}", k.command), k.matched.to_string(), format!("{:.4}", k.mean_return)),
        Err(_) => Default::default(),
    }
}

fn check_row(algo: &str, seed: u64, step: u64, training_s: f64, eval_mean: f64, c: &HeldOutCheck) -> String {
    let (command, matched, controller_return) = controller_fields(c);
    format!(
        "{algo},{seed},{step},{training_s:.1},{eval_mean:.4},{:.4},{:.4},{:.4},{:.4},{},{},{command},{matched},{controller_return},{}",
        c.mean_return,
        c.return_interval.low,
        c.return_interval.high,
        c.speed,
        c.falls,
        c.episodes,
        c.beats_controller()
    )
}

/// Trains one run, checking held-out episodes as it goes.
fn run_one(o: &Options, algo: &str, seed: u64, threads: usize, check: WalkingCheck, best: f64) -> Result<RunState> {
    let env = EnvConfig::new("minitaur");
    let mut overrides = o.set.clone();
    overrides.push(("total_steps".into(), o.steps.to_string()));
    let cfg = build_config(&env.name, Algo::parse(algo)?, &overrides)?;
    Protocol { episodes: o.episodes, seed: 0 }.check_disjoint(seed, cfg.total_steps, cfg.eval_episodes)?;
    let state = Arc::new(Mutex::new(RunState::default()));
    let check = Arc::new(Mutex::new(check));
    let (hook_state, algo_name, cap_s, gate) = (Arc::clone(&state), algo.to_string(), o.minutes * 60.0, o.gate);
    let hook = EvaluationHook(Arc::new(move |ev: &EvaluationEvent<'_>| -> Result<bool> {
        let started = Instant::now();
        let mut s = hook_state.lock().unwrap();
        let training_s = ev.wall_time - s.checking_s;
        (s.last_step, s.last_training_s) = (ev.step, training_s);
        if ev.evaluation.mean() >= gate {
            let mut policy = AgentPolicy { agent: ev.agent, label: algo_name.clone() };
            let c = check.lock().unwrap().check(&mut policy)?;
            s.checks.push(check_row(&algo_name, seed, ev.step, training_s, ev.evaluation.mean(), &c));
            for t in 0..THRESHOLDS.len() {
                if s.hits[t].is_none() && passes(t, &c, best) {
                    s.hits[t] = Some(Hit { step: ev.step, training_s, check: c.clone() });
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

fn result_rows(algo: &str, seed: u64, threads: usize, s: &RunState) -> Vec<String> {
    let mut rows = Vec::new();
    for (t, name) in THRESHOLDS.iter().enumerate() {
        rows.push(match &s.hits[t] {
            Some(h) => {
                let c = &h.check;
                let (command, matched, ret) = controller_fields(c);
                format!(
                    "{algo},{seed},{threads},{name},true,{},{:.1},{:.4},{:.4},{:.4},{:.4},{},{},{command},{matched},{ret}",
                    h.step, h.training_s, c.mean_return, c.return_interval.low, c.return_interval.high, c.speed, c.falls, c.episodes
                )
            }
            None => format!("{algo},{seed},{threads},{name},false,{},{:.1},,,,,,,,,", s.last_step, s.last_training_s),
        });
    }
    rows
}

fn summarize(results: &[(String, u64, RunState)]) {
    println!(
        "\n{:<6} {:<14} {:>8} {:>24} {:>28}",
        "algo", "threshold", "reached", "minutes (min-median-max)", "steps (min-median-max)"
    );
    let mut algos: Vec<&str> = results.iter().map(|r| r.0.as_str()).collect();
    algos.dedup();
    for algo in algos {
        let runs: Vec<&RunState> = results.iter().filter(|r| r.0 == algo).map(|r| &r.2).collect();
        for (t, name) in THRESHOLDS.iter().enumerate() {
            let hits: Vec<&Hit> = runs.iter().filter_map(|s| s.hits[t].as_ref()).collect();
            let spread = |mut v: Vec<f64>, unit: &str| -> String {
                if v.is_empty() {
                    return "-".into();
                }
                v.sort_by(f64::total_cmp);
                format!("{:.1}{unit} - {:.1}{unit} - {:.1}{unit}", v[0], quantile(&v, 0.5), v[v.len() - 1])
            };
            println!(
                "{algo:<6} {name:<14} {:>8} {:>24} {:>28}",
                format!("{}/{}", hits.len(), runs.len()),
                spread(hits.iter().map(|h| h.training_s / 60.0).collect(), ""),
                spread(hits.iter().map(|h| h.step as f64 / 1000.0).collect(), "k")
            );
        }
    }
}

/// Writes `time-to-walk.csv` and `checks.csv` for the runs finished so far (sorted by algorithm
/// as given, then seed).
fn write_results(o: &Options, header: &str, threads: usize, results: &mut [(String, u64, RunState)]) -> Result<()> {
    results.sort_by_key(|r| (o.algos.iter().position(|x| *x == r.0), r.1));
    let mut summary = header.to_string()
        + "algo,seed,threads,threshold,reached,step,training_s,heldout_return,heldout_low,heldout_high,speed,falls,episodes,controller_command,controller_matched,controller_return\n";
    let mut checks = header.to_string()
        + "algo,seed,step,training_s,eval_mean,heldout_return,heldout_low,heldout_high,speed,falls,episodes,controller_command,controller_matched,controller_return,beats_matched\n";
    for (algo, seed, s) in results.iter() {
        for row in result_rows(algo, *seed, threads, s) {
            summary += &(row + "\n");
        }
        for row in &s.checks {
            checks += &(row.clone() + "\n");
        }
    }
    write_bytes_atomic(&o.out.join("time-to-walk.csv"), summary.as_bytes())?;
    write_bytes_atomic(&o.out.join("checks.csv"), checks.as_bytes())
}

fn main() -> Result<()> {
    locobench::runtime::configure_process();
    let o = parse_options()?;
    std::fs::create_dir_all(&o.out)?;
    let env = EnvConfig::new("minitaur");
    let protocol = Protocol { episodes: o.episodes, seed: 0 };
    let started = Instant::now();
    let check = WalkingCheck::new(&env, protocol, 2)?;
    let (best_command, best) = check.controller_best().context("the controller works at no speed")?;
    println!(
        "controller grid: {:.0} s; best {best:.2} at {best_command:.2} m/s commanded, top speed {:.2} m/s",
        started.elapsed().as_secs_f64(),
        check.controller_top_speed().unwrap_or(0.0)
    );
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
                match run_one(&o, &algo, seed, threads, check.clone(), best) {
                    Ok(s) => {
                        let mut results = results.lock().unwrap();
                        results.push((algo, seed, s));
                        // Rewritten after every run, so that a stopped bench keeps what finished.
                        if let Err(e) = write_results(&o, &header, threads, &mut results) {
                            failures.lock().unwrap().push(format!("writing results: {e:#}"));
                        }
                    }
                    Err(e) => failures.lock().unwrap().push(format!("{algo} seed {seed}: {e:#}")),
                }
            });
        }
    });
    let results = results.into_inner().unwrap();
    summarize(&results);
    println!("controller best return {best:.2}; written {}", o.out.join("time-to-walk.csv").display());
    let failures = failures.into_inner().unwrap();
    if !failures.is_empty() {
        bail!("runs failed:\n{}", failures.join("\n"));
    }
    Ok(())
}
