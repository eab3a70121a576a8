//! Rows of the held-out evaluation: one per group of runs (the same env, algorithm, reward and
//! settings) and step budget, every run that reached the budget evaluated from its policy at that
//! budget under the evaluation protocol, and listed when it has none.
use std::collections::BTreeSet;
use std::path::PathBuf;

use anyhow::{Context, Result};

use super::budgets::{policy_at, reached};
use super::runs::{Group, Run};
use crate::controller::measure::{mean_cost_of_transport, GaitEpisode};
use crate::envs::{make, EnvConfig};
use crate::evaluation::cache::{EvalCache, Key};
use crate::evaluation::stats;
use crate::evaluation::{Protocol, Push};
use crate::policy::AgentPolicy;
use crate::train::provenance;

/// Rows with fewer seeds than this say so: intervals over so few seeds are rough.
pub(crate) const FEW_SEEDS: usize = 3;

/// One run's episodes at a budget.
#[derive(Debug, Clone)]
pub struct SeedResult {
    /// The run the policy came from.
    pub run_dir: PathBuf,
    /// Its training seed.
    pub seed: u64,
    /// The held-out episodes it played.
    pub episodes: Vec<GaitEpisode>,
}

/// One table row: a group of runs at one step budget, each played on the held-out episodes.
#[derive(Debug, Clone)]
pub struct BudgetRow {
    /// The runs' env, algorithm, reward and settings.
    pub group: Group,
    /// Environment steps the policies were trained for.
    pub budget: u64,
    /// One result per run that has a policy at the budget.
    pub evaluated: Vec<SeedResult>,
    /// Runs that reached the budget without a policy there, with the reason.
    pub missing: Vec<(PathBuf, String)>,
    /// The env the policies ran in (the first run's).
    pub env_config: Option<EnvConfig>,
    /// What computed the runs up to the budget, and whether they differ.
    pub provenance: String,
    /// Whether the runs' provenance differs (another CPU path, commit or MuJoCo).
    pub mixed_provenance: bool,
    /// Mean over seeds of the wall time to reach the budget (s), where recorded.
    pub wall_time: Option<f64>,
    /// Seeds that more than one run of the row used (not independent samples).
    pub duplicate_seeds: Vec<u64>,
    /// Evaluated outside locobench (`report --external`): episodes read from files, no policy
    /// the report can play itself.
    pub external: bool,
}

pub use crate::evaluation::stats::{estimate, Estimate};

impl BudgetRow {
    /// A row of `group` at `budget` with nothing evaluated or recorded yet.
    pub(crate) fn empty(group: Group, budget: u64) -> BudgetRow {
        BudgetRow {
            group,
            budget,
            evaluated: Vec::new(),
            missing: Vec::new(),
            env_config: None,
            provenance: String::new(),
            mixed_provenance: false,
            wall_time: None,
            duplicate_seeds: Vec::new(),
            external: false,
        }
    }

