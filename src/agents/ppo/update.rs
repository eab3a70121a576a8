//! PPO's update from one rollout: generalised advantage estimation (Schulman et al. 2016), then
//! `update_epochs` passes over shuffled minibatches of the rollout, stopped early when the
//! approximate KL divergence passes `target_kl` (CleanRL's `ppo_continuous_action.py`, the
//! "Optimizing the policy and value network" block). The collection loop that fills a
//! [`Rollout`] is `train::on_policy`.
use candle_core::Result;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::{PpoBatch, PpoConfig, PpoLosses};
use crate::agents::OnPolicyAgent;

/// One rollout, time-major (`t * copies + i`).
#[derive(Debug, Default)]
pub struct Rollout {
    /// Normalised observations, `obs_dim` each.
    pub obs: Vec<f32>,
    /// The sampled actions, `act_dim` each.
    pub actions: Vec<f32>,
    /// Log-probability of each action when it was sampled.
    pub log_probs: Vec<f32>,
    /// The value of each observation when it was seen.
    pub values: Vec<f32>,
    /// The learner's rewards (a truncated episode's last one includes the bootstrap).
    pub rewards: Vec<f32>,
    /// The transition ended its episode (terminated, truncated or unstable).
    pub dones: Vec<bool>,
    /// The physics blew up: not a real transition, left out of the update.
    pub unstable: Vec<bool>,
}

/// Advantages by GAE(`gamma`, `lambda`) over `steps` steps of `copies` environments, bootstrapped
/// from `next_values` (one per copy) after the last step. Unstable transitions get 0 and cut the
/// trace.
pub fn advantages(r: &Rollout, next_values: &[f32], copies: usize, steps: usize, gamma: f32, lambda: f32) -> Vec<f32> {
    let n = copies;
    let mut advantages = vec![0.0f32; steps * n];
    for (i, &bootstrap) in next_values.iter().enumerate() {
        let mut last = 0.0f32;
        for t in (0..steps).rev() {
            let k = t * n + i;
            if r.unstable[k] {
                last = 0.0;
                continue;
            }
            let next_value = if t + 1 == steps { bootstrap } else { r.values[k + n] };
            let not_done = if r.dones[k] { 0.0 } else { 1.0 };
            let delta = r.rewards[k] + gamma * next_value * not_done - r.values[k];
            last = delta + gamma * lambda * not_done * last;
            advantages[k] = last;
        }
    }
    advantages
}

/// GAE over the rollout, then `update_epochs` passes of shuffled minibatches (shuffled with
/// `rng`); returns the last minibatch's losses.
pub fn update(
    agent: &mut dyn OnPolicyAgent,
    r: &Rollout,
    next_values: &[f32],
    settings: &PpoConfig,
    gamma: f64,
    rng: &mut ChaCha8Rng,
) -> Result<PpoLosses> {
    let (n, steps) = (settings.num_envs, settings.num_steps);
    let advantages = advantages(r, next_values, n, steps, gamma as f32, settings.gae_lambda as f32);
    let returns: Vec<f32> = advantages.iter().zip(&r.values).map(|(a, v)| a + v).collect();
    let mut indices: Vec<usize> = (0..steps * n).filter(|&k| !r.unstable[k]).collect();
    let (obs_dim, act_dim) = (r.obs.len() / (steps * n), r.actions.len() / (steps * n));
    let minibatch = indices.len().div_ceil(settings.num_minibatches).max(1);
    let mut last = PpoLosses::default();
    for _ in 0..settings.update_epochs {
        indices.shuffle(rng);
        for chunk in indices.chunks(minibatch) {
            let rows = |src: &[f32], width: usize| -> Vec<f32> {
                chunk.iter().flat_map(|&k| src[k * width..(k + 1) * width].iter().copied()).collect()
            };
            let batch = PpoBatch {
                obs: rows(&r.obs, obs_dim),
                actions: rows(&r.actions, act_dim),
                log_probs: rows(&r.log_probs, 1),
                advantages: rows(&advantages, 1),
                returns: rows(&returns, 1),
                values: rows(&r.values, 1),
            };
            last = agent.learn(&batch)?;
        }
        if settings.target_kl.is_some_and(|kl| last.approx_kl > kl) {
            break;
        }
    }
    Ok(last)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rollout(rewards: &[f32], values: &[f32], dones: &[bool], unstable: &[bool]) -> Rollout {
        Rollout {
            rewards: rewards.to_vec(),
            values: values.to_vec(),
            dones: dones.to_vec(),
            unstable: unstable.to_vec(),
            ..Rollout::default()
        }
    }

    #[test]
    fn advantages_match_a_hand_computed_gae() {
        // One copy, three steps, no episode end: delta_t = r_t + g V_{t+1} - V_t, and
        // A_t = delta_t + g l A_{t+1}, bootstrapped from V = 4 after the last step.
        let (g, l) = (0.5f32, 0.5f32);
        let r = rollout(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0], &[false; 3], &[false; 3]);
        let a = advantages(&r, &[4.0], 1, 3, g, l);
        let d2 = 3.0 + g * 4.0 - 3.0;
        let d1 = 2.0 + g * 3.0 - 2.0;
        let d0 = 1.0 + g * 2.0 - 1.0;
        let a2 = d2;
        let a1 = d1 + g * l * a2;
        let a0 = d0 + g * l * a1;
        assert_eq!(a, vec![a0, a1, a2]);
    }

    #[test]
    fn an_episode_end_stops_the_bootstrap_and_an_unstable_step_cuts_the_trace() {
        // Two copies, time-major. Copy 0 ends its episode at t = 0; copy 1's t = 1 blew up.
        let r = rollout(
            &[1.0, 1.0, 1.0, 1.0],
            &[0.0, 0.0, 0.0, 0.0],
            &[true, false, false, true],
            &[false, false, false, true],
        );
        let a = advantages(&r, &[10.0, 10.0], 2, 2, 1.0, 1.0);
        // copy 0: t = 0 ends its episode, so neither V(t = 1) nor A(t = 1) flows back into it
        assert_eq!(a[0], 1.0);
        assert_eq!(a[2], 1.0 + 10.0);
        // copy 1: t = 1 is left out (0) and the trace restarts, so t = 0 sees only V(t = 1) = 0
        assert_eq!(a[3], 0.0);
        assert_eq!(a[1], 1.0);
    }
}
