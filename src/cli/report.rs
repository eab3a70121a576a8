use std::path::PathBuf;

use anyhow::Result;
use locobench::report::{fmt_return, write_report, ReportOptions};

#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// Run directories, or directories holding them (e.g. a sweep).
    #[arg(long, num_args = 1.., required = true)]
    pub runs: Vec<PathBuf>,
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
    /// Episodes per policy, seed and reward in the baseline-vs-RL comparison (0 skips it).
    #[arg(long, default_value_t = 5)]
    pub episodes: usize,
    #[command(flatten)]
    pub seed: super::SeedArg,
    /// Baseline speed set-point on Minitaur (m/s).
    #[arg(long, default_value_t = 0.35)]
    pub minitaur_speed: f64,
    /// Baseline speed set-point on Ant (m/s).
    #[arg(long, default_value_t = 0.5)]
    pub ant_speed: f64,
}

pub fn run(args: ReportArgs) -> Result<()> {
    let mut opts = ReportOptions { compare_episodes: args.episodes, seed: args.seed.seed, ..Default::default() };
    opts.baseline_speed.insert("minitaur".into(), args.minitaur_speed);
    opts.baseline_speed.insert("ant".into(), args.ant_speed);
    let report = write_report(&args.runs, &args.out, &opts)?;
    for g in &report.groups {
        println!(
            "{:<18} {:<28} seeds {:>2}  final eval {:>9} ± {:<7} AUC {:>9}",
            g.group.env,
            g.group.label(),
            g.seeds,
            fmt_return(g.final_mean),
            fmt_return(g.final_std),
            fmt_return(g.auc)
        );
    }
    for (env, rows) in &report.comparisons {
        println!("{env}: baseline vs RL over {} rows (see the report)", rows.len());
    }
    println!("wrote {} and {}", report.index.display(), report.readme.display());
    Ok(())
}
