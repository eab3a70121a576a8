use std::path::PathBuf;

use anyhow::Result;
use locobench::envs::EnvConfig;
use locobench::evaluation::robustness::{output, select, Contender, ControllerChoice, Suite};
use locobench::evaluation::{EvalCache, Protocol, DEFAULT_EPISODES};

#[derive(clap::Args, Debug)]
pub struct RobustnessArgs {
    /// The env (minitaur: 13 axes; ant: 9); a command task (minitaur-command, ant-command) takes
    /// its base's axes, and `--option schedule="0:1.0:0"` matches every contender's command.
    #[arg(long, default_value = "minitaur")]
    pub env: String,
    /// A trained policy as LABEL=REFERENCE, or LABEL=REFERENCE@BUDGET for a committed result
    /// run; REFERENCE is anything `eval --policy` takes. Repeat for several; policies with the
    /// same label form one row (one per training seed), as the report's rows do.
    #[arg(long = "policy", value_name = "LABEL=REF[@BUDGET]")]
    pub policies: Vec<String>,
    /// Controllers to add: `best` (its best grid speed), `matched` (each policy's speed), or a
    /// commanded speed in m/s. Comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "best,matched")]
    pub controller: Vec<ControllerChoice>,
    /// Axes to run (comma-separated), or `all`.
    #[arg(long, value_delimiter = ',', default_value = "all")]
    pub axes: Vec<String>,
    /// Held-out episodes per cell.
    #[arg(long, default_value_t = DEFAULT_EPISODES)]
    pub episodes: usize,
    /// Protocol seed: picks the held-out reset seeds.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Cells played at once (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Directory for robustness.csv and robustness.toml.
    #[arg(long)]
    pub out: PathBuf,
    /// An earlier suite's directory (same env, episodes and seed): its cells of the same
    /// contender, axis and level are taken instead of played again (adding a policy to a
    /// committed suite).
    #[arg(long, value_name = "DIR")]
    pub reuse: Option<PathBuf>,
    /// Keep each contender's episodes on each cell in this evaluation cache (the one `report
    /// --cache` takes), and read those it already holds: a suite run again, or one sharing cells
    /// with an earlier one, plays only what is new.
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Options over the suite's environment, e.g. `--option schedule="0:1.0:0"` on a command task.
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
}

pub fn run(args: RobustnessArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    let agents = Contender::parse_agents(&args.policies)?;
    let suite = Suite {
        env: args.env_options.apply(EnvConfig::new(&args.env))?,
        axes: select(&args.env, &args.axes)?,
        protocol: Protocol { episodes: args.episodes, seed: args.seed },
        threads: args.threads.unwrap_or_else(locobench::evaluation::parallel::default_threads),
        cache: match &args.cache {
            Some(dir) => EvalCache::open(dir)?,
            None => EvalCache::off(),
        },
    };
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let (reuse, from) = match &args.reuse {
        Some(dir) => {
            let (cells, meta) = output::reusable(dir, &suite, &agents)?;
            (cells, Some((dir.display().to_string(), meta.total_wall())))
        }
        None => (Vec::new(), None),
    };
    let (cells, meta) = output::run_to_dir(&suite, agents, &args.controller, &args.out, &command, &reuse, from)?;
    for note in &meta.notes {
        println!("{note}");
    }
    let controller = cells.iter().find(|c| c.kind == "controller").map(|c| c.policy.clone());
    for line in output::summary_lines(&cells, &suite.axes, controller.as_deref()) {
        println!("{line}");
    }
    if let Some(dir) = suite.cache.dir() {
        let (read, computed, damaged) = suite.cache.counts();
        let damaged = if damaged > 0 { format!(" ({damaged} damaged entries recomputed)") } else { String::new() };
        println!("evaluation cache {}: {read} read, {computed} computed{damaged}", dir.display());
    }
    println!(
        "{} cells x {} episodes in {:.0} s -> {}",
        cells.len(),
        suite.protocol.episodes,
        meta.wall_seconds,
        args.out.join(output::CSV_FILE).display()
    );
    Ok(())
}
