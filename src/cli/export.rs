use std::path::PathBuf;

use anyhow::Result;

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// A trained policy: a run directory (its newest checkpoint) or a checkpoint directory.
    /// `--checkpoint` is the old spelling.
    #[arg(long, alias = "checkpoint", value_name = "RUN_DIR|CHECKPOINT")]
    pub policy: PathBuf,
    /// Where to write policy.safetensors (the actor only), config.toml and metrics.csv.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: ExportArgs) -> Result<()> {
    super::deprecated_flag("--checkpoint", "--policy");
    let file = locobench::train::export_policy(&args.policy, &args.out)?;
    let size = std::fs::metadata(&file)?.len();
    println!(
        "wrote {} ({:.0} KB); eval, record and report take {} like a run directory",
        file.display(),
        size as f64 / 1024.0,
        args.out.display()
    );
    Ok(())
}
