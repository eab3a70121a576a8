//! Soft Actor-Critic: Haarnoja et al., "Soft Actor-Critic Algorithms and Applications" (2018,
//! arXiv:1812.05905) for v2, the default, and "Soft Actor-Critic: Off-Policy Maximum Entropy Deep
//! Reinforcement Learning with a Stochastic Actor" (ICML 2018) for v1.
//!
//! One update from a replay minibatch (v2):
//! 1. critics: y = r + gamma (1 - terminated) (min_i Q'_i(s', a') - alpha log pi(a'|s')) with
//!    a' ~ pi(.|s'); both critics regress on y, and their targets follow by Polyak averaging;
//! 2. actor: minimise alpha log pi(a|s) - min_i Q_i(s, a) over a = tanh(mu + sigma eps), the
//!    reparameterised sample of a tanh-squashed Gaussian;
//! 3. temperature: minimise -log(alpha) (log pi(a|s) + target entropy), target entropy -dim(A).
//!
//! v1 learns a state-value network V with its own target network instead of target critics, and
//! keeps the temperature fixed.
//!
//! Defaults are the paper's (and Stable-Baselines3's): 256 x 256, Adam 3e-4 for every network,
//! batch 256, tau 0.005, gamma 0.99. Where this differs: 10k uniformly random warm-up steps (SB3
//! has 100), and the log-density's tanh correction is the exact one (jaxrl's) unless
//! `tanh_correction = "epsilon"` asks for SB3's and CleanRL's `log(1 - a^2 + 1e-6)`.
//!
//! Two of CrossQ's optimiser settings are options, off by default: `policy_delay` (the actor and
//! temperature step on every k-th critic update, as in `araffin/sbx`, `sbx/crossq/crossq.py`) and
//! `adam_beta1`; `tau = 1` gives CrossQ's "no target networks".
//!
//! To read it end to end: this file (settings, the fused CPU agent and its update), then
//! `../common/squashed.rs` (the policy head), `../common/objectives.rs` (targets and losses),
//! `../common/critics.rs` (the twin critics); `device.rs` is the same agent on any candle device.
pub mod device;

use serde::{Deserialize, Serialize};

