//! `locobench track`: how closely the controller or a trained policy follows a velocity command,
//! over a grid of commands on a command task (`evaluation::tracking`).
use std::path::PathBuf;

use anyhow::{bail, Result};
use locobench::controller::baseline::{baseline_controller_for, baseline_env};
use locobench::controller::command::Command;
use locobench::envs::EnvConfig;
use locobench::evaluation::stats::Interval;
use locobench::evaluation::tracking::{tracking_grid, TrackingPoint, SETTLE_WINDOW};
use locobench::evaluation::Protocol;
use locobench::io::write_bytes_atomic;
use locobench::policy::AgentPolicy;
use locobench::train::resolve_policy;

#[derive(clap::Args, Debug)]
pub struct TrackArgs {
    /// A trained policy (run directory, checkpoint, budget policy or exported policy) trained on a
    /// command task; without it, the Raibert/QP controller on `--env`.
    #[arg(long, value_name = "RUN_DIR|CHECKPOINT|POLICY")]
    pub policy: Option<PathBuf>,
    /// With --policy: the actor the run saved at this step budget.
    #[arg(long)]
    pub budget: Option<u64>,
    /// The command task the controller runs on (minitaur-command); a policy runs on its own.
    #[arg(long)]
    pub env: Option<String>,
    /// Commanded forward speeds (m/s).
    #[arg(long, value_delimiter = ',', default_value = "0.25,0.5,1.0,1.5,2.0,2.5")]
    pub speeds: Vec<f64>,
    /// Commanded yaw rates (rad/s, positive turns left).
    #[arg(long, value_delimiter = ',', default_value = "0", allow_negative_numbers = true)]
    pub yaw_rates: Vec<f64>,
    /// Held-out episodes per grid point.
    #[arg(long, default_value_t = 10)]
    pub episodes: usize,
    /// Protocol seed: picks the held-out reset seeds.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also write the grid as CSV here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Options over the environment (e.g. `--option friction_scale=0.5`).
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
}

pub fn run(args: TrackArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    let protocol = Protocol { episodes: args.episodes, seed: args.seed };
    let (points, who) = match &args.policy {
        Some(path) => {
            let (run, agent) = resolve_policy(path, args.budget)?.load()?;
            if !locobench::envs::command::is_command_task(&run.env.name) {
                bail!(
                    "{} was trained on {}, not on a command task: it has no command to follow",
                    path.display(),
                    run.env.name
                );
            }
            warn_outside_training_range(&run.env, &args.speeds, &args.yaw_rates, &path.display().to_string())?;
            protocol.check_run(run.seed, &run.train)?;
            let env = args.env_options.apply(run.env.for_evaluation())?;
            let mut policy = AgentPolicy { agent: agent.as_ref(), label: run.train.algo.name().into() };
            (
                tracking_grid(&env, &mut policy, &args.speeds, &args.yaw_rates, protocol)?,
                format!("{} {}", path.display(), run.train.algo.name()),
            )
        }
        None => {
            let name = args.env.clone().unwrap_or_else(|| "minitaur-command".into());
            let env = args.env_options.apply(baseline_env(&name)?)?;
            let mut controller = baseline_controller_for(&name, Command::straight(0.0, 0.0), None)?;
            let who = controller.name();
            (tracking_grid(&env, controller.as_mut(), &args.speeds, &args.yaw_rates, protocol)?, who)
        }
    };
    println!(
        "{who}: {} held-out episodes per command (protocol seed {}), errors after the first {SETTLE_WINDOW} s, 95% intervals",
        args.episodes, args.seed
    );
    println!(
        "{:>7} {:>6} {:>24} {:>24} {:>8} {:>18} {:>20} {:>20}",
        "speed", "yaw", "speed RMS m/s", "yaw RMS rad/s", "speed", "falls", "CoT", "settle s"
    );
    for p in &points {
        let (settle, settled) = p.settle_time();
        let falls = p.fall_rate();
        println!(
            "{:>7.2} {:>6.2} {:>24} {:>24} {:>8.3} {:>18} {:>20} {:>20}",
            p.speed,
            p.yaw_rate,
            interval(p.speed_rms()),
            interval(p.yaw_rate_rms()),
            p.achieved_speed().estimate,
            format!("{}/{} [{:.2}, {:.2}]", p.falls(), p.episodes.len(), falls.low, falls.high),
            interval(p.cost_of_transport()),
            format!("{} ({settled})", interval(settle)),
        );
    }
    if let Some(out) = &args.out {
        write_bytes_atomic(out, csv(&who, &points).as_bytes())?;
        println!("wrote {}", out.display());
    }
    Ok(())
}

/// A measure with its interval, as `eval` prints them; `-` where no episode gave one.
fn interval(i: Interval) -> String {
    if i.estimate.is_nan() {
        return "-".into();
    }
    locobench::evaluation::stats::interval(i, |v| format!("{v:.3}"))
}

/// As `eval` does: a command outside the range a policy was trained on is a warning naming it.
fn warn_outside_training_range(env: &EnvConfig, speeds: &[f64], yaw_rates: &[f64], policy: &str) -> Result<()> {
    let asked: Vec<[f64; 2]> = speeds.iter().flat_map(|&v| yaw_rates.iter().map(move |&w| [v, w])).collect();
    for line in locobench::envs::command::outside_training_range(env, &asked, policy)? {
        eprintln!("warning: {line}");
    }
    Ok(())
}

fn csv(who: &str, points: &[TrackingPoint]) -> String {
    let mut out = String::from("contender,speed,yaw_rate,episodes,speed_rms,speed_rms_low,speed_rms_high,yaw_rate_rms,yaw_rate_rms_low,yaw_rate_rms_high,achieved_speed,falls,fall_rate_low,fall_rate_high,cost_of_transport,cost_of_transport_low,cost_of_transport_high,settle_time,settle_time_low,settle_time_high,settled\n");
    for p in points {
        let (s, r, v, c) = (p.speed_rms(), p.yaw_rate_rms(), p.achieved_speed(), p.cost_of_transport());
        let (t, settled) = p.settle_time();
        let f = p.fall_rate();
        out += &format!(
            "{who},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            p.speed,
            p.yaw_rate,
            p.episodes.len(),
            s.estimate,
            s.low,
            s.high,
            r.estimate,
            r.low,
            r.high,
            v.estimate,
            p.falls(),
            f.low,
            f.high,
            c.estimate,
            c.low,
            c.high,
            t.estimate,
            t.low,
            t.high,
            settled
        );
    }
    out
}