    /// The rows of external evaluations (`evaluation::external`) of one env: one per label,
    /// its directories' episodes as seeds. Each must follow `protocol` and have been played in
    /// one of `envs` (the env options and reward of the report's groups in that env, first
    /// the default); otherwise an error names the directory and what differs from the first.
    pub(crate) fn external_rows(
        externals: &[crate::evaluation::external::External],
        envs: &[EnvConfig],
        protocol: &Protocol,
    ) -> Result<Vec<BudgetRow>> {
        let env = envs.first().context("no env to match external evaluations with")?;
        let resolved = envs.iter().map(EnvConfig::resolved_options).collect::<Result<Vec<_>, _>>()?;
        let ours = &resolved[0];
        let mut rows: Vec<BudgetRow> = Vec::new();
        for x in externals {
            anyhow::ensure!(
                x.protocol() == *protocol,
                "{}: {} episodes with protocol seed {}; this report plays {} with protocol seed {}",
                x.dir.display(),
                x.meta.episodes,
                x.meta.protocol_seed,
                protocol.episodes,
                protocol.seed
            );
            // Resolved through today's registry: an options table written before an option
            // existed means that option's default.
            let theirs = EnvConfig { name: env.name.clone(), options: x.meta.options.clone() }
                .resolved_options()
                .with_context(|| format!("{}: its env options", x.dir.display()))?;
            let matched = resolved.iter().position(|r| *r == theirs);
            if matched.is_none() {
                let differs: Vec<String> = theirs
                    .iter()
                    .filter(|(k, v)| ours.get(*k) != Some(*v))
                    .map(|(k, v)| {
                        format!(
                            "{k} = {v} (the report's runs: {})",
                            ours.get(k).map_or("unset".into(), |o| o.to_string())
                        )
                    })
                    .collect();
                anyhow::bail!(
                    "{}: played {} under other options or rewards than the report's runs (none of its {} \
                     groups there matches; against the first: {})",
                    x.dir.display(),
                    x.meta.env,
                    envs.len(),
                    differs.join(", ")
                );
            }
            let matched_env = &envs[matched.unwrap_or(0)];
            let group = Group {
                env: x.meta.env.clone(),
                algo: x.meta.label.clone(),
                reward: String::new(),
                settings: "evaluated outside locobench".into(),
                variant: format!("{} (external)", x.meta.label),
            };
            let budget = x.meta.steps.unwrap_or(0);
            let i = match rows.iter().position(|r| r.group == group) {
                Some(i) => i,
                None => {
                    let mut row = BudgetRow::empty(group, budget);
                    row.external = true;
                    row.env_config = Some(matched_env.clone());
                    rows.push(row);
                    rows.len() - 1
                }
            };
            let row = &mut rows[i];
            row.budget = row.budget.max(budget);
            row.evaluated.push(SeedResult {
                run_dir: x.dir.clone(),
                seed: x.meta.seed.unwrap_or(0),
                episodes: x.episodes.clone(),
            });
            let provenance = x.provenance();
            if !row.provenance.is_empty() && !row.provenance.split("; ").any(|p| p == provenance) {
                row.mixed_provenance = true;
                row.provenance = format!("{}; {provenance}", row.provenance);
            } else if row.provenance.is_empty() {
                row.provenance = provenance;
            }
        }
        for row in &mut rows {
            row.duplicate_seeds = duplicate_seeds(&row.evaluated);
        }
        Ok(rows)
    }

    /// Number of runs evaluated.
    pub fn seeds(&self) -> usize {
        self.evaluated.len()
    }
    pub(crate) fn episodes_per_seed(&self) -> usize {
        self.evaluated.first().map_or(0, |s| s.episodes.len())
    }
    pub(crate) fn all_episodes(&self) -> impl Iterator<Item = &GaitEpisode> {
        self.evaluated.iter().flat_map(|s| s.episodes.iter())
    }
    pub(crate) fn returns_per_seed(&self) -> Vec<Vec<f64>> {
        self.evaluated.iter().map(|s| s.episodes.iter().map(|e| e.episode_return).collect()).collect()
    }
    /// The mean return over seeds, with a bootstrap interval seeded by `seed`.
    pub fn mean_return(&self, seed: u64) -> Estimate {
        estimate(&self.returns_per_seed(), stats::mean, seed)
    }
    pub(crate) fn iqm_return(&self, seed: u64) -> Estimate {
        estimate(&self.returns_per_seed(), stats::iqm, seed ^ 0x1)
    }
    /// Falls and episodes, over every seed.
    pub fn falls(&self) -> (usize, usize) {
        (self.all_episodes().filter(|e| e.fell).count(), self.all_episodes().count())
    }
    /// Mean forward speed over every episode (m/s).
    pub fn speed(&self) -> f64 {
        stats::mean(&self.all_episodes().map(|e| e.mean_speed).collect::<Vec<_>>())
    }
    pub(crate) fn cost_of_transport(&self) -> f64 {
        mean_cost_of_transport(&self.all_episodes().cloned().collect::<Vec<_>>())
    }
}

/// Seeds that more than one of `evaluated` used (a seed used k times is listed k - 1 times).
fn duplicate_seeds(evaluated: &[SeedResult]) -> Vec<u64> {
    let mut seeds: Vec<u64> = evaluated.iter().map(|s| s.seed).collect();
    seeds.sort_unstable();
    seeds.windows(2).filter(|w| w[0] == w[1]).map(|w| w[0]).collect()
}

/// The env a held-out row plays: the run's env without its perturbations (`for_evaluation`) and,
/// on a velocity-command task, with the task's default reward. There the reward is a training
/// device (fine-tunes narrow its kernels or reweigh its terms) and the tracking table is the
/// comparison, so every policy's return is measured on the one reward the controller is scored on.
pub(crate) fn evaluation_env(env: &EnvConfig) -> EnvConfig {
    let mut out = env.for_evaluation();
    if crate::envs::command::is_command_task(&out.name) {
        out.options.retain(|k, _| !super::runs::is_reward_option(k));
    }
    out
}

