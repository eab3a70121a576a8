//! PPO's training loop: collect a rollout on a vector environment, compute GAE advantages, run
//! the update epochs, evaluate and checkpoint between rollouts (CleanRL's
//! `ppo_continuous_action.py` is the reference; docs/training.md lists the differences).
//!
//! Reward normalisation is gymnasium's `NormalizeReward`: each copy keeps a discounted return,
//! reset at termination, whose running variance scales the rewards, which are then clipped. One
//! set of observation and return statistics serves every copy (as Stable-Baselines3's
//! `VecNormalize`), updated in copy order. A copy truncated by its time limit adds `gamma V` of
//! its last observation to its last reward, so the time limit is not treated as a terminal state.
//!
//! Checkpoints are taken between rollouts and resume bit for bit: the vector environment's
//! snapshot (`envs::VecEnvSnapshot`), the reward statistics and the running episode totals go to
//! `rollout.safetensors` beside the networks.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use candle_core::{Device, Tensor};
use rand_chacha::ChaCha8Rng;

use super::checkpoint::POLICY_BUDGETS;
use super::checkpoint::{self, TrainState};
use super::control::{Outcome, RunControl, RunSummary};
use super::evaluate::evaluate_at;
use super::fault::{self, Point};
use super::metrics::MetricsRow;
use super::policy_ref::PolicyRef;
use super::run_config::RunConfig;
use super::scaffold::{self, finish_run, save_budget_policy, Scaffold};
use super::seeds::{init_rng, train_episode_seed, training_rng, RngState};
use crate::agents::ppo::update::{update, Rollout};
use crate::agents::ppo::{PpoLosses, RunningMeanStd};
use crate::agents::{make_on_policy_on, Losses, OnPolicyAgent, PpoConfig, TrainConfig};
use crate::envs::{make, Env, VecEnv, VecEnvSnapshot};
use crate::policy::to_space;

pub(super) const ROLLOUT_FILE: &str = "rollout.safetensors";
/// gymnasium's `NormalizeReward` epsilon.
const RETURN_EPSILON: f64 = 1e-8;

/// Training episode `k` of copy `i` of `n` is the run's training episode `k n + i`, so the
/// evaluation protocol's check against training seeds (`train_episode_seed`) covers PPO runs too.
fn training_seeds(run_seed: u64, copy: usize, copies: usize, episode: u64) -> u64 {
    train_episode_seed(run_seed, episode * copies as u64 + copy as u64)
}

struct OnPolicyTrainer {
    run_dir: PathBuf,
    run: RunConfig,
    settings: PpoConfig,
    agent: Box<dyn OnPolicyAgent>,
    envs: VecEnv,
    eval_env: Box<dyn Env>,
    rng: ChaCha8Rng,
    /// The observations to act on next, raw.
    obs: Vec<Vec<f64>>,
    step: u64,
    episodes: u64,
    wall_offset: f64,
    metrics: Vec<MetricsRow>,
    /// The best in-training evaluation mean so far.
    best_eval: Option<f64>,
    returns: Vec<f64>,
    /// Running statistics of the copies' discounted returns (one feature).
    return_stat: RunningMeanStd,
    episode_returns: Vec<f64>,
    episode_lengths: Vec<u64>,
}

/// Starts a new PPO run in `run_dir` (checked to be free), from `init_from`'s weights if given.
pub(super) fn train(
    run_dir: &Path,
    run: &RunConfig,
    init_from: Option<&PolicyRef>,
    control: &RunControl,
) -> Result<RunSummary> {
    let mut t = OnPolicyTrainer::new(run_dir, run, control)?;
    if let Some(policy) = init_from {
        policy.load_into_env(&*t.agent, &run.env)?;
    }
    let _lock = scaffold::create_run_dir(run_dir, run, control)?;
    t.obs = t.envs.reset(run.seed)?;
    t.agent.observe(&t.obs)?;
    t.run(control)
}

