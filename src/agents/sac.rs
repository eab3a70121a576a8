//! Soft Actor-Critic. v2 (Haarnoja et al. 2018b, the default): tanh-squashed Gaussian policy,
//! twin critics with target networks, automatic temperature towards entropy -dim(A). v1
//! (2018a): a separate state-value network with its own target network and a fixed temperature.
use candle_core::{Device, Result, Tensor, Var, D};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::buffer::Batch;
use super::config::{Algo, SacVersion, TanhCorrection, TrainConfig, WeightInit};
use super::critics::{polyak_update_critics, Critics};
use super::nets::{batch_tensor, polyak_update, scalar_var, Mlp, Output};
use super::{layer_sizes, Agent, Losses};
use crate::numeric::optim::Adam;

/// The policy's log-std is clamped to this range (SAC's and CrossQ's).
pub(crate) const LOG_STD_MIN: f64 = -20.0;
pub(crate) const LOG_STD_MAX: f64 = 2.0;

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
    updates: u64,
}

/// log(1 - tanh(u)^2), computed stably as 2 (log 2 - u - softplus(-2u)).
pub(crate) fn log_one_minus_tanh_sq(u: &Tensor) -> Result<Tensor> {
    let minus_2u = u.affine(-2.0, 0.0)?;
    // softplus(x) = max(x, 0) + log(1 + exp(-|x|))
    let softplus = (minus_2u.relu()? + minus_2u.abs()?.neg()?.exp()?.affine(1.0, 1.0)?.log()?)?;
    ((u.neg()? - softplus)? + 2f64.ln())?.affine(2.0, 0.0)
}

/// Stable-Baselines3's and CleanRL's log(1 - a^2 + 1e-6), a = tanh(u).
pub(crate) fn log_one_minus_sq_plus_epsilon(a: &Tensor) -> Result<Tensor> {
    a.sqr()?.affine(-1.0, 1.0 + 1e-6)?.log()
}

/// Log-density of a = tanh(u), u = mean + std * eps, summed over action dimensions.
pub(crate) fn squashed_gaussian_log_prob(
    u: &Tensor,
    eps: &Tensor,
    log_std: &Tensor,
    correction: TanhCorrection,
) -> Result<Tensor> {
    let half_log_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
    let gaussian = ((eps.sqr()?.affine(-0.5, -half_log_2pi))? - log_std)?;
    let squash = match correction {
        TanhCorrection::Exact => log_one_minus_tanh_sq(u)?,
        TanhCorrection::Epsilon => log_one_minus_sq_plus_epsilon(&u.tanh()?)?,
    };
    (gaussian - squash)?.sum_keepdim(D::Minus1)
}

/// A reparameterised sample of the squashed Gaussian with `mean` and `log_std` (`[n, act_dim]`):
/// (tanh(u), log pi(a|s)) with eps drawn from `rng`. SAC's and CrossQ's policy.
pub(crate) fn sample_squashed(
    mean: Tensor,
    log_std: &Tensor,
    correction: TanhCorrection,
    rng: &mut ChaCha8Rng,
) -> Result<(Tensor, Tensor)> {
    let (n, act_dim) = mean.dims2()?;
    let eps: Vec<f32> = (0..n * act_dim).map(|_| StandardNormal.sample(rng)).collect();
    let eps = Tensor::from_vec(eps, (n, act_dim), &Device::Cpu)?;
    let u = (mean + (log_std.exp()? * &eps)?)?;
    let log_prob = squashed_gaussian_log_prob(&u, &eps, log_std, correction)?;
    Ok((u.tanh()?, log_prob))
}

/// The temperature exp(log_alpha).
pub(crate) fn temperature(log_alpha: &Var) -> Result<f64> {
    Ok(log_alpha.as_tensor().exp()?.flatten_all()?.to_vec1::<f32>()?[0] as f64)
}

/// The temperature's loss, -log_alpha (log pi + target entropy), averaged over the batch.
pub(crate) fn temperature_loss(log_alpha: &Var, log_prob: &Tensor, target_entropy: f64) -> Result<Tensor> {
    let gap = log_prob.detach().affine(1.0, target_entropy)?;
    log_alpha.as_tensor().broadcast_mul(&gap)?.mean_all()?.neg()
}