use candle_core::{Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;

use crate::agents::common::buffer::Batch;
use crate::agents::common::critics::{polyak_update_critics, Critics};
use crate::agents::common::nets::{batch_tensor, polyak_update, scalar_var, Mlp, Output};
use crate::agents::common::objectives::{
    actor_objective, critic_input, soft_value, td_target, temperature, temperature_loss,
};
use crate::agents::common::squashed::{sample_squashed_joint, squashed_mean};
use crate::agents::config::{positive, Algo, SacVersion, TanhCorrection, TrainConfig, WeightInit};
use crate::agents::{layer_sizes, Agent, Losses, OffPolicyAgent};
use crate::numeric::optim::{Adam, Optimizer};

struct ValueNet {
    net: Mlp,
    target: Mlp,
    opt: Adam,
}

/// Soft Actor-Critic, v1 (with a value network) or v2 (twin critics, tuned temperature).
pub struct SacAgent {
    obs_dim: usize,
    act_dim: usize,
    gamma: f64,
    tau: f64,
    actor: Mlp,
    critics: Critics,
    critic_targets: Critics,
    value: Option<ValueNet>,
    log_alpha: Var,
    target_entropy: f64,
    tanh_correction: TanhCorrection,
    actor_opt: Adam,
    critic_opt: Adam,
    alpha_opt: Option<Adam>,
    policy_delay: u64,
    updates: u64,
}

impl SacAgent {
    /// Builds the networks for `obs_dim`/`act_dim`, initialised from `rng`.
    pub fn new(cfg: &TrainConfig, obs_dim: usize, act_dim: usize, rng: &mut ChaCha8Rng) -> Result<Self> {
        let actor = Mlp::new(&layer_sizes(obs_dim, &cfg.hidden, 2 * act_dim), Output::Linear, cfg.weight_init, rng)?;
        if cfg.weight_init == WeightInit::Orthogonal {
            // jaxrl: mean head gain sqrt(2), log-std head gain 1 (`log_std_scale`).
            actor.scale_output_rows(act_dim..2 * act_dim, std::f64::consts::FRAC_1_SQRT_2)?;
        }
        let settings = cfg.sac();
        let critics = Critics::new(2, &layer_sizes(obs_dim + act_dim, &cfg.hidden, 1), cfg.weight_init, rng)?
            .layer_normalised_if(settings.critic_layer_norm)?;
        let critic_targets = critics.deep_copy()?;
        let value = match settings.sac_version {
            SacVersion::V2 => None,
            SacVersion::V1 => {
                let net = Mlp::new(&layer_sizes(obs_dim, &cfg.hidden, 1), Output::Linear, cfg.weight_init, rng)?;
                let target = net.deep_copy()?;
                let opt = Adam::with_beta1(net.params(), settings.value_lr, settings.adam_beta1);
                Some(ValueNet { net, target, opt })
            }
        };
        let log_alpha = scalar_var(settings.initial_alpha.ln() as f32)?;
        let autotune = settings.autotune_alpha && settings.sac_version == SacVersion::V2;
        Ok(SacAgent {
            obs_dim,
            act_dim,
            gamma: cfg.gamma,
            tau: cfg.tau,
            actor_opt: Adam::with_beta1(actor.params(), cfg.actor_lr, settings.adam_beta1),
            critic_opt: Adam::with_beta1(critics.params(), cfg.critic_lr, settings.adam_beta1),
            alpha_opt: autotune
                .then(|| Adam::with_beta1(vec![log_alpha.clone()], settings.alpha_lr, settings.adam_beta1)),
            actor,
            critics,
            critic_targets,
            value,
            log_alpha,
            target_entropy: settings.target_entropy.unwrap_or(-(act_dim as f64)),
            tanh_correction: settings.tanh_correction,
            policy_delay: settings.policy_delay as u64,
            updates: 0,
        })
    }

    /// The current temperature.
    pub fn alpha(&self) -> Result<f64> {
        temperature(&self.log_alpha)
    }

    /// A reparameterised sample, `[n, act_dim + 1]`: tanh(u) and log pi(a|s) side by side, with
    /// eps drawn from `rng`.
    fn sample(&self, obs: &Tensor, rng: &mut ChaCha8Rng) -> Result<Tensor> {
        sample_squashed_joint(&self.actor.forward(obs)?, self.tanh_correction, rng)
    }

    fn critic_input(obs: &Tensor, action: &Tensor) -> Result<Tensor> {
        Tensor::cat(&[obs, action], 1)
    }
}

/// The [`Agent`] methods both versions of SAC share (this file's fused one and `device.rs`'s),
/// written once: both keep their networks, optimisers and counters under the same field names, so
/// a checkpoint names the same things on either path.
macro_rules! sac_glue {
    () => {
        fn algo(&self) -> Algo {
            Algo::Sac
        }

        fn counters(&self) -> Vec<(&'static str, u64)> {
            vec![("updates", self.updates)]
        }

        fn set_counter(&mut self, name: &str, value: u64) {
            if name == "updates" {
                self.updates = value;
            }
        }
    };
}
pub(crate) use sac_glue;

impl Agent for SacAgent {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        squashed_mean(&self.actor.forward(&batch_tensor(obs, 1, self.obs_dim)?)?)
    }

    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        let sample = self.sample(&batch_tensor(obs, 1, self.obs_dim)?, rng)?;
        sample.narrow(1, 0, self.act_dim)?.flatten_all()?.to_vec1::<f32>()
    }

    fn parameters(&self) -> Vec<(String, Var)> {
        let mut out = self.actor.named_vars("actor");
        out.extend(self.critics.named_vars("critics"));
        out.extend(self.critic_targets.named_vars("critics_target"));
        if let Some(v) = &self.value {
            out.extend(v.net.named_vars("value"));
            out.extend(v.target.named_vars("value_target"));
        }
        out.push(("log_alpha".into(), self.log_alpha.clone()));
        out
    }

    fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn Optimizer)> {
        let mut out: Vec<(&str, &mut dyn Optimizer)> =
            vec![("actor_opt", &mut self.actor_opt), ("critic_opt", &mut self.critic_opt)];
        if let Some(o) = &mut self.alpha_opt {
            out.push(("alpha_opt", o));
        }
        if let Some(v) = &mut self.value {
            out.push(("value_opt", &mut v.opt));
        }
        out
    }

    sac_glue!();
}

