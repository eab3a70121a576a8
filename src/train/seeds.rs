//! Every random stream of a run, derived from its one seed.
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::agents::config::EvalStarts;

/// SplitMix64 finaliser: turns structured inputs into well-mixed seeds.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Network initialisation.
pub(crate) fn init_rng(run_seed: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(run_seed);
    r.set_stream(1);
    r
}

/// Exploration, warm-up actions, minibatch sampling and the agents' sampling noise.
pub(crate) fn training_rng(run_seed: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(run_seed);
    r.set_stream(2);
    r
}

/// Reset seed of training episode `episode`.
pub(crate) fn train_episode_seed(run_seed: u64, episode: u64) -> u64 {
    mix(mix(run_seed) ^ episode)
}

/// Reset seed of evaluation episode `i` (the same for every evaluation of a run).
pub(crate) fn eval_episode_seed(run_seed: u64, i: u64) -> u64 {
    mix(mix(run_seed ^ 0xE7A1_0000_0000_0000) ^ i)
}

/// Reset seed of episode `i` of the in-training evaluation at `step`, for a run whose evaluations
/// each draw fresh starts: a domain of its own, keyed by the step (no two evaluations of a run
/// share one).
pub(crate) fn fresh_eval_episode_seed(run_seed: u64, step: u64, i: u64) -> u64 {
    mix(mix(mix(run_seed ^ 0xF2E5_0000_0000_0000) ^ step) ^ i)
}

/// Reset seed of episode `i` of run `run_seed`'s in-training evaluation at `step`, under its
/// `eval_starts`.
pub fn evaluation_seed(starts: EvalStarts, run_seed: u64, step: u64, i: u64) -> u64 {
    match starts {
        EvalStarts::Fixed => eval_episode_seed(run_seed, i),
        EvalStarts::Fresh => fresh_eval_episode_seed(run_seed, step, i),
    }
}

/// Reset seed of held-out episode `i` of an evaluation protocol seeded `protocol_seed`: a third
/// domain, apart from every run's training and evaluation episodes (`evaluation::protocol`
/// checks that no run's seeds collide with them).
pub(crate) fn held_out_episode_seed(protocol_seed: u64, i: u64) -> u64 {
    mix(mix(protocol_seed ^ 0x4E1D_0000_0000_0000) ^ i)
}

/// A ChaCha8 stream's position, to save and restore it exactly.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RngState {
    /// The ChaCha8 key.
    pub seed: [u8; 32],
    /// The stream id.
    pub stream: u64,
    /// Word position as a decimal string (u128 does not fit TOML integers).
    pub word_pos: String,
}

impl RngState {
    /// Captures `rng`'s position.
    pub fn of(rng: &ChaCha8Rng) -> RngState {
        RngState { seed: rng.get_seed(), stream: rng.get_stream(), word_pos: rng.get_word_pos().to_string() }
    }
    pub(crate) fn restore(&self) -> anyhow::Result<ChaCha8Rng> {
        let mut r = ChaCha8Rng::from_seed(self.seed);
        r.set_stream(self.stream);
        r.set_word_pos(self.word_pos.parse::<u128>()?);
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresh_evaluation_starts_are_each_evaluations_own_and_fixed_ones_ignore_the_step() {
        let fixed = |step, i| evaluation_seed(EvalStarts::Fixed, 7, step, i);
        let fresh = |step, i| evaluation_seed(EvalStarts::Fresh, 7, step, i);
        assert_eq!(fixed(5000, 3), eval_episode_seed(7, 3));
        assert_eq!(fixed(5000, 3), fixed(10_000, 3));
        let drawn: std::collections::HashSet<u64> = (1..=200)
            .flat_map(|k| (0..20).map(move |i| fresh(k * 5000, i)))
            .chain((0..20).map(|i| fixed(0, i)))
            .collect();
        assert_eq!(drawn.len(), 200 * 20 + 20, "every evaluation's starts are new, and apart from the fixed ones");
        assert_eq!(fresh(5000, 3), fresh(5000, 3));
        assert_ne!(evaluation_seed(EvalStarts::Fresh, 8, 5000, 3), fresh(5000, 3));
    }
}
