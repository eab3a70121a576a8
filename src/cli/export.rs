use std::path::PathBuf;

use anyhow::Result;

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// A trained policy: a run directory (its newest checkpoint, or for a committed result run
    /// its newest budget policy), a checkpoint directory, a budget policy file or an exported
    /// policy. `--checkpoint` is the old spelling.
    #[arg(long, alias = "checkpoint", value_name = "RUN_DIR|CHECKPOINT|POLICY")]
    pub policy: PathBuf,
    /// With a run directory: export the actor the run saved at this step budget.
    #[arg(long)]
    pub budget: Option<u64>,
    /// Where to write policy.safetensors (the actor only), config.toml and metrics.csv.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: ExportArgs) -> Result<()> {
    super::deprecated_flag("--checkpoint", "--policy");
    let file = locobench::train::export_policy(&args.policy, args.budget, &args.out)?;
    let size = std::fs::metadata(&file)?.len();
    println!(
        "wrote {} ({:.0} KB); eval, record and report take {} like a run directory",
        file.display(),
        size as f64 / 1024.0,
        args.out.display()
    );
    Ok(())
}