impl OffPolicyAgent for SacAgent {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let obs = batch_tensor(&batch.obs, n, self.obs_dim)?;
        let actions = batch_tensor(&batch.actions, n, self.act_dim)?;
        let next_obs = batch_tensor(&batch.next_obs, n, self.obs_dim)?;
        let alpha = self.alpha()?;
        let mut losses = Losses::default();

        // Critic target: soft value of the next state, from the target critics (v2) or the
        // target value network (v1).
        let next_value = match &self.value {
            None => {
                let next = self.sample(&next_obs, rng)?;
                soft_value(&self.critic_targets.forward(&critic_input(&next_obs, &next)?)?, &next, alpha)?
            }
            Some(v) => v.target.forward(&next_obs)?.flatten_all()?.to_vec1::<f32>()?,
        };
        let y = td_target(&batch.rewards, &batch.terminated, &next_value, self.gamma)?;
        let critic_loss = self.critics.mse_sum(&Self::critic_input(&obs, &actions)?, &y)?;
        self.critic_opt.step(&critic_loss.backward()?)?;
        losses.critic = critic_loss.to_scalar::<f32>()? as f64;

        // The actor and the temperature on every policy_delay-th update (every one by default).
        if self.updates.is_multiple_of(self.policy_delay) {
            // the action and its log-density side by side, and the objective as two nodes
            // (agents::objectives: the graph's bits without its small nodes)
            let pi = self.sample(&obs, rng)?;
            let logp = pi.narrow(1, self.act_dim, 1)?;
            let q = self.critics.forward_frozen(&critic_input(&obs, &pi)?)?;
            if let Some(v) = &mut self.value {
                let v_target = (q.min(0)? - logp.affine(alpha, 0.0)?)?.detach();
                let value_loss = v.net.forward(&obs)?.sub(&v_target)?.sqr()?.mean_all()?;
                v.opt.step(&value_loss.backward()?)?;
                losses.value = Some(value_loss.to_scalar::<f32>()? as f64);
            }
            let actor_loss = actor_objective(&q, &pi, alpha)?;
            self.actor_opt.step(&actor_loss.backward()?)?;
            losses.actor = Some(actor_loss.to_scalar::<f32>()? as f64);

            if let Some(opt) = &mut self.alpha_opt {
                let alpha_loss = temperature_loss(&self.log_alpha, &logp, self.target_entropy)?;
                opt.step(&alpha_loss.backward()?)?;
                losses.alpha_loss = Some(alpha_loss.to_scalar::<f32>()? as f64);
            }
        }
        losses.alpha = Some(self.alpha()?);

        match &self.value {
            None => {
                polyak_update_critics(&self.critics, &self.critic_targets, self.tau)?;
            }
            Some(v) => polyak_update(&v.net, &v.target, self.tau)?,
        }
        self.updates += 1;
        Ok(losses)
    }
}

/// SAC's own settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SacConfig {
    /// Which SAC variant to train.
    pub sac_version: SacVersion,
    /// Learn the temperature against `target_entropy`; otherwise keep `initial_alpha`.
    pub autotune_alpha: bool,
    /// Temperature at the start (and throughout when not tuned).
    pub initial_alpha: f64,
    /// Adam learning rate of the log-temperature.
    pub alpha_lr: f64,
    /// Target entropy for the temperature; absent means -dim(A).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_entropy: Option<f64>,
    /// SAC v1's value network.
    pub value_lr: f64,
    /// How the log-probability is corrected for the tanh squashing.
    pub tanh_correction: TanhCorrection,
    /// Layer-normalise the critics' hidden layers (`agents::common::critics`). Off unless asked for.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub critic_layer_norm: bool,
    /// Update the actor and the temperature on every `policy_delay`-th critic update (CrossQ's
    /// 3); 1, the default, updates them every time.
    #[serde(default = "SacConfig::no_delay", skip_serializing_if = "SacConfig::is_no_delay")]
    pub policy_delay: u32,
    /// Adam's beta1 for every optimiser (CrossQ's 0.5); 0.9, the default, is Adam's own.
    #[serde(default = "SacConfig::adam_default_beta1", skip_serializing_if = "SacConfig::is_adam_default_beta1")]
    pub adam_beta1: f64,
}

