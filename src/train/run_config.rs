//! `config.toml` of a run directory: what was trained, on what, with which settings, in a
//! versioned format that older run directories keep loading under.
//!
//! Format history:
//! - 1 (no `format` key): every run written up to 2026-11-23.
//! - 2: adds `format`. Hyperparameters added later (`reward_scale`, `normalize_observations`,
//!   ...) take their algorithm's default when a file does not name them, so a new field never
//!   makes an old run unreadable; an unknown key is still an error naming it.
//! - 3: each algorithm's own settings move to its section (`[train.td3]`, `[train.ddpg]`,
//!   `[train.sac]`); formats 1 and 2 listed every algorithm's settings flat in `[train]`, and
//!   reading them ignores the settings of the algorithms the run did not use.
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::agents::{OtherAlgorithmKeys, TrainConfig};
use crate::envs::EnvConfig;

/// The format this version writes.
pub(crate) const FORMAT: u32 = 3;

/// A run's `config.toml`: everything needed to rebuild it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunConfig {
    /// Version of the run directory format.
    pub format: u32,
    /// The run's seed.
    pub seed: u64,
    /// The crate version that started the run.
    pub crate_version: String,
    /// The commit that started the run, when known.
    pub git_commit: Option<String>,
    /// Checkpoint the weights were initialised from (fine-tuning), if any.
    pub init_from: Option<String>,
    /// The environment and its options.
    pub env: EnvConfig,
    /// Every training hyperparameter.
    pub train: TrainConfig,
}

/// The file as written, before the `[train]` table gets its defaults.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StoredRunConfig {
    #[serde(default = "first_format")]
    format: u32,
    seed: u64,
    #[serde(default)]
    crate_version: String,
    #[serde(default)]
    git_commit: Option<String>,
    #[serde(default)]
    init_from: Option<String>,
    env: EnvConfig,
    train: toml::Table,
}

fn first_format() -> u32 {
    1
}

impl RunConfig {
    /// Parses a run's `config.toml` text; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<RunConfig> {
        let stored: StoredRunConfig = toml::from_str(text).map_err(|e| {
            anyhow::anyhow!("{}: not a valid run configuration: {}", path.display(), e.to_string().trim())
        })?;
        if stored.format > FORMAT {
            bail!(
                "{} has format {}, newer than this locobench reads ({FORMAT}): update locobench",
                path.display(),
                stored.format
            );
        }
        let others = if stored.format < 3 { OtherAlgorithmKeys::Ignore } else { OtherAlgorithmKeys::Refuse };
        let train = TrainConfig::from_table(&stored.train, others)
            .with_context(|| format!("{}: in the [train] table", path.display()))?;
        Ok(RunConfig {
            format: FORMAT,
            seed: stored.seed,
            crate_version: stored.crate_version,
            git_commit: stored.git_commit,
            init_from: stored.init_from,
            env: stored.env,
            train,
        })
    }

    pub(crate) fn to_toml(&self) -> Result<String> {
        Ok(toml::to_string(self)?)
    }
}

/// Reads `run_dir/config.toml`.
pub fn read_run_config(run_dir: &Path) -> Result<RunConfig> {
    let path = run_dir.join("config.toml");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("{} is not a run directory (no config.toml)", run_dir.display()))?;
    RunConfig::parse(&text, &path)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORMAT_1: &str = r#"
seed = 3
crate_version = "0.1.0"

[env]
name = "half-cheetah"

[train]
algo = "sac"
total_steps = 1000
"#;

    #[test]
    fn a_format_1_file_without_newer_fields_loads_with_the_algorithms_defaults() {
        let run = RunConfig::parse(FORMAT_1, Path::new("config.toml")).unwrap();
        let defaults = TrainConfig::defaults(crate::agents::Algo::Sac);
        assert_eq!(run.train, TrainConfig { total_steps: 1000, ..defaults });
        assert_eq!(run.format, FORMAT);
        // Written back, it is the current format and reads the same.
        let text = run.to_toml().unwrap();
        let again = RunConfig::parse(&text, Path::new("x")).unwrap();
        assert_eq!(again, run);
        assert!(text.starts_with("format = 3") && text.contains("[train.sac]"), "{text}");
        assert!(!text.contains("policy_delay"), "no other algorithm's settings: {text}");
    }

    #[test]
    fn a_format_2_file_lists_every_algorithm_flat_and_loads_its_own() {
        let flat = FORMAT_1.replace("total_steps = 1000", "total_steps = 1000\nalpha_lr = 0.001\npolicy_delay = 2");
        let run = RunConfig::parse(&format!("format = 2\n{flat}"), Path::new("c")).unwrap();
        assert_eq!(run.train.sac().alpha_lr, 0.001);
        // TD3's policy_delay there is not the one SAC took later.
        assert_eq!(run.train.sac().policy_delay, 1);
        // In the current format another algorithm's key is an error.
        let crossq = flat.replace("policy_delay = 2", "batch_norm_momentum = 0.9");
        let err = format!("{:#}", RunConfig::parse(&format!("format = 3\n{crossq}"), Path::new("c")).unwrap_err());
        assert!(err.contains("batch_norm_momentum") && err.contains("crossq"), "{err}");
        // In the current format SAC's own policy_delay is read.
        let run = RunConfig::parse(&format!("format = 3\n{flat}"), Path::new("c")).unwrap();
        assert_eq!(run.train.sac().policy_delay, 2);
    }

    #[test]
    fn errors_name_the_file_and_the_key() {
        let p = Path::new("/runs/a/config.toml");
        let err = format!("{:#}", RunConfig::parse("garbage }{", p).unwrap_err());
        assert!(err.contains("/runs/a/config.toml") && err.contains("not a valid run configuration"), "{err}");

        let unknown = FORMAT_1.replace("total_steps = 1000", "total_steps = 1000\nlearning_rate = 0.1");
        let err = format!("{:#}", RunConfig::parse(&unknown, p).unwrap_err());
        assert!(err.contains("/runs/a/config.toml") && err.contains("learning_rate"), "{err}");

        let top = format!("colour = \"red\"\n{FORMAT_1}");
        let err = format!("{:#}", RunConfig::parse(&top, p).unwrap_err());
        assert!(err.contains("colour"), "{err}");

        let newer = format!("format = 99\n{FORMAT_1}");
        let err = format!("{:#}", RunConfig::parse(&newer, p).unwrap_err());
        assert!(err.contains("newer"), "{err}");

        let no_algo = FORMAT_1.replace("algo = \"sac\"", "");
        assert!(RunConfig::parse(&no_algo, p).is_err());
    }
}