/// Evaluates `runs` (one group) at `budget`, optionally under a push; episodes `cache` holds are
/// read from it, the others played and kept there.
pub(crate) fn evaluate_row(
    group: &Group,
    runs: &[&Run],
    budget: u64,
    protocol: &Protocol,
    push: Option<Push>,
    cache: &EvalCache,
) -> Result<BudgetRow> {
    let mut row = BudgetRow::empty(group.clone(), budget);
    let mut machines = BTreeSet::new();
    let mut walls = Vec::new();
    for run in runs.iter().filter(|r| reached(r) >= budget) {
        let source = match policy_at(run, budget) {
            Ok(s) => s,
            Err(why) => {
                row.missing.push((run.dir.clone(), why));
                continue;
            }
        };
        let (cfg, agent) = match source.load(&run.dir, budget) {
            Ok(x) => x,
            Err(e) => {
                row.missing.push((run.dir.clone(), format!("policy unreadable: {e:#}")));
                continue;
            }
        };
        protocol.check_run(cfg.seed, &cfg.train)?;
        let env_config = evaluation_env(&cfg.env);
        let key = cache.timed(|| -> Result<Key> {
            let policy_key = format!("agent {}", source.digest(&run.dir)?);
            Key::episodes(&env_config, protocol, &policy_key, None, push)
        })?;
        let episodes = cache.episodes(&key, || {
            let mut env = make(&env_config).with_context(|| format!("making the env of {}", run.dir.display()))?;
            let mut policy = AgentPolicy { agent: agent.as_ref(), label: run.algo().to_string() };
            protocol.run(env.as_mut(), &mut policy, None, push)
        })?;
        row.env_config.get_or_insert(env_config);
        row.evaluated.push(SeedResult { run_dir: run.dir.clone(), seed: cfg.seed, episodes });
        machines.insert(machine_of(run, budget));
        if let Some(w) = run.metrics.iter().rfind(|m| m.step <= budget).map(|m| m.wall_time) {
            walls.push(w);
        }
    }
    row.duplicate_seeds = duplicate_seeds(&row.evaluated);
    row.mixed_provenance = machines.len() > 1;
    row.provenance = machines.into_iter().collect::<Vec<_>>().join("; ");
    if !walls.is_empty() && walls.len() == row.evaluated.len() {
        row.wall_time = Some(stats::mean(&walls));
    }
    Ok(row)
}

/// What computed `run` up to `budget`: CPU, SIMD level, kernels and commit of each stretch.
pub(crate) fn machine_of(run: &Run, budget: u64) -> String {
    match provenance::read(&run.dir) {
        Ok(stretches) if !stretches.is_empty() => {
            let mut parts: Vec<String> = stretches
                .iter()
                .filter(|s| s.from_step < budget.max(1))
                .map(|s| {
                    let commit = crate::train::provenance::short_commit(&s.git_commit, 8);
                    format!("{} ({}, {} kernels) @ {commit}", s.cpu_model, s.simd, s.kernel_path)
                })
                .collect();
            parts.dedup();
            parts.join(" then ")
        }
        _ => "not recorded".to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(env: &str, overrides: &str) -> EnvConfig {
        let pairs = crate::envs::parse_overrides(overrides).unwrap();
        let mut c = EnvConfig::new(env).with_overrides(&pairs).unwrap();
        c.options = c.resolved_options().unwrap();
        c
    }

    #[test]
    fn command_tasks_are_played_on_their_default_reward() {
        let trained =
            config("minitaur-command", "tracking_sigma=0.05,tracking_yaw_rate_weight=1.0,random_battery_min=6.0");
        let played = evaluation_env(&trained);
        assert_eq!(played.resolved_options().unwrap(), EnvConfig::new("minitaur-command").resolved_options().unwrap());
        // what is not reward or perturbation stays: the Ant run trained in the torso's frame
        let ant = evaluation_env(&config("ant-command", "forward_angle=0.0,feet_air_time_weight=1.0"));
        let options = ant.resolved_options().unwrap();
        assert_eq!(options.get("forward_angle").and_then(|v| v.as_float()), Some(0.0));
        let defaults = EnvConfig::new("ant-command").resolved_options().unwrap();
        assert_eq!(options.get("feet_air_time_weight"), defaults.get("feet_air_time_weight"));
    }

    #[test]
    fn other_envs_keep_the_reward_they_were_trained_on() {
        let freeman = config("minitaur", "energy_weight=0.0,random_push_max=0.5");
        let played = evaluation_env(&freeman);
        assert_eq!(played.options.get("energy_weight").and_then(|v| v.as_float()), Some(0.0));
        assert!(!played.options.contains_key("random_push_max"));
    }
}