/// Continues a PPO run from `ckpt`, with the run's metrics rows up to it.
pub(super) fn resume(
    run_dir: &Path,
    run: &RunConfig,
    ckpt: &Path,
    metrics: Vec<MetricsRow>,
    control: &RunControl,
) -> Result<RunSummary> {
    let mut t = OnPolicyTrainer::new(run_dir, run, control)?;
    let state = checkpoint::load_training(ckpt, &mut *t.agent)?;
    t.rng = state.rng.restore()?;
    t.step = state.step;
    t.episodes = state.episodes;
    t.wall_offset = state.wall_time;
    t.best_eval = state.best_eval_mean;
    let saved = checkpoint::read_trainer_file(ckpt, ROLLOUT_FILE)?;
    let snapshot =
        t.read_rollout_state(&saved).with_context(|| format!("{} is corrupt", ckpt.join(ROLLOUT_FILE).display()))?;
    t.obs = t.envs.restore(&snapshot)?;
    t.metrics = metrics;
    scaffold::record_stretch(run_dir, state.step, control)?;
    t.run(control)
}

impl OnPolicyTrainer {
    fn new(run_dir: &Path, run: &RunConfig, control: &RunControl) -> Result<OnPolicyTrainer> {
        let settings = run.train.ppo().clone();
        let envs = VecEnv::new(&run.env, settings.num_envs, control.threads.max(1))?.with_episode_seeds(training_seeds);
        let spec = envs.spec().clone();
        let (obs_dim, act_dim) = (spec.observation_space.dim(), spec.action_space.dim());
        let agent = make_on_policy_on(&run.train, obs_dim, act_dim, &mut init_rng(run.seed), control.device)?;
        let n = settings.num_envs;
        Ok(OnPolicyTrainer {
            run_dir: run_dir.to_path_buf(),
            run: run.clone(),
            agent,
            envs,
            eval_env: make(&run.env)?,
            rng: training_rng(run.seed),
            obs: Vec::new(),
            step: 0,
            episodes: 0,
            wall_offset: 0.0,
            metrics: Vec::new(),
            best_eval: None,
            returns: vec![0.0; n],
            return_stat: RunningMeanStd::new(1),
            episode_returns: vec![0.0; n],
            episode_lengths: vec![0; n],
            settings,
        })
    }

    fn cfg(&self) -> &TrainConfig {
        &self.run.train
    }

    fn run(&mut self, control: &RunControl) -> Result<RunSummary> {
        let total = self.cfg().total_steps;
        let rollout = self.settings.rollout_size() as u64;
        let iterations = total.div_ceil(rollout).max(1);
        let recording = scaffold::open_recording(control)?;
        let mut sc = Scaffold::start(control, &self.run_dir, &self.run.env, total, self.step, recording.as_ref())?;
        let mut losses: Option<Losses>;
        let checkpoint_every = self.cfg().checkpoint_every;
        let eval_every = self.cfg().eval_every;
        let mut next_checkpoint = (self.step / checkpoint_every + 1) * checkpoint_every;

        let outcome = loop {
            if self.step >= total || sc.solved(control) {
                break Outcome::Finished;
            }
            // Rollouts are short (seconds), so every stop request waits for the next boundary,
            // where a checkpoint resumes exactly.
            if sc.signals.now() || sc.signals.at_episode_end() || control.stop_after.is_some_and(|s| self.step >= s) {
                break Outcome::Stopped;
            }
            if self.settings.anneal_lr {
                let iteration = self.step / rollout;
                self.agent.anneal(1.0 - iteration as f64 / iterations as f64);
            }
            let before = self.step;
            let data = self.collect(&mut sc)?;
            let l = self.update(&data)?;
            losses = Some(Losses { critic: l.value, actor: Some(l.policy), ..Losses::default() });

            if scaffold::crossed(before, self.step, eval_every) || self.step >= total {
                let e = evaluate_at(&*self.agent, self.eval_env.as_mut(), &self.run.train, self.run.seed, self.step)?;
                self.best_eval = Some(self.best_eval.map_or(e.mean(), |b: f64| b.max(e.mean())));
                let row =
                    MetricsRow::progress("eval", self.step, losses, sc.rate(self.step), sc.wall(self.wall_offset));
                sc.evaluated(&self.run_dir, &mut self.metrics, row, e, control, &*self.agent, self.run.seed)?;
            }
            sc.bar.set_position(self.step);
            if self.step >= next_checkpoint {
                self.save(sc.wall(self.wall_offset))?;
                next_checkpoint = (self.step / checkpoint_every + 1) * checkpoint_every;
            }
        };
        sc.end()?;
        if outcome == Outcome::Finished {
            save_budget_policy(&self.run_dir, self.step, &*self.agent)?;
        }
        let checkpoint = self.save(sc.wall(self.wall_offset))?;
        let summary = sc.summary(&self.run_dir, outcome, self.step, self.best_eval, checkpoint);
        finish_run(&self.metrics, recording, summary)
    }

