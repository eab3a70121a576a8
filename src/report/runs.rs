//! Finding and reading training run directories (`config.toml` + `metrics.csv`).
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::envs::EnvConfig;
use crate::train::metrics::{self, MetricsRow};
use crate::train::{read_run_config, RunConfig};

/// Option keys that shape the reward: the terms' weights (what a reward sweep varies),
/// Minitaur's cap on the speed the distance term pays for, and a command task's kernel width and
/// air-time target.
pub(crate) fn is_reward_option(key: &str) -> bool {
    key.ends_with("_weight")
        || matches!(key, "healthy_reward" | "max_rewarded_speed" | "tracking_sigma" | "feet_air_time_target")
}

/// `Run::reward_label` of a run with the env's default reward weights.
const DEFAULT_REWARD: &str = "default reward";

/// A run directory, loaded: its configuration and metrics.
#[derive(Debug, Clone)]
pub struct Run {
    /// The run directory.
    pub dir: PathBuf,
    /// Its `config.toml`.
    pub config: RunConfig,
    /// Its `metrics.csv` rows (empty when absent).
    pub metrics: Vec<MetricsRow>,
    /// Where an imported policy came from (`source.toml`'s `library`, e.g. a Stable-Baselines3
    /// model converted by `locobench.import_sb3`); None for locobench's own runs.
    pub imported: Option<Imported>,
}

/// An exported policy trained elsewhere, as its `source.toml` describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    /// The library and its version.
    pub library: String,
    /// The model file it was converted from, where stated.
    pub model_file: String,
    /// That file's SHA-256, where stated.
    pub model_sha256: String,
}

impl Imported {
    /// The `source.toml` of `dir`, when it names a library the policy was trained with.
    fn read(dir: &Path) -> Result<Option<Imported>> {
        let path = dir.join("source.toml");
        let Ok(text) = std::fs::read_to_string(&path) else { return Ok(None) };
        let table: toml::Table = text.parse().with_context(|| format!("reading {}", path.display()))?;
        let text_of = |k: &str| table.get(k).and_then(|v| v.as_str()).unwrap_or_default().to_string();
        let library = text_of("library");
        if library.is_empty() {
            return Ok(None);
        }
        Ok(Some(Imported { library, model_file: text_of("model_file"), model_sha256: text_of("model_sha256") }))
    }
}

impl Run {
    /// Reads `config.toml` and `metrics.csv` from `dir`.
    pub fn load(dir: &Path) -> Result<Run> {
        let config = read_run_config(dir)?;
        // An env this build does not know (a policy imported for another version, a typo) is an
        // error naming the run before the report writes anything.
        config.env.resolved_options().with_context(|| format!("{}: its env in config.toml", dir.display()))?;
        let path = dir.join("metrics.csv");
        let metrics = if path.exists() {
            metrics::read(&path).with_context(|| format!("reading {}", path.display()))?
        } else {
            Vec::new()
        };
        let imported = Imported::read(dir)?;
        Ok(Run { dir: dir.to_path_buf(), config, metrics, imported })
    }

    /// The env's registered name.
    pub fn env(&self) -> &str {
        &self.config.env.name
    }

