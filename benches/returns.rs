//! `cargo bench --bench returns`: TD3, SAC and DDPG trained on every environment over several
//! seeds, the Raibert baseline on Minitaur and Ant, and the published anchors, as one table per
//! environment (printed, and written as CSV and Markdown).
//!
//! The default budget is small enough for about half an hour on 2 cores: 5,000 steps per run,
//! 2 seeds, 2 runs at a time, with warm-up and learning start shortened to 1,000 steps so that
//! learning happens at all (every other hyperparameter is the published one). The full
//! benchmark is `LOCOBENCH_RETURNS_FULL=1 cargo bench --bench returns`: 1M steps, 5 seeds, the
//! published settings untouched. Other knobs (environment variables):
//!   LOCOBENCH_RETURNS_STEPS, LOCOBENCH_RETURNS_SEEDS, LOCOBENCH_RETURNS_ENVS (comma list),
//!   LOCOBENCH_RETURNS_ALGOS, LOCOBENCH_RETURNS_JOBS, LOCOBENCH_RETURNS_OUT (default
//!   target/bench-returns; the runs stay there for `locobench report`), LOCOBENCH_RETURNS_KEEP=1
//!   (keep the runs already there: finished ones are not trained again, only tabulated).
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use locobench::controller::baseline::{baseline_controller, baseline_env};
use locobench::controller::measure::measure;
use locobench::envs::make;
use locobench::io::write_bytes_atomic;
use locobench::report::anchors::bundled_anchors;
use locobench::report::curves::mean_std;
use locobench::report::runs::find_runs;
use locobench::report::{fmt_return, group_runs, summarise};
use locobench::sweep::{jobs, run_jobs, write_plan, SweepSpec};

fn var<T: std::str::FromStr>(name: &str) -> Option<T> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

fn list(name: &str, default: &str) -> Vec<String> {
    std::env::var(name).unwrap_or_else(|_| default.to_string()).split(',').map(|s| s.trim().to_string()).collect()
}