impl SacConfig {
    pub(crate) const KEYS: &'static [&'static str] = &[
        "sac_version",
        "autotune_alpha",
        "initial_alpha",
        "alpha_lr",
        "target_entropy",
        "value_lr",
        "tanh_correction",
        "critic_layer_norm",
        "policy_delay",
        "adam_beta1",
    ];

    fn no_delay() -> u32 {
        1
    }

    fn is_no_delay(delay: &u32) -> bool {
        *delay == 1
    }

    fn adam_default_beta1() -> f64 {
        0.9
    }

    fn is_adam_default_beta1(beta1: &f64) -> bool {
        *beta1 == 0.9
    }

    /// The settings away from their defaults that only the fused CPU agent implements.
    pub(crate) fn cpu_only_settings(&self) -> Vec<&'static str> {
        [
            ("critic_layer_norm", self.critic_layer_norm),
            ("policy_delay", !Self::is_no_delay(&self.policy_delay)),
            ("adam_beta1", !Self::is_adam_default_beta1(&self.adam_beta1)),
        ]
        .into_iter()
        .filter_map(|(name, set)| set.then_some(name))
        .collect()
    }

    /// Checks this section's settings.
    pub(crate) fn validate(&self) -> anyhow::Result<()> {
        positive("alpha_lr", self.alpha_lr)?;
        positive("value_lr", self.value_lr)?;
        positive("initial_alpha", self.initial_alpha)?;
        anyhow::ensure!(self.policy_delay >= 1, "policy_delay must be at least 1, not {}", self.policy_delay);
        anyhow::ensure!(
            (0.0..1.0).contains(&self.adam_beta1),
            "adam_beta1 must lie in [0, 1), not {}",
            self.adam_beta1
        );
        anyhow::ensure!(
            self.policy_delay == 1 || self.sac_version == SacVersion::V2,
            "policy_delay applies to SAC v2 only"
        );
        Ok(())
    }
}

impl TrainConfig {
    /// SAC v2's (Haarnoja et al. 2018b): 256-256, Adam 3e-4, batch 256.
    pub(crate) fn sac_defaults() -> TrainConfig {
        TrainConfig {
            batch_size: 256,
            hidden: vec![256, 256],
            actor_lr: 3e-4,
            critic_lr: 3e-4,
            sac: Some(SacConfig {
                sac_version: SacVersion::V2,
                autotune_alpha: true,
                initial_alpha: 1.0,
                alpha_lr: 3e-4,
                target_entropy: None,
                value_lr: 3e-4,
                tanh_correction: TanhCorrection::Exact,
                critic_layer_norm: false,
                policy_delay: 1,
                adam_beta1: 0.9,
            }),
            ..TrainConfig::shared_defaults(Algo::Sac)
        }
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, D};
    use rand::SeedableRng;

    use super::*;
    use crate::agents::common::squashed::{sample_squashed, squashed_sample, LOG_STD_MAX, LOG_STD_MIN};
    use crate::numeric::second_core;
    use rand_distr::{Distribution, StandardNormal};