    /// The algorithm's registered name.
    pub fn algo(&self) -> &'static str {
        self.config.train.algo.name()
    }

    /// The algorithm a reader compares the run as: its registered name, except that CrossQ in
    /// `td3_mode` (TD3's actor on CrossQ's critics) is `crossq-td3`, apart from CrossQ's own actor.
    pub fn family(&self) -> &'static str {
        match &self.config.train.crossq {
            Some(c) if c.td3_mode => "crossq-td3",
            _ => self.algo(),
        }
    }

    /// Reward options that differ from the environment's defaults, e.g. `drift=0.25` or
    /// `max_rewarded_speed=1.6`, or `DEFAULT_REWARD`.
    pub(crate) fn reward_label(&self) -> String {
        let defaults = EnvConfig::new(self.env()).resolved_options().unwrap_or_default();
        let mut changed: Vec<String> = self
            .config
            .env
            .options
            .iter()
            .filter(|(k, v)| is_reward_option(k) && defaults.get(*k) != Some(*v))
            .map(|(k, v)| format!("{}={}", k.trim_end_matches("_weight"), v))
            .collect();
        changed.sort();
        if changed.is_empty() {
            DEFAULT_REWARD.into()
        } else {
            changed.join(",")
        }
    }

    /// Hyperparameters and non-reward environment options that differ from what
    /// `locobench train --env E --algo A` would use today (the algorithm's defaults and the
    /// shipped presets), e.g. `reward_scale=100`; empty when none. Budget and bookkeeping keys
    /// (steps, evaluation and checkpoint cadence) do not count, but for a run that picks its
    /// budget actors among its evaluations (`budget_policy`) the evaluations' cadence and length do.
    pub(crate) fn settings_label(&self) -> String {
        const BOOKKEEPING: [&str; 5] =
            ["total_steps", "eval_every", "eval_episodes", "eval_starts", "checkpoint_every"];
        let picks = self.config.train.budget_policy.selects();
        let bookkeeping = |k: &str| BOOKKEEPING.contains(&k) && !(picks && k.starts_with("eval_"));
        let mut changed = Vec::new();
        if let Ok(preset) = crate::train::config::build_config(self.env(), self.config.train.algo, &[]) {
            let (ours, theirs) = (self.config.train.to_flat_table(), preset.to_flat_table());
            for (k, v) in &ours {
                if !bookkeeping(k) && theirs.get(k) != Some(v) {
                    changed.push(format!("{k}={v}"));
                }
            }
        }
        let defaults = EnvConfig::new(self.env()).resolved_options().unwrap_or_default();
        for (k, v) in &self.config.env.options {
            if !is_reward_option(k) && defaults.get(k) != Some(v) {
                changed.push(format!("{k}={v}"));
            }
        }
        changed.sort();
        changed.join(",")
    }

    /// The name a person gave the run: its directory's name without its `-seed<N>` part
    /// (sweeps name runs `<algo>-<grid point>-seed<N>`; `td3-cleanrl-seed2-300k` reads
    /// `td3-cleanrl-300k`).
    pub(crate) fn variant_name(&self) -> String {
        let name = self.dir.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
        without_seed(&name)
    }

    /// Runs that differ only in their seed share a group. Runs with the shipped settings group
    /// by algorithm and reward whatever their directories are called; runs with other settings
    /// also by the name they were given.
    pub fn group(&self) -> Group {
        if let Some(imported) = &self.imported {
            // Its own row, never pooled with runs trained here.
            return Group {
                env: self.env().to_string(),
                algo: self.family().to_string(),
                reward: self.reward_label(),
                settings: format!("imported from {}", imported.library),
                variant: format!("{} (imported, {})", self.variant_name(), imported.library),
            };
        }
        let settings = self.settings_label();
        Group {
            env: self.env().to_string(),
            algo: self.family().to_string(),
            reward: self.reward_label(),
            variant: if settings.is_empty() { String::new() } else { self.variant_name() },
            settings,
        }
    }

    pub(crate) fn evals(&self) -> impl Iterator<Item = (u64, f64)> + '_ {
        self.metrics.iter().filter(|r| r.kind == "eval").filter_map(|r| r.eval_mean.map(|m| (r.step, m)))
    }

    /// (step, return) of every training episode.
    pub fn episodes(&self) -> impl Iterator<Item = (u64, f64)> + '_ {
        self.metrics.iter().filter(|r| r.kind == "episode").filter_map(|r| r.episode_return.map(|m| (r.step, m)))
    }

    /// Wall time at the last metrics row (s).
    pub fn wall_time(&self) -> f64 {
        self.metrics.last().map_or(0.0, |r| r.wall_time)
    }

    /// Steps at the last metrics row.
    pub fn steps(&self) -> u64 {
        self.metrics.last().map_or(0, |r| r.step)
    }
}

/// What runs must share to be pooled as seeds of one row.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Group {
    /// Env name.
    pub env: String,
    /// Algorithm name.
    pub algo: String,
    /// Reward weights that differ from the env's defaults, as a label.
    pub reward: String,
    /// `Run::settings_label`: empty for the shipped settings.
    pub settings: String,
    /// `Run::variant_name` for runs with other settings than the shipped ones, else empty.
    pub variant: String,
}

