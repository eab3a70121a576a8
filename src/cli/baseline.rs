use anyhow::Result;
use locobench::controller::baseline::{baseline_controller_for, baseline_env, parse_gait, RAMP_TIME};
use locobench::controller::command::{Command, SpeedProfile};
use locobench::controller::measure::{summary_cells, SUMMARY_COLUMNS};
use locobench::envs::make;
use locobench::evaluation::Protocol;

#[derive(clap::Args, Debug)]
pub struct BaselineArgs {
    /// minitaur or ant.
    #[arg(long)]
    pub env: String,
    /// The controller's commanded forward speeds (m/s), comma-separated for a sweep:
    /// `--speed 0.35,1.0,2.0`; each is reached over the first second.
    #[arg(long, value_delimiter = ',', default_value = "0.35")]
    pub speed: Vec<f64>,
    #[command(flatten)]
    pub command: CommandArgs,
    /// Held-out episodes per command (the evaluation protocol's, as `eval` and `report` play).
    #[arg(long, default_value_t = locobench::evaluation::DEFAULT_EPISODES)]
    pub episodes: usize,
    /// Protocol seed: picks the held-out reset seeds, the same ones `eval` and `report` use.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// trot, bound or pace for Minitaur (bound by default); row (default) or trot for Ant.
    #[arg(long)]
    pub gait: Option<String>,
    /// Options over the baseline's environment (Minitaur in torque mode), e.g. `--reward drift=1`.
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
    /// Also print every episode.
    #[arg(long)]
    pub verbose: bool,
    /// Also print where the controller met the robot's limits (episode means): motor commands
    /// clipped at the torque limit (stance and swing legs), stance forces on the friction cone, stance feet slipping,
    /// swing targets out of the leg's reach, distance from the foothold at touchdown.
    #[arg(long)]
    pub limits: bool,
}

/// What the Raibert controller is asked to do besides a constant speed (shared by `baseline`
/// and `record`).
#[derive(clap::Args, Debug, Clone)]
pub struct CommandArgs {
    /// A forward-speed profile instead of a constant speed: time:speed knots (s, m/s), linear
    /// in between, e.g. PyBullet's example `0:0,3:0.35,6:-0.35` (up over 3 s, then reverse).
    #[arg(long, conflicts_with = "speed")]
    pub profile: Option<String>,
    /// Yaw-rate command (rad/s, positive turns left).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub yaw_rate: f64,
}

impl CommandArgs {
    /// The commands to run: the profile if one is given, else one straight ramp per speed.
    pub fn commands(&self, speeds: &[f64]) -> Result<Vec<Command>> {
        anyhow::ensure!(speeds.iter().all(|s| s.is_finite()), "speeds must be finite");
        Ok(match &self.profile {
            Some(p) => vec![Command { speed: SpeedProfile::parse(p)?, yaw_rate: self.yaw_rate }],
            None => speeds
                .iter()
                .map(|&v| Command { speed: SpeedProfile::ramp(v, RAMP_TIME), yaw_rate: self.yaw_rate })
                .collect(),
        })
    }
}

pub fn run(args: BaselineArgs) -> Result<()> {
    let gait = args.gait.as_deref().map(parse_gait).transpose()?;
    let cfg = args.env_options.apply(baseline_env(&args.env)?)?;
    let mut env = make(&cfg)?;
    let widths = [17, 9, 15, 14, 7, 9, 7, 8, 8, 6, 6];
    let line = |first: String, cells: &[String], last: String| {
        let middle: Vec<String> = cells.iter().zip(widths).map(|(c, w)| format!("{c:>w$}")).collect();
        println!("{first:>6} {} {last:>8}", middle.join(" "));
    };
    let header: Vec<String> = SUMMARY_COLUMNS.iter().map(|c| c.to_string()).collect();
    line("speed".into(), &header, "QP fails".into());
    if let Some(p) = &args.command.profile {
        println!("speed profile {p} (the speed column shows where it ends)");
    }
    for command in args.command.commands(&args.speed)? {
        let speed = command.speed.final_speed();
        let profile = command.speed.clone();
        let mut controller = baseline_controller_for(&args.env, command, gait)?;
        let protocol = Protocol { episodes: args.episodes, seed: args.seed };
        let eps = protocol.run(env.as_mut(), controller.as_mut(), Some(&profile), None)?;
        let qp_failures = eps.iter().map(|e| e.qp_failures).sum::<f64>();
        line(format!("{speed:.2}"), &summary_cells(&eps, |v| format!("{v:.2}")), qp_failures.to_string());
        if args.limits {
            let names: Vec<&str> =
                eps.first().map(|e| e.diagnostics.iter().map(|(n, _)| *n).collect()).unwrap_or_default();
            let line: Vec<String> = names
                .iter()
                .enumerate()
                .map(|(k, n)| {
                    format!("{n} {:.3}", eps.iter().map(|e| e.diagnostics[k].1).sum::<f64>() / eps.len() as f64)
                })
                .collect();
            println!("       limits: {}", line.join(", "));
        }
        if args.verbose {
            for (i, e) in eps.iter().enumerate() {
                println!("    episode {i}: {e:?}");
            }
        }
    }
    Ok(())
}