    /// The head as candle operations, one node each: the reference the fused node must match.
    fn sample_squashed_graph(out: &Tensor, eps: &Tensor, correction: TanhCorrection) -> (Tensor, Tensor) {
        let act_dim = out.dims()[1] / 2;
        let mean = out.narrow(1, 0, act_dim).unwrap();
        let log_std = out.narrow(1, act_dim, act_dim).unwrap().clamp(LOG_STD_MIN as f32, LOG_STD_MAX as f32).unwrap();
        let u = (mean + (log_std.exp().unwrap() * eps).unwrap()).unwrap();
        let half_log_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
        let gaussian = (eps.sqr().unwrap().affine(-0.5, -half_log_2pi).unwrap() - &log_std).unwrap();
        let squash = match correction {
            TanhCorrection::Exact => {
                // log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)),
                // softplus(x) = max(x, 0) + log(1 + exp(-|x|))
                let minus_2u = u.affine(-2.0, 0.0).unwrap();
                let exp_term = minus_2u.abs().unwrap().neg().unwrap().exp().unwrap();
                let softplus = (minus_2u.relu().unwrap() + exp_term.affine(1.0, 1.0).unwrap().log().unwrap()).unwrap();
                ((u.neg().unwrap() - softplus).unwrap() + 2f64.ln()).unwrap().affine(2.0, 0.0).unwrap()
            }
            TanhCorrection::Epsilon => {
                u.tanh().unwrap().sqr().unwrap().affine(-1.0, 1.0 + 1e-6).unwrap().log().unwrap()
            }
        };
        let log_prob = (gaussian - squash).unwrap().sum_keepdim(D::Minus1).unwrap();
        (u.tanh().unwrap(), log_prob)
    }

    fn tensor(v: &[f32], shape: (usize, usize)) -> Tensor {
        Tensor::from_vec(v.to_vec(), shape, &Device::Cpu).unwrap()
    }

    fn flat(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    }

    /// Policy outputs that reach every branch: clamp ties and both sides of the clamp, means far
    /// in tanh's tails and at zero, signed zeros.
    fn policy_output(n: usize, act_dim: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
        let special = [-20.0, 2.0, -25.0, 3.5, 0.0, -0.0, 30.0, -30.0, 9.0, -9.0];
        (0..n * 2 * act_dim)
            .map(|i| {
                let x: f32 = StandardNormal.sample(rng);
                if i % 7 == 3 {
                    special[(i / 7) % special.len()]
                } else {
                    2.0 * x
                }
            })
            .collect()
    }