impl Group {
    /// What tables call the group: the algorithm (with its reward when not the default) for the
    /// shipped settings, the name the runs were given otherwise. `description` says the rest.
    pub fn label(&self) -> String {
        if !self.variant.is_empty() {
            return self.variant.clone();
        }
        let mut label = self.algo.clone();
        if !self.has_default_reward() {
            label += &format!(" ({})", self.reward);
        }
        label
    }

    /// Trained with the env's default reward weights.
    pub(crate) fn has_default_reward(&self) -> bool {
        self.reward == DEFAULT_REWARD
    }

    /// Shipped settings and the env's default reward: what published curves are comparable with.
    pub(crate) fn is_default_setting(&self) -> bool {
        self.settings.is_empty() && self.has_default_reward()
    }

    /// Algorithm, reward and settings in full.
    pub fn description(&self) -> String {
        let settings = if self.settings.is_empty() { "shipped settings".to_string() } else { self.settings.clone() };
        format!("{}, {}, {settings}", self.algo, self.reward)
    }
}

/// `name` without its last `-seed<digits>` that ends the name or is followed by `-`.
fn without_seed(name: &str) -> String {
    for (i, _) in name.rmatch_indices("-seed") {
        let digits = name[i + 5..].chars().take_while(|c| c.is_ascii_digit()).count();
        let end = i + 5 + digits;
        if digits > 0 && (end == name.len() || name[end..].starts_with('-')) {
            return format!("{}{}", &name[..i], &name[end..]);
        }
    }
    name.to_string()
}

