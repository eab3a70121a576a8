use anyhow::Result;
use locobench::controller::baseline::{baseline_controller, baseline_env, parse_gait};
use locobench::controller::measure::{mean_cost_of_transport, measure};
use locobench::envs::make;
use locobench::report::curves::mean_std;

#[derive(clap::Args, Debug)]
pub struct BaselineArgs {
    /// minitaur or ant.
    #[arg(long)]
    pub env: String,
    /// Forward speed set-points (m/s), comma-separated for a sweep: `--speed 0.35,1.0,2.0`.
    #[arg(long, value_delimiter = ',', default_value = "0.35")]
    pub speed: Vec<f64>,
    #[arg(long, default_value_t = 10)]
    pub episodes: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// trot, bound or pace (Minitaur bounds by default; Ant trots).
    #[arg(long)]
    pub gait: Option<String>,
    /// Environment option overrides, e.g. `--option drift_weight=1`.
    #[arg(long = "option", value_name = "KEY=VALUE,...")]
    pub options: Vec<String>,
    /// Also print every episode.
    #[arg(long)]
    pub verbose: bool,
}

pub fn run(args: BaselineArgs) -> Result<()> {
    let gait = args.gait.as_deref().map(parse_gait).transpose()?;
    let cfg = super::apply_options(baseline_env(&args.env)?, &args.options)?;
    let mut env = make(&cfg)?;
    println!(
        "{:>6} {:>17} {:>8} {:>9} {:>9} {:>7} {:>8} {:>8} {:>6} {:>7} {:>8}",
        "speed", "return", "v mean", "v error", "energy J", "CoT", "drift m", "shake m", "falls", "length", "QP fails"
    );
    for &speed in &args.speed {
        let mut controller = baseline_controller(&args.env, speed, gait)?;
        let eps = measure(env.as_mut(), controller.as_mut(), args.episodes, args.seed, speed)?;
        let col = |f: fn(&locobench::controller::measure::GaitEpisode) -> f64| {
            mean_std(&eps.iter().map(f).collect::<Vec<_>>())
        };
        let (ret, ret_std) = col(|e| e.episode_return);
        let cot = mean_cost_of_transport(&eps);
        println!(
            "{:>6.2} {:>9.2} ± {:>5.2} {:>8.3} {:>9.3} {:>9.1} {:>7.2} {:>8.3} {:>8.3} {:>3}/{:<2} {:>7.1} {:>8}",
            speed,
            ret,
            ret_std,
            col(|e| e.mean_speed).0,
            col(|e| e.speed_error).0,
            col(|e| e.energy).0,
            cot,
            col(|e| e.drift).0,
            col(|e| e.shake).0,
            eps.iter().filter(|e| e.fell).count(),
            eps.len(),
            col(|e| e.length as f64).0,
            eps.iter().map(|e| e.qp_failures).sum::<f64>(),
        );
        if args.verbose {
            for (i, e) in eps.iter().enumerate() {
                println!("    episode {i}: {e:?}");
            }
        }
    }
    Ok(())
}
