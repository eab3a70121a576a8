//! Action-branching DQN (Tavakoli, Pardo and Kormushev, "Action Branching Architectures for Deep
//! Reinforcement Learning", AAAI 2018): each action dimension (joint) is discretised into
//! `levels` evenly spaced values over its range, and one network with a shared torso has a state
//! value head and one advantage head per joint, so the output grows with joints x levels instead
//! of levels^joints. Q_d(s, a_d) = V(s) + A_d(s, a_d) - mean_a A_d(s, a) (dueling). The target
//! averages the branches' double-DQN values: y = r + gamma (1/D) sum_d Q'_d(s', argmax_a Q_d(s', a)),
//! and the loss is the mean over branches of the squared TD errors. Exploration is epsilon-greedy
//! per branch with epsilon decaying linearly; the target network follows by Polyak averaging.
//!
//! The discretising wrapper is the agent's action encoding: level k of L stands for the value
//! -1 + 2k/(L-1) in the normalised action space [-1, 1], which the trainer maps onto the
//! environment's bounds like every agent's actions, and the replay buffer stores those values;
//! updates read the level back from them.
pub mod device;

use serde::{Deserialize, Serialize};

use candle_core::{Device, Result, Tensor, Var, D};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::agents::common::buffer::Batch;
use crate::agents::common::nets::{batch_tensor, polyak_update, Mlp, Output};
use crate::agents::config::{Algo, TrainConfig};
use crate::agents::{layer_sizes, Agent, Losses, OffPolicyAgent};
use crate::numeric::optim::{Adam, Optimizer};

/// Branching DQN: a dueling network with one advantage head per action dimension.
pub struct BranchingDqnAgent {
    obs_dim: usize,
    branches: usize,
    levels: usize,
    gamma: f64,
    tau: f64,
    schedule: EpsilonSchedule,
    /// Shared torso and every head in one network: output `1 + branches * levels` (V, then each
    /// branch's advantages).
    q: Mlp,
    target: Mlp,
    opt: Adam,
    steps: DqnCounters,
}

/// The counters a resume needs: gradient updates and exploratory actions taken (which set
/// epsilon). Both DQN paths keep them, under the same checkpoint names.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct DqnCounters {
    pub updates: u64,
    pub explore_steps: u64,
}

impl DqnCounters {
    pub fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![("updates", self.updates), ("explore_steps", self.explore_steps)]
    }

    pub fn set(&mut self, name: &str, value: u64) {
        match name {
            "updates" => self.updates = value,
            "explore_steps" => self.explore_steps = value,
            _ => {}
        }
    }
}

/// The checkpoint names of a branching DQN's networks: the Q-network is the policy (what an
/// exported policy keeps), then its target.
pub(crate) fn named_networks(q: Vec<(String, Var)>, target: Vec<(String, Var)>) -> Vec<(String, Var)> {
    q.into_iter().chain(target).collect()
}

/// Epsilon decaying linearly from `start` to `end` over `steps` exploratory actions, then staying.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EpsilonSchedule {
    pub start: f64,
    pub end: f64,
    pub steps: u64,
}

impl EpsilonSchedule {
    pub fn new(s: &DqnConfig) -> EpsilonSchedule {
        EpsilonSchedule { start: s.epsilon_start, end: s.epsilon_end, steps: s.exploration_steps }
    }

    /// The exploration rate after `steps` exploratory actions.
    pub fn at(&self, steps: u64) -> f64 {
        if steps >= self.steps {
            return self.end;
        }
        let frac = steps as f64 / self.steps as f64;
        self.start + frac * (self.end - self.start)
    }
}

/// Each branch's best level as its normalised action value (the first of equal ones), from a
/// `branches x levels` table of Q-values.
pub(crate) fn greedy_levels(q: &[f32], levels: usize) -> Vec<f32> {
    q.chunks(levels)
        .map(|row| {
            let k = row.iter().enumerate().fold(0, |best, (i, &v)| if v > row[best] { i } else { best });
            level_value(k, levels)
        })
        .collect()
}