/// Every run directory in `paths`: each path is a run directory itself or is searched
/// (a few levels deep) for them, e.g. a sweep directory.
pub fn find_runs(paths: &[PathBuf]) -> Result<Vec<Run>> {
    fn walk(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> Result<()> {
        // Results kept without checkpoints (config.toml + metrics.csv) count too, and so do
        // exported policies (config.toml + policy.safetensors), those imported from elsewhere
        // included.
        let kept = ["checkpoints", "metrics.csv", crate::train::checkpoint::POLICY_FILE];
        if dir.join("config.toml").is_file() && kept.iter().any(|k| dir.join(k).exists()) {
            out.push(dir.to_path_buf());
            return Ok(());
        }
        if depth == 0 {
            return Ok(());
        }
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("reading {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_dir())
            .collect();
        entries.sort();
        for e in entries {
            walk(&e, depth - 1, out)?;
        }
        Ok(())
    }
    let mut dirs = Vec::new();
    for p in paths {
        if !p.is_dir() {
            bail!("{} is not a directory", p.display());
        }
        let before = dirs.len();
        walk(p, 4, &mut dirs)?;
        if dirs.len() == before {
            bail!(
                "no run directories (with config.toml and checkpoints/, metrics.csv or an exported policy.safetensors) \
                 under {}",
                p.display()
            );
        }
    }
    dirs.sort();
    dirs.dedup();
    dirs.iter().map(|d| Run::load(d)).collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::agents::Algo;
    use crate::train::config::{build_config, split_pairs};

    /// A run of `env` and `algo` with hyperparameter overrides `settings` and env `options`, no metrics.
    pub(crate) fn run(env: &str, algo: Algo, settings: &str, options: &[(&str, &str)]) -> Run {
        let pairs: Vec<(String, String)> = options.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        let mut env_config = EnvConfig::new(env).with_overrides(&pairs).unwrap();
        env_config.options = env_config.resolved_options().unwrap();
        Run {
            dir: PathBuf::from("r"),
            config: RunConfig {
                format: crate::train::run_config::FORMAT,
                seed: 0,
                crate_version: String::new(),
                git_commit: None,
                init_from: None,
                env: env_config,
                train: build_config(env, algo, &split_pairs(settings).unwrap()).unwrap(),
            },
            metrics: vec![],
            imported: None,
        }
    }

    #[test]
    fn groups_tell_changed_settings_apart_but_not_budgets() {
        let plain = run("half-cheetah", Algo::Td3, "total_steps=300000", &[]);
        assert_eq!(plain.settings_label(), "");
        assert_eq!(plain.group().label(), "td3");
        let mut scaled = run("half-cheetah", Algo::Td3, "reward_scale=100,normalize_observations=true", &[]);
        scaled.dir = PathBuf::from("results/td3-scaled-seed3");
        assert_eq!(scaled.settings_label(), "normalize_observations=true,reward_scale=100.0");
        assert_ne!(plain.group(), scaled.group());
        assert_eq!(scaled.group().label(), "td3-scaled");
        assert!(scaled.group().description().contains("reward_scale=100.0"));
        let mut relaxed = run("minitaur", Algo::Sac, "", &[("fall_up_threshold", "0.7"), ("drift_weight", "0.5")]);
        relaxed.dir = PathBuf::from("sweep/runs/sac-drift0.5-seed10");
        assert_eq!(relaxed.settings_label(), "fall_up_threshold=0.7");
        assert_eq!(relaxed.group().label(), "sac-drift0.5");
        // The shipped settings group by algorithm and reward whatever the directory is called.
        let mut shipped = run("minitaur", Algo::Sac, "", &[("drift_weight", "0.5")]);
        shipped.dir = PathBuf::from("anything-seed2");
        assert_eq!(shipped.group().label(), "sac (drift=0.5)");
        assert_eq!(run("minitaur", Algo::Sac, "", &[]).variant_name(), "r");
        // A speed cap is part of the reward, not a setting: such runs are not the default reward.
        let capped = run("minitaur", Algo::Ppo, "", &[("max_rewarded_speed", "1.6"), ("random_push_max", "0.75")]);
        assert_eq!(capped.reward_label(), "max_rewarded_speed=1.6");
        assert_eq!(capped.settings_label(), "random_push_max=0.75");
        assert_eq!(run("minitaur", Algo::Ppo, "", &[("max_rewarded_speed", "0")]).reward_label(), DEFAULT_REWARD);
    }

    /// A run that picks its budget actors among its evaluations picks differently with more
    /// evaluation episodes, so their number is a setting there and bookkeeping elsewhere.
    #[test]
    fn evaluation_length_is_a_setting_only_where_it_picks_the_kept_actor() {
        assert_eq!(run("minitaur", Algo::Td3, "eval_episodes=20", &[]).settings_label(), "");
        let picks = run("minitaur", Algo::Td3, "budget_policy=\"fewest_falls\",eval_episodes=50", &[]);
        assert_eq!(picks.settings_label(), "budget_policy=\"fewest_falls\",eval_episodes=50");
        assert_eq!(run("minitaur", Algo::Ppo, "eval_starts=\"fresh\"", &[]).settings_label(), "");
        let fresh = run("minitaur", Algo::Crossq, "budget_policy=\"best\",eval_starts=\"fresh\"", &[]);
        assert_eq!(fresh.settings_label(), "budget_policy=\"best\",eval_starts=\"fresh\"");
    }

    /// TD3's actor on CrossQ's critics is its own row in the per-algorithm summary, not CrossQ's.
    #[test]
    fn crossq_in_td3_mode_is_compared_as_its_own_algorithm() {
        let td3_mode = run("minitaur", Algo::Crossq, "td3_mode=true", &[]);
        assert_eq!((td3_mode.algo(), td3_mode.family()), ("crossq", "crossq-td3"));
        assert_eq!(td3_mode.group().algo, "crossq-td3");
        assert_eq!(run("minitaur", Algo::Crossq, "", &[]).group().algo, "crossq");
    }

    #[test]
    fn the_seed_part_of_a_run_name_is_dropped_wherever_it_is() {
        assert_eq!(without_seed("sac-drift0.5-seed10"), "sac-drift0.5");
        assert_eq!(without_seed("td3-cleanrl-seed2-300k"), "td3-cleanrl-300k");
        assert_eq!(without_seed("td3-seedless"), "td3-seedless");
        assert_eq!(without_seed("a-seed1-b-seed2"), "a-seed1-b");
        assert_eq!(without_seed("plain"), "plain");
    }
}