    /// Steps every copy `num_steps` times with the current policy.
    fn collect(&mut self, sc: &mut Scaffold) -> Result<Rollout> {
        let (n, steps) = (self.settings.num_envs, self.settings.num_steps);
        let gamma = self.cfg().gamma;
        let reward_scale = self.cfg().reward_scale;
        let mut r = Rollout::default();
        let space = self.envs.spec().action_space.clone();
        for _ in 0..steps {
            let x = self.agent.normalize(&self.obs)?;
            let policy = self.agent.policy_step(&x, &mut self.rng)?;
            let env_actions: Vec<Vec<f64>> = policy
                .actions
                .chunks(space.dim())
                .map(|a| to_space(&space, &a.iter().map(|v| v.clamp(-1.0, 1.0)).collect::<Vec<f32>>()))
                .collect();
            let s = self.envs.step(&env_actions)?;
            let before = self.step;
            self.step += n as u64;
            fault::reach(Point::Step);
            // The actor that collected this step is the one at the budget. The run's own budget
            // counts too: it ends on a whole rollout, past a budget that is not a multiple of one.
            let budgets = POLICY_BUDGETS.iter().copied().chain([self.cfg().total_steps]);
            if let Some(budget) = budgets.filter(|&b| before < b && b <= self.step).min() {
                save_budget_policy(&self.run_dir, budget, &*self.agent)?;
            }

            // Observation statistics see every observation once: each ended episode's last,
            // then the observations acted on next.
            let finals: Vec<Vec<f64>> = s.final_observations.iter().flatten().cloned().collect();
            let mut bootstrap = vec![0.0f64; n];
            let truncated: Vec<usize> =
                (0..n).filter(|&i| s.truncated[i] && !s.terminated[i] && !s.infos[i].unstable).collect();
            if !truncated.is_empty() {
                let last: Vec<Vec<f64>> =
                    truncated.iter().map(|&i| s.final_observations[i].clone().expect("an ended episode")).collect();
                let values = self.agent.values(&self.agent.normalize(&last)?)?;
                for (&i, v) in truncated.iter().zip(values) {
                    bootstrap[i] = gamma * v as f64;
                }
            }
            let mut raw_rewards = Vec::with_capacity(n);
            for i in 0..n {
                let fell = s.terminated[i] && !s.infos[i].unstable;
                let reward = scaffold::learner_reward(s.rewards[i], fell, self.cfg()) * reward_scale;
                self.returns[i] = self.returns[i] * gamma * if s.terminated[i] { 0.0 } else { 1.0 } + reward;
                raw_rewards.push(reward);
            }
            let normalise = self.settings.normalize_rewards;
            if normalise {
                self.return_stat.update(&self.returns.chunks(1).collect::<Vec<_>>());
            }
            let scale = if normalise { (self.return_stat.var[0] + RETURN_EPSILON).sqrt() } else { 1.0 };
            let clip = self.settings.clip_rewards;
            r.obs.extend_from_slice(&x);
            r.actions.extend_from_slice(&policy.actions);
            r.log_probs.extend_from_slice(&policy.log_probs);
            r.values.extend_from_slice(&policy.values);
            for i in 0..n {
                let reward = if normalise { (raw_rewards[i] / scale).clamp(-clip, clip) } else { raw_rewards[i] };
                r.rewards.push((reward + bootstrap[i]) as f32);
                r.dones.push(s.terminated[i] || s.truncated[i]);
                r.unstable.push(s.infos[i].unstable);
            }

            for i in 0..n {
                if s.infos[i].unstable {
                    sc.bar.println(format!(
                        "warning: physics unstable at step {} in copy {i}; episode dropped ({:?})",
                        self.step, s.infos[i].warnings
                    ));
                    self.episode_returns[i] = 0.0;
                    self.episode_lengths[i] = 0;
                    self.returns[i] = 0.0;
                    continue;
                }
                self.episode_returns[i] += s.rewards[i];
                self.episode_lengths[i] += 1;
                if s.terminated[i] || s.truncated[i] {
                    self.episodes += 1;
                    self.metrics.push(MetricsRow {
                        episode_return: Some(self.episode_returns[i]),
                        episode_length: Some(self.episode_lengths[i]),
                        ..MetricsRow::progress(
                            "episode",
                            self.step,
                            None,
                            sc.rate(self.step),
                            sc.wall(self.wall_offset),
                        )
                    });
                    if let Some(rec) = &sc.recorder {
                        rec.curves(self.metrics.last().expect("just pushed"))?;
                    }
                    if let Some(e) = sc.events.as_mut() {
                        e.row(self.metrics.last().expect("just pushed"))?;
                    }
                    self.episode_returns[i] = 0.0;
                    self.episode_lengths[i] = 0;
                }
            }
            self.obs = s.observations;
            if !finals.is_empty() {
                self.agent.observe(&finals)?;
            }
            self.agent.observe(&self.obs)?;
        }
        Ok(r)
    }