/// Epsilon-greedy per branch: each greedy value is replaced by a random level with probability
/// `epsilon` (two draws from `rng` where it is, one where it is not).
pub(crate) fn epsilon_greedy(greedy: Vec<f32>, epsilon: f64, levels: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
    greedy
        .into_iter()
        .map(|g| if rng.random::<f64>() < epsilon { level_value(rng.random_range(0..levels), levels) } else { g })
        .collect()
}

/// The normalised action value of level `k` of `levels`.
pub fn level_value(k: usize, levels: usize) -> f32 {
    -1.0 + 2.0 * k as f32 / (levels - 1) as f32
}

/// The level a stored normalised action value stands for (the nearest one).
pub fn value_level(a: f32, levels: usize) -> usize {
    (((a + 1.0) * 0.5 * (levels - 1) as f32).round().max(0.0) as usize).min(levels - 1)
}

impl BranchingDqnAgent {
    /// Builds the network for `obs_dim` observations and `branches` action dimensions.
    pub fn new(cfg: &TrainConfig, obs_dim: usize, branches: usize, rng: &mut ChaCha8Rng) -> Result<Self> {
        let s = cfg.dqn();
        let q = Mlp::new(
            &layer_sizes(obs_dim, &cfg.hidden, 1 + branches * s.levels),
            Output::Linear,
            cfg.weight_init,
            rng,
        )?;
        let target = q.deep_copy()?;
        Ok(BranchingDqnAgent {
            obs_dim,
            branches,
            levels: s.levels,
            gamma: cfg.gamma,
            tau: cfg.tau,
            schedule: EpsilonSchedule::new(s),
            opt: Adam::new(q.params(), cfg.critic_lr),
            q,
            target,
            steps: DqnCounters::default(),
        })
    }

    /// Q-values `[n, branches, levels]` of a network for a batch of observations.
    fn q_values(&self, net: &Mlp, obs: &Tensor) -> Result<Tensor> {
        let n = obs.dims()[0];
        let out = net.forward(obs)?;
        let value = out.narrow(1, 0, 1)?.reshape((n, 1, 1))?;
        let adv = out.narrow(1, 1, self.branches * self.levels)?.reshape((n, self.branches, self.levels))?;
        let centred = adv.broadcast_sub(&adv.mean_keepdim(D::Minus1)?)?;
        centred.broadcast_add(&value)
    }

    /// Q-values of each branch's levels for one observation (`branches x levels`, row-major).
    pub fn q_table(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.q_values(&self.q, &batch_tensor(obs, 1, self.obs_dim)?)?.flatten_all()?.to_vec1::<f32>()
    }

    /// The exploration rate after `steps` exploratory actions.
    pub fn epsilon(&self, steps: u64) -> f64 {
        self.schedule.at(steps)
    }

    /// The TD targets of a batch, one per row.
    pub fn td_targets(&self, batch: &Batch) -> Result<Tensor> {
        let n = batch.size;
        let next_obs = batch_tensor(&batch.next_obs, n, self.obs_dim)?;
        // Double DQN per branch: the online network picks, the target network values.
        let best = self.q_values(&self.q, &next_obs)?.argmax_keepdim(D::Minus1)?;
        let q_next = self.q_values(&self.target, &next_obs)?.gather(&best, D::Minus1)?.squeeze(D::Minus1)?;
        let q_next = q_next.mean_keepdim(D::Minus1)?;
        let rewards = batch_tensor(&batch.rewards, n, 1)?;
        let not_done = batch_tensor(&batch.terminated, n, 1)?.affine(-1.0, 1.0)?;
        Ok((rewards + (not_done * q_next)?.affine(self.gamma, 0.0)?)?.detach())
    }

    fn greedy(&self, obs: &[f32]) -> Result<Vec<f32>> {
        Ok(greedy_levels(&self.q_table(obs)?, self.levels))
    }
}

