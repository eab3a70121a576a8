//! Baseline controller against trained agents on the same environment and reward: each policy
//! is run for whole episodes and measured the same way (return, speed, tracking, energy, cost
//! of transport, drift, shake, falls, length).
use anyhow::Result;

use super::runs::{is_reward_weight, Run};
use crate::controller::baseline::{baseline_controller, baseline_env_like, RAMP_TIME};
use crate::controller::command::SpeedProfile;
use crate::controller::measure::{measure, GaitEpisode};
use crate::envs::{make, EnvConfig};
use crate::policy::AgentPolicy;
use crate::train::{has_policy, load_policy};

/// A reward under which every policy is re-evaluated.
#[derive(Debug, Clone, PartialEq)]
pub struct RewardVariant {
    pub name: String,
    /// Option key -> weight.
    pub weights: Vec<(String, f64)>,
}

/// Minitaur's comparison rewards besides each run's own: no penalties at all, and the full
/// penalty set (drift 1, shake 1, energy 0.005).
pub fn minitaur_variants() -> Vec<RewardVariant> {
    let w = |d: f64, s: f64, e: f64| {
        vec![("drift_weight".to_string(), d), ("shake_weight".to_string(), s), ("energy_weight".to_string(), e)]
    };
    vec![
        RewardVariant { name: "no penalty".into(), weights: w(0.0, 0.0, 0.0) },
        RewardVariant { name: "full penalty".into(), weights: w(1.0, 1.0, 0.005) },
    ]
}

/// Measures of one policy under one reward, over all its episodes (all seeds for RL).
#[derive(Debug, Clone)]
pub struct ComparisonRow {
    pub policy: String,
    pub reward: String,
    pub episodes: Vec<GaitEpisode>,
    /// The speed set-point, for the baseline only (RL has none).
    pub set_point: Option<f64>,
}

fn with_weights(mut cfg: EnvConfig, weights: &[(String, f64)]) -> EnvConfig {
    for (k, v) in weights {
        cfg.options.insert(k.clone(), toml::Value::Float(*v));
    }
    cfg
}

/// The reward weights a run trained with.
fn training_weights(run: &Run) -> Vec<(String, f64)> {
    run.config
        .env
        .options
        .iter()
        .filter(|(k, _)| is_reward_weight(k))
        .filter_map(|(k, v)| v.as_float().or(v.as_integer().map(|i| i as f64)).map(|f| (k.clone(), f)))
        .collect()
}

/// Compares the baseline with every group of runs on `env` (`minitaur` or `ant`). Each group
/// is scored under its own training reward, and for Minitaur also under the no-penalty and
/// full-penalty rewards; the baseline is scored under each of those rewards too, in the first
/// run's env options (episode length, randomisation) with the baseline's action mode.
pub fn compare(env: &str, groups: &[Vec<&Run>], episodes: usize, seed: u64, speed: f64) -> Result<Vec<ComparisonRow>> {
    anyhow::ensure!(!groups.is_empty() && groups.iter().all(|g| !g.is_empty()), "no runs to compare on {env}");
    let mut variants: Vec<RewardVariant> = Vec::new();
    for group in groups {
        let weights = training_weights(group[0]);
        let name = format!("trained reward ({})", group[0].reward_label());
        if !variants.iter().any(|v| v.weights == weights) {
            variants.push(RewardVariant { name, weights });
        }
    }
    if env == "minitaur" {
        variants.extend(minitaur_variants());
    }
    let mut rows = Vec::new();
    for variant in &variants {
        let mut env_b = make(&with_weights(baseline_env_like(&groups[0][0].config.env)?, &variant.weights))?;
        let profile = SpeedProfile::ramp(speed, RAMP_TIME);
        let mut controller = baseline_controller(env, speed, None)?;
        let eps = measure(env_b.as_mut(), controller.as_mut(), episodes, seed, &profile)?;
        rows.push(ComparisonRow {
            policy: format!("baseline ({})", controller.name()),
            reward: variant.name.clone(),
            episodes: eps,
            set_point: Some(speed),
        });
        for group in groups {
            // Results kept without weights (config and metrics only) cannot act.
            let group: Vec<&Run> = group.iter().copied().filter(|r| has_policy(&r.dir)).collect();
            if group.is_empty() {
                continue;
            }
            let mut all = Vec::new();
            for run in &group {
                let (run_cfg, agent) = load_policy(&run.dir)?;
                let mut env_rl = make(&with_weights(run_cfg.env.clone(), &variant.weights))?;
                let mut policy = AgentPolicy { agent: agent.as_ref(), label: run.algo().into() };
                // RL has no set-point: its speed error is measured against the baseline's.
                all.extend(measure(env_rl.as_mut(), &mut policy, episodes, seed, &profile)?);
            }
            rows.push(ComparisonRow {
                policy: format!("{} ({}, {} seeds)", group[0].group().label(), group[0].reward_label(), group.len()),
                reward: variant.name.clone(),
                episodes: all,
                set_point: None,
            });
        }
    }
    Ok(rows)
}