    /// SAC's actor loss, mean(alpha * log pi - Q(s, tanh(u))), through the head built by `head`;
    /// returns the action, the log-density and the gradient of the policy output.
    fn actor_loss_through(
        out: &[f32],
        n: usize,
        act_dim: usize,
        head: impl Fn(&Tensor) -> (Tensor, Tensor),
    ) -> [Vec<f32>; 3] {
        let out = Var::from_tensor(&tensor(out, (n, 2 * act_dim))).unwrap();
        let obs = tensor(&(0..n * 3).map(|i| (i as f32 * 0.31).sin()).collect::<Vec<_>>(), (n, 3));
        let critic =
            tensor(&(0..n * (3 + act_dim)).map(|i| (i as f32 * 0.17).cos()).collect::<Vec<_>>(), (n, 3 + act_dim));
        let (action, log_prob) = head(out.as_tensor());
        let q = (Tensor::cat(&[&obs, &action], 1).unwrap() * &critic).unwrap().sum_keepdim(1).unwrap();
        let loss = (log_prob.affine(0.2, 0.0).unwrap() - q).unwrap().mean_all().unwrap();
        let grads = loss.backward().unwrap();
        [flat(&action), flat(&log_prob), flat(grads.get(out.as_tensor()).unwrap())]
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// The fused head gives candle's graph's action, log-density and gradient bit for bit, both
    /// corrections, in one piece and in halves on two threads.
    #[test]
    fn the_fused_head_gives_the_bits_of_candles_graph() {
        second_core::with_and_without_helper(|helper| {
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            for (n, act_dim) in [(1, 6), (5, 3), (256, 6), (77, 17)] {
                for correction in [TanhCorrection::Exact, TanhCorrection::Epsilon] {
                    let out = policy_output(n, act_dim, &mut rng);
                    let eps: Vec<f32> = (0..n * act_dim).map(|_| StandardNormal.sample(&mut rng)).collect();
                    let eps_tensor = tensor(&eps, (n, act_dim));
                    let graph =
                        actor_loss_through(&out, n, act_dim, |o| sample_squashed_graph(o, &eps_tensor, correction));
                    let fused = actor_loss_through(&out, n, act_dim, |o| {
                        let y = squashed_sample(o, eps.clone(), (LOG_STD_MIN as f32, LOG_STD_MAX as f32), correction)
                            .unwrap();
                        (y.narrow(1, 0, act_dim).unwrap(), y.narrow(1, act_dim, 1).unwrap())
                    });
                    for (what, (g, f)) in ["action", "log-density", "gradient"].iter().zip(graph.iter().zip(&fused)) {
                        assert_eq!(
                            bits(g),
                            bits(f),
                            "{what}: n {n}, act_dim {act_dim}, {correction:?}, helper {helper}"
                        );
                    }
                    assert!(fused[2].iter().all(|g| g.is_finite()));
                }
            }
        });
    }

    /// SAC's actor loss and its gradient at the policy output, through candle's graph (the head's
    /// output narrowed, `cat`, `min`, `affine`, `mean_all`) and through `actor_objective`'s two
    /// nodes, from the same noise.
    fn actor_objective_both_ways(
        out: &[f32],
        obs: &[f32],
        n: usize,
        act_dim: usize,
        critics: &Critics,
        correction: TanhCorrection,
    ) -> [[Vec<f32>; 2]; 2] {
        let obs_dim = obs.len() / n;
        let obs = tensor(obs, (n, obs_dim));
        let alpha = 0.37;
        let run = |fused: bool| {
            let out = Var::from_tensor(&tensor(out, (n, 2 * act_dim))).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(9);
            let loss = if fused {
                let pi = sample_squashed_joint(out.as_tensor(), correction, &mut rng).unwrap();
                let q = critics.forward_frozen(&critic_input(&obs, &pi).unwrap()).unwrap();
                actor_objective(&q, &pi, alpha).unwrap()
            } else {
                let (pi_a, logp) = sample_squashed(out.as_tensor(), correction, &mut rng).unwrap();
                let q_pi = critics.min_frozen(&Tensor::cat(&[&obs, &pi_a], 1).unwrap()).unwrap();
                (logp.affine(alpha, 0.0).unwrap() - q_pi).unwrap().mean_all().unwrap()
            };
            let grads = loss.backward().unwrap();
            [vec![loss.to_scalar::<f32>().unwrap()], flat(grads.get(out.as_tensor()).unwrap())]
        };
        [run(false), run(true)]
    }

    #[test]
    fn the_actor_objective_gives_the_bits_of_candles_graph() {
        second_core::with_and_without_helper(|helper| {
            let mut rng = ChaCha8Rng::seed_from_u64(6);
            for (n, obs_dim, act_dim) in [(1, 3, 2), (5, 4, 3), (256, 17, 6)] {
                for twins in [false, true] {
                    let sizes = [obs_dim + act_dim, 32, 32, 1];
                    let critics = Critics::new(2, &sizes, WeightInit::Uniform, &mut rng).unwrap();
                    if twins {
                        // equal members: every row's minimum is a tie, whose gradient both get
                        for (w, b) in critics.named_vars("c").chunks(2).map(|p| (&p[0].1, &p[1].1)) {
                            let w0 = w.as_tensor().narrow(0, 0, 1).unwrap();
                            let b0 = b.as_tensor().narrow(0, 0, 1).unwrap();
                            w.set(&Tensor::cat(&[&w0, &w0], 0).unwrap()).unwrap();
                            b.set(&Tensor::cat(&[&b0, &b0], 0).unwrap()).unwrap();
                        }
                    }
                    for correction in [TanhCorrection::Exact, TanhCorrection::Epsilon] {
                        let out = policy_output(n, act_dim, &mut rng);
                        let obs: Vec<f32> = (0..n * obs_dim).map(|_| StandardNormal.sample(&mut rng)).collect();
                        let [graph, fused] = actor_objective_both_ways(&out, &obs, n, act_dim, &critics, correction);
                        for (what, (g, f)) in ["loss", "gradient"].iter().zip(graph.iter().zip(&fused)) {
                            assert_eq!(
                                bits(g),
                                bits(f),
                                "{what}: n {n}, act_dim {act_dim}, twins {twins}, {correction:?}, helper {helper}"
                            );
                        }
                        assert!(fused[1].iter().any(|g| *g != 0.0));
                    }
                }
            }
        });
    }

    #[test]
    fn the_actor_objective_refuses_mismatched_shapes() {
        let q = Tensor::zeros((2, 4, 1), candle_core::DType::F32, &Device::Cpu).unwrap();
        let y = Tensor::zeros((3, 7), candle_core::DType::F32, &Device::Cpu).unwrap();
        let err = actor_objective(&q, &y, 0.2).unwrap_err().to_string();
        assert!(err.contains("[3, 7]"), "{err}");
        let obs = Tensor::zeros((4, 5), candle_core::DType::F32, &Device::Cpu).unwrap();
        let err = critic_input(&obs, &y).unwrap_err().to_string();
        assert!(err.contains("4 observations"), "{err}");
    }

    #[test]
    fn squashed_log_prob_matches_the_closed_form() {
        // Closed form per dimension: log N(u; m, s) - log(1 - tanh(u)^2).
        let (m, s) = ([0.3f64, -1.2, 2.5], [0.5f64, 1.3, 0.05]);
        let eps = [0.7f64, -1.9, 2.2];
        let u: Vec<f64> = (0..3).map(|i| m[i] + s[i] * eps[i]).collect();
        let expected: f64 = (0..3)
            .map(|i| {
                let z = (u[i] - m[i]) / s[i];
                let log_n = -0.5 * z * z - s[i].ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
                log_n - (1.0 - u[i].tanh().powi(2)).ln()
            })
            .sum();
        let out: Vec<f32> = m.iter().map(|x| *x as f32).chain(s.iter().map(|x| x.ln() as f32)).collect();
        let eps32: Vec<f32> = eps.iter().map(|x| *x as f32).collect();
        let range = (LOG_STD_MIN as f32, LOG_STD_MAX as f32);
        let sample = |out: &[f32], correction| {
            flat(&squashed_sample(&tensor(out, (1, out.len())), eps32.clone(), range, correction).unwrap())
        };
        let exact = sample(&out, TanhCorrection::Exact);
        for i in 0..3 {
            assert!((exact[i] as f64 - u[i].tanh()).abs() < 1e-6, "{exact:?}");
        }
        assert!((exact[3] as f64 - expected).abs() < 1e-4, "{} vs {expected}", exact[3]);
        // Away from saturation the epsilon form differs from the exact one by about 1e-6 / (1 - a^2).
        let epsilon = sample(&out, TanhCorrection::Epsilon);
        assert!((epsilon[3] - exact[3]).abs() < 1e-3, "{epsilon:?} vs {exact:?}");
        // Far in the tails (u = +-30, std e^-20) the naive formula overflows; the stable one does
        // not. Saturated in f32, the epsilon form stops at log(1e-6) per dimension.
        let tails = [30.0f32, -30.0, 0.0, -20.0, -20.0, -20.0];
        let exact = sample(&tails, TanhCorrection::Exact);
        assert!(exact.iter().all(|v| v.is_finite()), "{exact:?}");
        let gaussian: f64 = eps.iter().map(|e| -0.5 * e * e + 20.0 - 0.5 * (2.0 * std::f64::consts::PI).ln()).sum();
        let squash = 2.0 * (4f64.ln() - 60.0);
        assert!((exact[3] as f64 - (gaussian - squash)).abs() < 1e-2, "{} vs {}", exact[3], gaussian - squash);
        let capped = sample(&tails, TanhCorrection::Epsilon);
        let squash = 2.0 * 1e-6f64.ln();
        assert!((capped[3] as f64 - (gaussian - squash)).abs() < 0.1, "{} vs {}", capped[3], gaussian - squash);
    }

    /// With `policy_delay = 3` the actor and the temperature move on updates 0, 3, 6, ... and hold
    /// in between, while the critics move on every update; every optimiser takes `adam_beta1`.
    #[test]
    fn a_delayed_actor_moves_on_every_third_update_only() {
        let mut cfg = TrainConfig::sac_defaults();
        cfg.hidden = vec![16, 16];
        cfg.batch_size = 8;
        let settings = cfg.sac.as_mut().unwrap();
        settings.policy_delay = 3;
        settings.adam_beta1 = 0.5;
        cfg.validate().unwrap();
        let (obs_dim, act_dim, n) = (5, 2, 8);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut agent = SacAgent::new(&cfg, obs_dim, act_dim, &mut rng).unwrap();
        assert!([&agent.actor_opt, &agent.critic_opt, agent.alpha_opt.as_ref().unwrap()]
            .iter()
            .all(|o| o.beta1 == 0.5));
        let mut batch = Batch::new(n, obs_dim, act_dim);
        let mut normal = |len| (0..len).map(|_| StandardNormal.sample(&mut rng)).collect::<Vec<f32>>();
        batch.obs = normal(n * obs_dim);
        batch.actions = normal(n * act_dim).iter().map(|a| a.tanh()).collect();
        batch.rewards = normal(n);
        batch.next_obs = normal(n * obs_dim);
        batch.terminated = vec![0.0; n];
        let actor =
            |a: &SacAgent| a.actor.named_vars("a").iter().flat_map(|(_, v)| flat(v.as_tensor())).collect::<Vec<_>>();
        let critics =
            |a: &SacAgent| a.critics.named_vars("c").iter().flat_map(|(_, v)| flat(v.as_tensor())).collect::<Vec<_>>();
        let mut update_rng = ChaCha8Rng::seed_from_u64(5);
        for k in 0..7u64 {
            let (a0, c0, alpha0) = (actor(&agent), critics(&agent), agent.alpha().unwrap());
            let losses = agent.update(&batch, &mut update_rng).unwrap();
            let moved = actor(&agent) != a0;
            assert_eq!(moved, k % 3 == 0, "update {k}: actor moved {moved}");
            assert_eq!(agent.alpha().unwrap() != alpha0, k % 3 == 0, "update {k}: temperature");
            assert_eq!(losses.actor.is_some(), k % 3 == 0, "update {k}: actor loss");
            assert_ne!(critics(&agent), c0, "update {k}: critics");
        }
    }

    #[test]
    fn sac_settings_out_of_range_are_refused_by_name() {
        for (key, value, says) in [
            ("policy_delay", toml::Value::Integer(0), "policy_delay must be at least 1"),
            ("adam_beta1", toml::Value::Float(1.0), "adam_beta1 must lie in [0, 1)"),
        ] {
            let mut t = toml::Table::new();
            t.insert("algo".into(), "sac".into());
            t.insert(key.into(), value);
            let err = TrainConfig::from_table(&t, crate::agents::config::OtherAlgorithmKeys::Refuse)
                .and_then(|c| c.validate().map(|_| c))
                .unwrap_err();
            assert!(format!("{err:#}").contains(says), "{key}: {err:#}");
        }
        let mut t = toml::Table::new();
        t.insert("algo".into(), "sac".into());
        t.insert("sac_version".into(), "v1".into());
        t.insert("policy_delay".into(), 2.into());
        let err = TrainConfig::from_table(&t, crate::agents::config::OtherAlgorithmKeys::Refuse)
            .and_then(|c| c.validate().map(|_| c))
            .unwrap_err();
        assert!(format!("{err:#}").contains("policy_delay applies to SAC v2 only"), "{err:#}");
        let defaults = toml::to_string(&TrainConfig::sac_defaults()).unwrap();
        assert!(!defaults.contains("policy_delay") && !defaults.contains("adam_beta1"), "{defaults}");
        assert!(TrainConfig::sac_defaults().sac().cpu_only_settings().is_empty());
        let mut delayed = TrainConfig::sac_defaults();
        delayed.sac.as_mut().unwrap().policy_delay = 3;
        assert_eq!(delayed.sac().cpu_only_settings(), ["policy_delay"]);
    }

    #[test]
    fn a_malformed_policy_output_or_noise_is_an_error() {
        let out = tensor(&[0.0; 6], (1, 6));
        let range = (LOG_STD_MIN as f32, LOG_STD_MAX as f32);
        assert!(squashed_sample(&out, vec![0.0; 2], range, TanhCorrection::Exact).is_err());
        let odd = tensor(&[0.0; 5], (1, 5));
        assert!(squashed_sample(&odd, vec![0.0; 2], range, TanhCorrection::Exact).is_err());
    }
}