impl SacAgent {
    /// Builds the networks for `obs_dim`/`act_dim`, initialised from `rng`.
    pub fn new(cfg: &TrainConfig, obs_dim: usize, act_dim: usize, rng: &mut ChaCha8Rng) -> Result<Self> {
        let actor = Mlp::new(&layer_sizes(obs_dim, &cfg.hidden, 2 * act_dim), Output::Linear, cfg.weight_init, rng)?;
        if cfg.weight_init == WeightInit::Orthogonal {
            // jaxrl: mean head gain sqrt(2), log-std head gain 1 (`log_std_scale`).
            actor.scale_output_rows(act_dim..2 * act_dim, std::f64::consts::FRAC_1_SQRT_2)?;
        }
        let critics = Critics::new(2, &layer_sizes(obs_dim + act_dim, &cfg.hidden, 1), cfg.weight_init, rng)?;
        let critic_targets = critics.deep_copy()?;
        let settings = cfg.sac();
        let value = match settings.sac_version {
            SacVersion::V2 => None,
            SacVersion::V1 => {
                let net = Mlp::new(&layer_sizes(obs_dim, &cfg.hidden, 1), Output::Linear, cfg.weight_init, rng)?;
                let target = net.deep_copy()?;
                let opt = Adam::new(net.params(), settings.value_lr);
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
            actor_opt: Adam::new(actor.params(), cfg.actor_lr),
            critic_opt: Adam::new(critics.params(), cfg.critic_lr),
            alpha_opt: autotune.then(|| Adam::new(vec![log_alpha.clone()], settings.alpha_lr)),
            actor,
            critics,
            critic_targets,
            value,
            log_alpha,
            target_entropy: settings.target_entropy.unwrap_or(-(act_dim as f64)),
            tanh_correction: settings.tanh_correction,
            updates: 0,
        })
    }

    /// The current temperature.
    pub fn alpha(&self) -> Result<f64> {
        temperature(&self.log_alpha)
    }

    fn mean_log_std(&self, obs: &Tensor) -> Result<(Tensor, Tensor)> {
        let out = self.actor.forward(obs)?;
        let mean = out.narrow(1, 0, self.act_dim)?;
        let log_std = out.narrow(1, self.act_dim, self.act_dim)?.clamp(LOG_STD_MIN as f32, LOG_STD_MAX as f32)?;
        Ok((mean, log_std))
    }

    /// A reparameterised sample: (tanh(u), log pi(a|s)) with eps drawn from `rng`.
    fn sample(&self, obs: &Tensor, rng: &mut ChaCha8Rng) -> Result<(Tensor, Tensor)> {
        let (mean, log_std) = self.mean_log_std(obs)?;
        sample_squashed(mean, &log_std, self.tanh_correction, rng)
    }

    fn critic_input(obs: &Tensor, action: &Tensor) -> Result<Tensor> {
        Tensor::cat(&[obs, action], 1)
    }
}