/// The [`Agent`] methods both versions of the branching DQN share (this file's fused one and `device.rs`'s),
/// written once: both keep their networks, optimisers and counters under the same field names, so
/// a checkpoint names the same things on either path.
macro_rules! dqn_glue {
    () => {
        fn algo(&self) -> Algo {
            Algo::Dqn
        }

        fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
            self.greedy(obs)
        }

        fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
            let epsilon = self.schedule.at(self.steps.explore_steps);
            self.steps.explore_steps += 1;
            Ok(epsilon_greedy(self.greedy(obs)?, epsilon, self.levels, rng))
        }

        fn parameters(&self) -> Vec<(String, Var)> {
            named_networks(self.q.named_vars("actor.q"), self.target.named_vars("q_target"))
        }

        fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn Optimizer)> {
            vec![("q_opt", &mut self.opt as &mut dyn Optimizer)]
        }

        fn counters(&self) -> Vec<(&'static str, u64)> {
            self.steps.counters()
        }

        fn set_counter(&mut self, name: &str, value: u64) {
            self.steps.set(name, value)
        }
    };
}
pub(crate) use dqn_glue;

impl Agent for BranchingDqnAgent {
    dqn_glue!();
}

impl OffPolicyAgent for BranchingDqnAgent {
    fn update(&mut self, batch: &Batch, _rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let obs = batch_tensor(&batch.obs, n, self.obs_dim)?;
        let levels: Vec<u32> = batch.actions.iter().map(|&a| value_level(a, self.levels) as u32).collect();
        let taken = Tensor::from_vec(levels, (n, self.branches, 1), &Device::Cpu)?;
        let y = self.td_targets(batch)?;
        let q = self.q_values(&self.q, &obs)?.gather(&taken, D::Minus1)?.squeeze(D::Minus1)?;
        let loss = q.broadcast_sub(&y)?.sqr()?.mean_all()?;
        let grads = loss.backward()?;
        self.opt.step(&grads)?;
        polyak_update(&self.q, &self.target, self.tau)?;
        self.steps.updates += 1;
        Ok(Losses { critic: loss.to_scalar::<f32>()? as f64, ..Default::default() })
    }
}

/// The action-branching DQN's own settings. It reads the shared `critic_lr` (its one network's
/// learning rate), `tau` (the target network's Polyak coefficient), `batch_size`, the buffer and
/// `learning_starts`; `warmup_steps` must be 0 (epsilon-greedy exploration starts at random).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DqnConfig {
    /// Evenly spaced values each action dimension is discretised into, bounds included.
    pub levels: usize,
    /// Exploration rate at the start.
    pub epsilon_start: f64,
    /// Exploration rate after `exploration_steps`, and from then on.
    pub epsilon_end: f64,
    /// Exploratory steps over which epsilon decays linearly.
    pub exploration_steps: u64,
}

impl DqnConfig {
    pub(crate) const KEYS: &'static [&'static str] = &["levels", "epsilon_start", "epsilon_end", "exploration_steps"];

    /// Checks this section's settings (with the shared ones they depend on).
    pub(crate) fn validate(&self, train: &TrainConfig) -> anyhow::Result<()> {
        anyhow::ensure!(self.levels >= 2, "levels must be at least 2 (the two bounds), got {}", self.levels);
        anyhow::ensure!(
            (0.0..=1.0).contains(&self.epsilon_start) && (0.0..=1.0).contains(&self.epsilon_end),
            "epsilon_start and epsilon_end must lie in [0, 1]"
        );
        anyhow::ensure!(
            train.warmup_steps == 0,
            "dqn explores with epsilon-greedy levels from the start: warmup_steps must be 0 (the warm-up's \
             uniform continuous actions are not levels), got {}",
            train.warmup_steps
        );
        Ok(())
    }
}

