use std::path::PathBuf;

use anyhow::Result;
use locobench::agents::config::EvalStarts;
use locobench::envs::make;
use locobench::evaluation::summary::HeldOutSummary;
use locobench::evaluation::Protocol;
use locobench::policy::AgentPolicy;
use locobench::train::seeds::evaluation_seed;
use locobench::train::{evaluate::evaluate_with, resolve_policy};

#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// A trained policy: a run directory (its newest checkpoint, or for a committed result run
    /// its newest budget policy), a checkpoint directory, a budget policy file
    /// (`RUN/policies/step-N.safetensors`) or an exported policy. `--checkpoint` is the old
    /// spelling.
    #[arg(long, alias = "checkpoint", value_name = "RUN_DIR|CHECKPOINT|POLICY")]
    pub policy: PathBuf,
    /// Evaluate the actor the run saved at this step budget (`policies/step-N.safetensors`).
    #[arg(long)]
    pub budget: Option<u64>,
    /// Held-out episodes (the report's protocol).
    #[arg(long, default_value_t = locobench::evaluation::DEFAULT_EPISODES)]
    pub episodes: usize,
    /// Protocol seed: picks the held-out reset seeds, the same ones `locobench report` uses.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Play the run's own in-training evaluation episodes instead of held-out ones (what
    /// metrics.csv's eval rows were measured on).
    #[arg(long)]
    pub training_seeds: bool,
    /// With `--training-seeds`, for a run whose evaluations each drew fresh starts
    /// (`eval_starts = "fresh"`): play the starts of its evaluation at this step (an eval row's
    /// step in metrics.csv).
    #[arg(long, requires = "training_seeds", value_name = "STEP")]
    pub eval_step: Option<u64>,
    /// Where the policy's networks run: cpu (the exact fused path), or cuda / cuda:N (the
    /// device-generic path; actions agree with the CPU's to about 1e-6, so long episodes may
    /// drift apart). Needs a build with the `cuda` feature (docs/gpu.md).
    #[arg(long, default_value = "cpu", value_name = "cpu|cuda[:N]")]
    pub device: locobench::device::ComputeDevice,
    /// Options over the run's own environment (perturbations it trained under return to
    /// nominal), e.g. `--reward drift=1,shake=1,energy=0.005` to evaluate under other reward
    /// weights, `--option payload_mass=2` under a payload.
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
}

pub fn run(args: EvalArgs) -> Result<()> {
    super::deprecated_flag("--checkpoint", "--policy");
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    let (run, agent) = resolve_policy(&args.policy, args.budget)?.load_on(args.device)?;
    let env_cfg = args.env_options.apply(run.env.for_evaluation())?;
    for line in locobench::envs::command::command_warnings(&run.env, &env_cfg, &args.policy.display().to_string())? {
        eprintln!("warning: {line}");
    }
    let mut env = make(&env_cfg)?;
    let what = format!("{} {} on {}", args.policy.display(), run.train.algo.name(), run.env.name);
    if args.training_seeds {
        let starts = run.train.eval_starts;
        let step = match (starts, args.eval_step) {
            (EvalStarts::Fixed, None) => 0,
            (EvalStarts::Fixed, Some(_)) => anyhow::bail!(
                "--eval-step: every evaluation of {} replayed the same starts (eval_starts = \"fixed\"); leave it out",
                args.policy.display()
            ),
            (EvalStarts::Fresh, None) => anyhow::bail!(
                "{} drew fresh starts at each evaluation (eval_starts = \"fresh\"): name the evaluation with --eval-step \
                 STEP (an eval row's step in its metrics.csv)",
                args.policy.display()
            ),
            (EvalStarts::Fresh, Some(0)) => anyhow::bail!("--eval-step must be a step of an evaluation, at least 1"),
            (EvalStarts::Fresh, Some(step)) => step,
        };
        let seeds = |i: u64| evaluation_seed(starts, run.seed, step, i);
        let e = evaluate_with(agent.as_ref(), env.as_mut(), args.episodes, seeds)?;
        println!(
            "{what}, the run's evaluation episodes: return {:.3} ± {:.3} (population std) over {} episodes (mean length {:.1})",
            e.mean(),
            e.std(),
            e.returns.len(),
            e.lengths.iter().sum::<usize>() as f64 / e.lengths.len() as f64
        );
        for (term, v) in &e.term_means {
            println!("  {term:<14} {v:>12.3}");
        }
        println!("  {:<14} {:>12.3}  (share of action components at |a| >= 0.99)", "saturated", e.saturation);
        return Ok(());
    }
    let protocol = Protocol { episodes: args.episodes, seed: args.seed };
    protocol.check_run(run.seed, &run.train)?;
    let mut policy = AgentPolicy { agent: agent.as_ref(), label: run.train.algo.name().into() };
    let eps = protocol.run(env.as_mut(), &mut policy, None, None)?;
    println!("{what}: {} held-out episodes (protocol seed {})", eps.len(), args.seed);
    for line in HeldOutSummary::of(&eps).lines() {
        println!("{line}");
    }
    Ok(())
}