fn main() -> Result<()> {
    // `cargo test --all-targets` runs this binary without `--bench`: a smoke run of the whole
    // path (jobs, tables, baseline) on a tiny budget instead of half an hour of training.
    let smoke = !std::env::args().any(|a| a == "--bench");
    let full = std::env::var("LOCOBENCH_RETURNS_FULL").is_ok_and(|v| v == "1");
    let steps: u64 =
        if smoke { 300 } else { var("LOCOBENCH_RETURNS_STEPS").unwrap_or(if full { 1_000_000 } else { 5_000 }) };
    let seeds: u64 = if smoke { 2 } else { var("LOCOBENCH_RETURNS_SEEDS").unwrap_or(if full { 5 } else { 2 }) };
    let parallel: usize = var("LOCOBENCH_RETURNS_JOBS").unwrap_or(2);
    let envs = if smoke {
        vec!["inverted-pendulum".to_string()]
    } else {
        list("LOCOBENCH_RETURNS_ENVS", "inverted-pendulum,half-cheetah,ant,humanoid,minitaur")
    };
    let algos = if smoke { vec!["td3".to_string()] } else { list("LOCOBENCH_RETURNS_ALGOS", "td3,sac,ddpg") };
    let default_out = if smoke { "target/bench-returns-smoke" } else { "target/bench-returns" };
    let out = PathBuf::from(std::env::var("LOCOBENCH_RETURNS_OUT").unwrap_or_else(|_| default_out.into()));
    let binary = PathBuf::from(env!("CARGO_BIN_EXE_locobench"));

    // A short budget cannot afford 10k random steps; shorten warm-up only, and say so.
    let mut set = vec![format!("buffer_capacity={}", steps.max(1000)), format!("checkpoint_every={steps}")];
    if smoke {
        set.push("hidden=[16,16],batch_size=32".into());
    }
    if !full {
        let start = (steps / 5).min(1000);
        let eval_every = (steps / 5).max(1);
        set.push(format!("warmup_steps={start},learning_starts={start},eval_every={eval_every},eval_episodes=5"));
    }
    let keep = std::env::var("LOCOBENCH_RETURNS_KEEP").is_ok_and(|v| v == "1");
    if out.exists() && !keep {
        std::fs::remove_dir_all(&out).with_context(|| format!("clearing {}", out.display()))?;
    }
    println!(
        "returns bench: {} envs x {} algorithms x {seeds} seeds, {steps} steps each, {parallel} at a time -> {}",
        envs.len(),
        algos.len(),
        out.display()
    );
    for env in &envs {
        let spec = SweepSpec {
            env: env.clone(),
            algos: algos.clone(),
            grid: vec![],
            seeds: (0..seeds).collect(),
            steps: Some(steps),
            set: set.clone(),
            options: vec![],
        };
        let dir = out.join(env);
        let js = jobs(&spec, &dir)?;
        write_plan(&spec, &dir, &js)?;
        let outcomes = run_jobs(&binary, &js, &dir, parallel, &|o| {
            println!("  {env} {} {} in {:.0} s", o.name, if o.ok { "ok" } else { "FAILED" }, o.seconds)
        })?;
        for o in outcomes.iter().filter(|o| !o.ok) {
            eprintln!("job {} failed; see {}", o.name, o.log.display());
        }
    }

    let anchors = bundled_anchors();
    let mut md = String::new();
    let mut csv = String::from(
        "env,policy,seeds,steps,final_mean,final_std,return_at_25pct,return_at_50pct,return_at_100pct,normalised_auc,wall_time_s,steps_per_s\n",
    );
    let marks = [steps / 4, steps / 2, steps];
    let mut total_wall = 0.0;
    let fmt = |v: Option<f64>| v.map_or("–".to_string(), fmt_return);
    for env in &envs {
        let runs = match find_runs(&[out.join(env)]) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{env}: {e:#}");
                continue;
            }
        };
        let header = format!(
            "| policy | seeds | final eval | @{} | @{} | @{} | norm. AUC | wall min | steps/s | published |",
            marks[0], marks[1], marks[2]
        );
        let _ = writeln!(md, "## {env}\n\n{header}\n|---|---|---|---|---|---|---|---|---|---|");
        println!("\n{env}\n{header}");
        total_wall += runs.iter().map(|r| r.wall_time()).sum::<f64>();
        for (group, rs) in group_runs(&runs) {
            let s = summarise(&group, &rs);
            let wall = s.wall_time;
            let rate = if wall > 0.0 { s.steps as f64 / wall } else { f64::NAN };
            let published: Vec<String> = anchors
                .iter()
                .filter(|a| a.env == *env && a.algo == group.algo)
                .map(|a| {
                    let sd = a.std.map_or(String::new(), |s| format!(" ± {s}"));
                    let source = a.source.split([',', '(']).next().unwrap_or("").trim();
                    format!("{}{sd} @{}k ({source})", a.value, a.steps / 1000)
                })
                .collect();
            let at: Vec<Option<f64>> = marks.iter().map(|&m| s.curve.at(m)).collect();
            let row = format!(
                "| {} | {} | {} ± {} | {} | {} | {} | {} | {:.1} | {:.0} | {} |",
                group.algo,
                s.seeds,
                fmt(Some(s.final_mean)),
                fmt(Some(s.final_std)),
                fmt(at[0]),
                fmt(at[1]),
                fmt(at[2]),
                fmt(Some(s.auc)),
                wall / 60.0,
                rate,
                if published.is_empty() { "–".into() } else { published.join("; ") }
            );
            println!("{row}");
            let _ = writeln!(md, "{row}");
            let _ = writeln!(
                csv,
                "{env},{},{},{},{},{},{},{},{},{},{:.1},{:.1}",
                group.algo,
                s.seeds,
                s.steps,
                s.final_mean,
                s.final_std,
                at[0].unwrap_or(f64::NAN),
                at[1].unwrap_or(f64::NAN),
                at[2].unwrap_or(f64::NAN),
                s.auc,
                wall,
                rate
            );
        }
        if env == "minitaur" || env == "ant" {
            let speed = if env == "minitaur" { 0.35 } else { 0.5 };
            let mut e = make(&baseline_env(env)?)?;
            let mut c = baseline_controller(env, speed, None)?;
            let t = Instant::now();
            let eps = measure(e.as_mut(), c.as_mut(), 5, 0, speed)?;
            let (m, sd) = mean_std(&eps.iter().map(|x| x.episode_return).collect::<Vec<_>>());
            let falls = eps.iter().filter(|x| x.fell).count();
            let v = mean_std(&eps.iter().map(|x| x.mean_speed).collect::<Vec<_>>()).0;
            let row = format!(
                "| raibert @{speed} m/s | 5 episodes | {} ± {} | – | – | – | – | {:.1} | – | mean speed {v:.2} m/s, falls {falls}/5 |",
                fmt_return(m),
                fmt_return(sd),
                t.elapsed().as_secs_f64() / 60.0
            );
            println!("{row}");
            let _ = writeln!(md, "{row}");
            let _ = writeln!(csv, "{env},raibert,5,,{m},{sd},,,,,{:.1},", t.elapsed().as_secs_f64());
        }
        md.push('\n');
    }
    let header = format!(
        "# Returns bench\n\n{steps} steps per run, {seeds} seeds{}, {parallel} runs at a time; the runs' wall times add \
         up to {:.0} min. Evaluation: mean return of the deterministic policy over the evaluation episodes; mean ± std \
         over seeds.\n\n",
        if full { " (published settings)" } else { ", warm-up and learning start shortened to 1,000 steps" },
        total_wall / 60.0
    );
    let md = header + &md;
    write_bytes_atomic(&out.join("returns.md"), md.as_bytes())?;
    write_bytes_atomic(&out.join("returns.csv"), csv.as_bytes())?;
    println!(
        "\nwrote {} and {}; runs under {} (`locobench report --runs {}`)",
        out.join("returns.md").display(),
        out.join("returns.csv").display(),
        out.display(),
        out.display()
    );
    Ok(())
}