impl Agent for SacAgent {
    fn algo(&self) -> Algo {
        Algo::Sac
    }

    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let (mean, _) = self.mean_log_std(&batch_tensor(obs, 1, self.obs_dim)?)?;
        mean.tanh()?.flatten_all()?.to_vec1::<f32>()
    }

    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        let (a, _) = self.sample(&batch_tensor(obs, 1, self.obs_dim)?, rng)?;
        a.flatten_all()?.to_vec1::<f32>()
    }

    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let obs = batch_tensor(&batch.obs, n, self.obs_dim)?;
        let actions = batch_tensor(&batch.actions, n, self.act_dim)?;
        let next_obs = batch_tensor(&batch.next_obs, n, self.obs_dim)?;
        let rewards = batch_tensor(&batch.rewards, n, 1)?;
        let not_done = batch_tensor(&batch.terminated, n, 1)?.affine(-1.0, 1.0)?;
        let alpha = self.alpha()?;
        let mut losses = Losses::default();

        // Critic target: soft value of the next state, from the target critics (v2) or the
        // target value network (v1).
        let next_value = match &self.value {
            None => {
                let (next_a, next_logp) = self.sample(&next_obs, rng)?;
                (self.critic_targets.min(&Self::critic_input(&next_obs, &next_a)?)? - next_logp.affine(alpha, 0.0)?)?
            }
            Some(v) => v.target.forward(&next_obs)?,
        };
        let y = (rewards + (not_done * next_value)?.affine(self.gamma, 0.0)?)?.detach();
        let critic_loss = self.critics.mse_sum(&Self::critic_input(&obs, &actions)?, &y)?;
        self.critic_opt.step(&critic_loss.backward()?)?;
        losses.critic = critic_loss.to_scalar::<f32>()? as f64;

        let (pi_a, logp) = self.sample(&obs, rng)?;
        let q_pi = self.critics.min_frozen(&Self::critic_input(&obs, &pi_a)?)?;
        if let Some(v) = &mut self.value {
            let v_target = (&q_pi - logp.affine(alpha, 0.0)?)?.detach();
            let value_loss = v.net.forward(&obs)?.sub(&v_target)?.sqr()?.mean_all()?;
            v.opt.step(&value_loss.backward()?)?;
            losses.value = Some(value_loss.to_scalar::<f32>()? as f64);
        }
        let actor_loss = (logp.affine(alpha, 0.0)? - q_pi)?.mean_all()?;
        self.actor_opt.step(&actor_loss.backward()?)?;
        losses.actor = Some(actor_loss.to_scalar::<f32>()? as f64);

        if let Some(opt) = &mut self.alpha_opt {
            let alpha_loss = temperature_loss(&self.log_alpha, &logp, self.target_entropy)?;
            opt.step(&alpha_loss.backward()?)?;
            losses.alpha_loss = Some(alpha_loss.to_scalar::<f32>()? as f64);
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

    fn optimizers(&mut self) -> Vec<(&'static str, &mut Adam)> {
        let mut out = vec![("actor_opt", &mut self.actor_opt), ("critic_opt", &mut self.critic_opt)];
        if let Some(o) = &mut self.alpha_opt {
            out.push(("alpha_opt", o));
        }
        if let Some(v) = &mut self.value {
            out.push(("value_opt", &mut v.opt));
        }
        out
    }

    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![("updates", self.updates)]
    }

    fn set_counter(&mut self, name: &str, value: u64) {
        if name == "updates" {
            self.updates = value;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let t = |v: &[f64]| {
            Tensor::from_vec(v.iter().map(|x| *x as f32).collect::<Vec<_>>(), (1, 3), &Device::Cpu).unwrap()
        };
        let log_std: Vec<f64> = s.iter().map(|x| x.ln()).collect();
        let got = squashed_gaussian_log_prob(&t(&u), &t(&eps), &t(&log_std), TanhCorrection::Exact)
            .unwrap()
            .to_vec2::<f32>()
            .unwrap()[0][0];
        assert!((got as f64 - expected).abs() < 1e-4, "{got} vs {expected}");
        // Away from saturation the epsilon form differs from the exact one by about 1e-6 / (1 - a^2).
        let eps_form = squashed_gaussian_log_prob(&t(&u), &t(&eps), &t(&log_std), TanhCorrection::Epsilon)
            .unwrap()
            .to_vec2::<f32>()
            .unwrap()[0][0];
        assert!((eps_form - got).abs() < 1e-3, "{eps_form} vs {got}");
        // Far in the tails the naive formula overflows; the stable one does not.
        let big = log_one_minus_tanh_sq(&t(&[30.0, -30.0, 0.0])).unwrap().to_vec2::<f32>().unwrap();
        assert!(big[0].iter().all(|v| v.is_finite()));
        assert!((big[0][0] as f64 - (4f64.ln() - 60.0)).abs() < 1e-3);
        // Saturated in f32, the epsilon form stops at log(1e-6) where the exact one goes on.
        let a = t(&[30.0, -30.0, 0.0]).tanh().unwrap();
        let capped = log_one_minus_sq_plus_epsilon(&a).unwrap().to_vec2::<f32>().unwrap();
        assert!((capped[0][0] as f64 - 1e-6f64.ln()).abs() < 0.05, "{:?}", capped);
        assert!(capped[0][2].abs() < 1e-5);
    }
}