impl TrainConfig {
    /// Tavakoli et al. (2018)'s branching DQN: Adam 1e-4, batch 64, 512-256 shared torso, three
    /// levels per joint (the Minitaur study this project grew from used three), epsilon-greedy
    /// from 1 to 0.05 over 50k steps.
    pub(crate) fn dqn_defaults() -> TrainConfig {
        TrainConfig {
            warmup_steps: 0,
            batch_size: 64,
            hidden: vec![512, 256],
            actor_lr: 1e-4,
            critic_lr: 1e-4,
            dqn: Some(DqnConfig { levels: 3, epsilon_start: 1.0, epsilon_end: 0.05, exploration_steps: 50_000 }),
            ..TrainConfig::shared_defaults(Algo::Dqn)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn agent(levels: usize) -> BranchingDqnAgent {
        let mut cfg = TrainConfig::defaults(Algo::Dqn);
        cfg.hidden = vec![8, 8];
        cfg.dqn.as_mut().unwrap().levels = levels;
        BranchingDqnAgent::new(&cfg, 3, 2, &mut ChaCha8Rng::seed_from_u64(0)).unwrap()
    }

    #[test]
    fn levels_and_values_round_trip() {
        for levels in [2, 3, 5] {
            for k in 0..levels {
                assert_eq!(value_level(level_value(k, levels), levels), k);
            }
        }
        assert_eq!(level_value(0, 3), -1.0);
        assert_eq!(level_value(1, 3), 0.0);
        assert_eq!(level_value(2, 3), 1.0);
        assert_eq!(value_level(0.4, 3), 1);
        assert_eq!(value_level(0.6, 3), 2);
    }

    #[test]
    fn q_values_are_value_plus_centred_advantages() {
        let a = agent(3);
        let obs = [0.3f32, -0.1, 0.7];
        let out =
            a.q.forward(&batch_tensor(&obs, 1, 3).unwrap()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let q = a.q_table(&obs).unwrap();
        for d in 0..2 {
            let adv = &out[1 + 3 * d..1 + 3 * d + 3];
            let mean = adv.iter().sum::<f32>() / 3.0;
            for k in 0..3 {
                assert!((q[3 * d + k] - (out[0] + adv[k] - mean)).abs() < 1e-6);
            }
        }
        // The greedy action takes each branch's best level.
        let act = a.act(&obs).unwrap();
        for d in 0..2 {
            let row = &q[3 * d..3 * d + 3];
            let best = (0..3).max_by(|&i, &j| row[i].total_cmp(&row[j])).unwrap();
            assert_eq!(act[d], level_value(best, 3));
        }
    }

    #[test]
    fn targets_average_the_branches_double_dqn_values() {
        let a = agent(3);
        let mut b = Batch::new(2, 3, 2);
        b.next_obs = vec![0.1, 0.2, 0.3, -0.5, 0.4, 0.0];
        b.rewards = vec![1.0, 2.0];
        b.terminated = vec![0.0, 1.0];
        let y = a.td_targets(&b).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let online = a.q_table(&b.next_obs[..3]).unwrap();
        let target = a.q_values(&a.target, &batch_tensor(&b.next_obs[..3], 1, 3).unwrap()).unwrap();
        let target = target.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let mut sum = 0.0;
        for d in 0..2 {
            let row = &online[3 * d..3 * d + 3];
            let best = (0..3).max_by(|&i, &j| row[i].total_cmp(&row[j])).unwrap();
            sum += target[3 * d + best];
        }
        assert!((y[0] - (1.0 + 0.99 * sum / 2.0)).abs() < 1e-5, "{} vs {}", y[0], 1.0 + 0.99 * sum / 2.0);
        assert_eq!(y[1], 2.0, "a terminated row does not bootstrap");
    }

    #[test]
    fn epsilon_decays_linearly_then_stays() {
        let a = agent(3);
        let (start, end, steps) = (a.schedule.start, a.schedule.end, a.schedule.steps);
        assert_eq!(a.epsilon(0), start);
        assert!((a.epsilon(steps / 2) - (start + end) / 2.0).abs() < 1e-9);
        assert_eq!(a.epsilon(steps), end);
        assert_eq!(a.epsilon(10 * steps), end);
    }
}
