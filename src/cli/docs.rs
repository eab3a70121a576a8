use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;

#[derive(Args, Debug)]
#[command(after_help = "Example:\n  locobench docs --check")]
pub struct DocsArgs {
    /// Only compare: list the generated sections that differ from what the result files give, and
    /// fail if there are any.
    #[arg(long)]
    check: bool,
    /// The repository to work on.
    #[arg(long, default_value = ".")]
    root: PathBuf,
}

pub fn run(args: DocsArgs) -> Result<()> {
    if args.check {
        let stale = super::docgen::stale(&args.root)?;
        if !stale.is_empty() {
            bail!("generated sections out of date (run `locobench docs`): {}", stale.join(", "));
        }
        println!("every generated section is up to date");
        return Ok(());
    }
    let changed = super::docgen::write(&args.root)?;
    if changed.is_empty() {
        println!("every generated section is up to date");
    } else {
        println!("rewrote {}", changed.join(", "));
    }
    Ok(())
}
