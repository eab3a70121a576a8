use std::path::PathBuf;

use anyhow::Result;

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// A checkpoint directory, or a run directory (its newest checkpoint).
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// Where to write policy.safetensors (the actor only), config.toml and metrics.csv.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: ExportArgs) -> Result<()> {
    let file = locobench::train::export_policy(&args.checkpoint, &args.out)?;
    let size = std::fs::metadata(&file)?.len();
    println!(
        "wrote {} ({:.0} KB); eval, record and report take {} like a run directory",
        file.display(),
        size as f64 / 1024.0,
        args.out.display()
    );
    Ok(())
}
