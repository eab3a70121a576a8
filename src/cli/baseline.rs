use anyhow::Result;
use locobench::controller::baseline::{baseline_controller_for, baseline_env, parse_gait, RAMP_TIME};
use locobench::controller::command::{Command, SpeedProfile};
use locobench::controller::measure::{mean_cost_of_transport, measure};
use locobench::envs::make;
use locobench::report::curves::mean_std;

#[derive(clap::Args, Debug)]
pub struct BaselineArgs {
    /// minitaur or ant.
    #[arg(long)]
    pub env: String,
    /// Forward speed set-points (m/s), comma-separated for a sweep: `--speed 0.35,1.0,2.0`;
    /// each is reached over the first second.
    #[arg(long, value_delimiter = ',', default_value = "0.35")]
    pub speed: Vec<f64>,
    #[command(flatten)]
    pub command: CommandArgs,
    #[arg(long, default_value_t = 10)]
    pub episodes: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// trot, bound or pace (Minitaur bounds by default; Ant trots).
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
    println!(
        "{:>6} {:>17} {:>8} {:>9} {:>8} {:>8} {:>9} {:>7} {:>8} {:>8} {:>6} {:>7} {:>8}",
        "speed",
        "return",
        "v mean",
        "v error",
        "yaw r/s",
        "side m",
        "energy J",
        "CoT",
        "drift m",
        "shake m",
        "falls",
        "length",
        "QP fails"
    );
    if let Some(p) = &args.command.profile {
        println!("speed profile {p} (the speed column shows where it ends)");
    }
    for command in args.command.commands(&args.speed)? {
        let speed = command.speed.final_speed();
        let profile = command.speed.clone();
        let mut controller = baseline_controller_for(&args.env, command, gait)?;
        let eps = measure(env.as_mut(), controller.as_mut(), args.episodes, args.seed, &profile)?;
        let col = |f: fn(&locobench::controller::measure::GaitEpisode) -> f64| {
            mean_std(&eps.iter().map(f).collect::<Vec<_>>())
        };
        let (ret, ret_std) = col(|e| e.episode_return);
        let cot = mean_cost_of_transport(&eps);
        println!(
            "{:>6.2} {:>9.2} ± {:>5.2} {:>8.3} {:>9.3} {:>8.3} {:>8.3} {:>9.1} {:>7.2} {:>8.3} {:>8.3} {:>3}/{:<2} {:>7.1} {:>8}",
            speed,
            ret,
            ret_std,
            col(|e| e.mean_speed).0,
            col(|e| e.speed_error).0,
            col(|e| e.yaw_rate).0,
            col(|e| e.sideways).0,
            col(|e| e.energy).0,
            cot,
            col(|e| e.drift).0,
            col(|e| e.shake).0,
            eps.iter().filter(|e| e.fell).count(),
            eps.len(),
            col(|e| e.length as f64).0,
            eps.iter().map(|e| e.qp_failures).sum::<f64>(),
        );
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