    /// PPO's update on the rollout, bootstrapped from the values of the observations it ended on.
    fn update(&mut self, r: &Rollout) -> Result<PpoLosses> {
        let next_values = self.agent.values(&self.agent.normalize(&self.obs)?)?;
        let gamma = self.cfg().gamma;
        Ok(update(self.agent.as_mut(), r, &next_values, &self.settings, gamma, &mut self.rng)?)
    }

    fn save(&mut self, wall_time: f64) -> Result<PathBuf> {
        let state = TrainState {
            step: self.step,
            episodes: self.episodes,
            at_episode_boundary: true,
            wall_time,
            rng: RngState::of(&self.rng),
            optimizer_steps: Default::default(),
            counters: Default::default(),
            // Every row's losses come from its own rollout's update: nothing to carry.
            losses: None,
            best_eval_mean: self.best_eval,
            best_policy: None,
        };
        let tensors = self.rollout_state()?;
        checkpoint::save_with(&self.run_dir.clone(), &mut *self.agent, &state, &self.metrics, |dir| {
            candle_core::safetensors::save(&tensors, dir.join(ROLLOUT_FILE))?;
            Ok(())
        })
    }

    /// What a resume needs besides the networks: the copies' snapshot, the reward statistics and
    /// the episode totals in progress.
    fn rollout_state(&self) -> Result<HashMap<String, Tensor>> {
        let snapshot = self.envs.snapshot();
        let cpu = &Device::Cpu;
        let ints = |v: Vec<i64>| Tensor::from_vec(v.clone(), v.len(), cpu);
        let floats = |v: Vec<f64>| Tensor::from_vec(v.clone(), v.len(), cpu);
        let mut out = HashMap::new();
        out.insert("seed".to_string(), ints(vec![snapshot.seed as i64])?);
        out.insert("episodes".to_string(), ints(snapshot.episodes.iter().map(|&e| e as i64).collect())?);
        out.insert("action_lengths".to_string(), ints(snapshot.actions.iter().map(|a| a.len() as i64).collect())?);
        // One extra entry keeps the tensor non-empty when every copy has just reset.
        out.insert("actions".to_string(), floats(snapshot.actions.concat().into_iter().chain([0.0]).collect())?);
        out.insert("returns".to_string(), floats(self.returns.clone())?);
        let s = &self.return_stat;
        out.insert("return_stat".to_string(), floats(vec![s.mean[0], s.var[0], s.count])?);
        out.insert("episode_returns".to_string(), floats(self.episode_returns.clone())?);
        out.insert("episode_lengths".to_string(), ints(self.episode_lengths.iter().map(|&l| l as i64).collect())?);
        Ok(out)
    }

    fn read_rollout_state(&mut self, t: &HashMap<String, Tensor>) -> Result<VecEnvSnapshot> {
        let get = |name: &str| t.get(name).with_context(|| format!("no tensor '{name}'"));
        let ints = |name: &str| -> Result<Vec<i64>> { Ok(get(name)?.to_vec1::<i64>()?) };
        let floats = |name: &str| -> Result<Vec<f64>> { Ok(get(name)?.to_vec1::<f64>()?) };
        let n = self.settings.num_envs;
        let lengths = ints("action_lengths")?;
        let all_actions = floats("actions")?;
        anyhow::ensure!(
            lengths.len() == n && lengths.iter().sum::<i64>() as usize + 1 == all_actions.len(),
            "the saved actions do not fit {n} copies"
        );
        let mut actions = Vec::with_capacity(n);
        let mut at = 0;
        for &len in &lengths {
            actions.push(all_actions[at..at + len as usize].to_vec());
            at += len as usize;
        }
        let episodes: Vec<u64> = ints("episodes")?.into_iter().map(|e| e as u64).collect();
        let returns = floats("returns")?;
        let stat = floats("return_stat")?;
        let episode_returns = floats("episode_returns")?;
        let episode_lengths: Vec<u64> = ints("episode_lengths")?.into_iter().map(|l| l as u64).collect();
        anyhow::ensure!(
            episodes.len() == n
                && returns.len() == n
                && stat.len() == 3
                && episode_returns.len() == n
                && episode_lengths.len() == n,
            "the saved per-copy state does not fit {n} copies"
        );
        self.returns = returns;
        self.return_stat = RunningMeanStd { mean: vec![stat[0]], var: vec![stat[1]], count: stat[2] };
        self.episode_returns = episode_returns;
        self.episode_lengths = episode_lengths;
        Ok(VecEnvSnapshot { seed: ints("seed")?[0] as u64, episodes, actions })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_statistic_matches_the_two_pass_formula() {
        let mut s = RunningMeanStd::new(1);
        s.update(&[&[1.0], &[2.0]]);
        s.update(&[&[4.0]]);
        // The prior counts 1e-4 of a sample with mean 0 and variance 1.
        let count = 3.0 + 1e-4;
        let mean = 7.0 / count;
        let m2 = 1e-4 * (1.0 + mean * mean) + [1.0, 2.0, 4.0].iter().map(|x: &f64| (x - mean).powi(2)).sum::<f64>();
        assert!(
            (s.mean[0] - mean).abs() < 1e-12 && (s.var[0] - m2 / count).abs() < 1e-9 && (s.count - count).abs() < 1e-12
        );
    }

    #[test]
    fn training_seeds_interleave_the_copies_into_the_run_s_training_episodes() {
        assert_eq!(training_seeds(9, 0, 4, 0), train_episode_seed(9, 0));
        assert_eq!(training_seeds(9, 3, 4, 0), train_episode_seed(9, 3));
        assert_eq!(training_seeds(9, 1, 4, 2), train_episode_seed(9, 9));
    }
}
