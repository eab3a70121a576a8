//! Replay buffer: preallocated contiguous f32 storage, uniform sampling from the caller's RNG.
//!
//! Layout: each observation is stored once. The next observation of transition `i` is the
//! observation of transition `i + 1`, except where an episode ended (or the caller passed a
//! next observation that is not the following observation): those few are kept in a side table.
//! Terminated and truncated are stored separately: learners bootstrap through truncation, never
//! through termination.
use std::collections::HashMap;

use rand::Rng;

use crate::numeric::second_core;

const TERMINATED: u8 = 1;
const TRUNCATED: u8 = 2;

/// A fixed-capacity ring of transitions that overwrites the oldest once full.
pub struct ReplayBuffer {
    capacity: usize,
    obs_dim: usize,
    act_dim: usize,
    obs: Vec<f32>,
    actions: Vec<f32>,
    rewards: Vec<f32>,
    flags: Vec<u8>,
    /// Next observations that are not the following slot's observation.
    side_next: HashMap<usize, Vec<f32>>,
    /// The newest transition's next observation (its slot's successor is not written yet).
    newest_next: Vec<f32>,
    write: usize,
    len: usize,
}

/// Batches at least this large are copied in two halves.
const SPLIT_ROWS: usize = 64;

/// Consecutive rows of a [`Batch`], borrowed for filling.
struct BatchRows<'a> {
    obs: &'a mut [f32],
    actions: &'a mut [f32],
    rewards: &'a mut [f32],
    next_obs: &'a mut [f32],
    terminated: &'a mut [f32],
}

impl<'a> BatchRows<'a> {
    /// Rows before `row` and rows from it on.
    fn split_at(self, row: usize, obs_dim: usize, act_dim: usize) -> (BatchRows<'a>, BatchRows<'a>) {
        let (obs_a, obs_z) = self.obs.split_at_mut(row * obs_dim);
        let (actions_a, actions_z) = self.actions.split_at_mut(row * act_dim);
        let (rewards_a, rewards_z) = self.rewards.split_at_mut(row);
        let (next_a, next_z) = self.next_obs.split_at_mut(row * obs_dim);
        let (terminated_a, terminated_z) = self.terminated.split_at_mut(row);
        (
            BatchRows {
                obs: obs_a,
                actions: actions_a,
                rewards: rewards_a,
                next_obs: next_a,
                terminated: terminated_a,
            },
            BatchRows {
                obs: obs_z,
                actions: actions_z,
                rewards: rewards_z,
                next_obs: next_z,
                terminated: terminated_z,
            },
        )
    }
}

/// A sampled minibatch, row-major, reused between samples (no per-sample allocation).
#[derive(Debug, Clone, Default)]
pub struct Batch {
    /// Rows in the batch.
    pub size: usize,
    /// Observations, `size × obs_dim`.
    pub obs: Vec<f32>,
    /// Actions, `size × act_dim`.
    pub actions: Vec<f32>,
    /// Rewards as stored (already multiplied by the run's reward scale).
    pub rewards: Vec<f32>,
    /// Next observations, `size × obs_dim`.
    pub next_obs: Vec<f32>,
    /// 1.0 where the transition terminated (no bootstrap), else 0.0.
    pub terminated: Vec<f32>,
}

impl Batch {
    /// A zeroed batch of `size` rows for the given observation and action sizes.
    pub fn new(size: usize, obs_dim: usize, act_dim: usize) -> Batch {
        Batch {
            size,
            obs: vec![0.0; size * obs_dim],
            actions: vec![0.0; size * act_dim],
            rewards: vec![0.0; size],
            next_obs: vec![0.0; size * obs_dim],
            terminated: vec![0.0; size],
        }
    }
}

impl ReplayBuffer {
    /// An empty buffer with room for `capacity` transitions; panics on a zero capacity.
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> ReplayBuffer {
        assert!(capacity > 0);
        ReplayBuffer {
            capacity,
            obs_dim,
            act_dim,
            obs: vec![0.0; capacity * obs_dim],
            actions: vec![0.0; capacity * act_dim],
            rewards: vec![0.0; capacity],
            flags: vec![0; capacity],
            side_next: HashMap::new(),
            newest_next: vec![0.0; obs_dim],
            write: 0,
            len: 0,
        }
    }

    /// Transitions stored (at most the capacity).
    pub fn len(&self) -> usize {
        self.len
    }
    /// Whether no transition is stored yet.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// The most transitions the buffer holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }
    pub(crate) fn dims(&self) -> (usize, usize) {
        (self.obs_dim, self.act_dim)
    }

    /// Bytes of preallocated storage per transition (the side table adds one observation per
    /// episode end on top).
    pub fn bytes_per_transition(&self) -> usize {
        4 * (self.obs_dim + self.act_dim + 1) + 1
    }

    fn newest(&self) -> Option<usize> {
        (self.len > 0).then(|| (self.write + self.capacity - 1) % self.capacity)
    }

    /// Stores one transition, overwriting the oldest when the buffer is full.
    pub fn add(
        &mut self,
        obs: &[f32],
        action: &[f32],
        reward: f32,
        next_obs: &[f32],
        terminated: bool,
        truncated: bool,
    ) {
        assert_eq!(obs.len(), self.obs_dim);
        assert_eq!(next_obs.len(), self.obs_dim);
        assert_eq!(action.len(), self.act_dim);
        if let Some(prev) = self.newest() {
            let ended = self.flags[prev] != 0;
            if !ended && self.newest_next.as_slice() != obs {
                self.side_next.insert(prev, self.newest_next.clone());
            }
        }
        let i = self.write;
        self.side_next.remove(&i);
        self.obs[i * self.obs_dim..(i + 1) * self.obs_dim].copy_from_slice(obs);
        self.actions[i * self.act_dim..(i + 1) * self.act_dim].copy_from_slice(action);
        self.rewards[i] = reward;
        self.flags[i] = ((terminated as u8) * TERMINATED) | ((truncated as u8) * TRUNCATED);
        if truncated && !terminated {
            self.side_next.insert(i, next_obs.to_vec());
        }
        self.newest_next.copy_from_slice(next_obs);
        self.write = (self.write + 1) % self.capacity;
        self.len = (self.len + 1).min(self.capacity);
    }

    /// The next observation of transition `i` (for a terminated one, any finite vector: it is
    /// never bootstrapped; the transition's own observation is used).
    pub fn next_obs(&self, i: usize) -> &[f32] {
        if let Some(v) = self.side_next.get(&i) {
            return v;
        }
        if self.flags[i] & TERMINATED != 0 {
            return &self.obs[i * self.obs_dim..(i + 1) * self.obs_dim];
        }
        if Some(i) == self.newest() {
            return &self.newest_next;
        }
        let j = (i + 1) % self.capacity;
        &self.obs[j * self.obs_dim..(j + 1) * self.obs_dim]
    }

    /// Whether transition `i` ended its episode in a terminal state.
    pub fn terminated(&self, i: usize) -> bool {
        self.flags[i] & TERMINATED != 0
    }
    /// Whether transition `i` was cut short (time limit or instability).
    pub fn truncated(&self, i: usize) -> bool {
        self.flags[i] & TRUNCATED != 0
    }
    /// The observation of transition `i`.
    pub fn obs(&self, i: usize) -> &[f32] {
        &self.obs[i * self.obs_dim..(i + 1) * self.obs_dim]
    }
    /// The action of transition `i`.
    pub fn action(&self, i: usize) -> &[f32] {
        &self.actions[i * self.act_dim..(i + 1) * self.act_dim]
    }
    /// The stored reward of transition `i`.
    pub fn reward(&self, i: usize) -> f32 {
        self.rewards[i]
    }

    /// Fills `batch` with `batch.size` transitions drawn uniformly (with replacement). The
    /// indices are drawn first, in row order; the rows are then copied in two halves, the second
    /// on the helper thread when there is one (the copies are random reads from a large buffer).
    pub fn sample_into(&self, batch: &mut Batch, rng: &mut impl Rng) {
        assert!(self.len > 0, "sampling an empty replay buffer");
        let picks: Vec<usize> = (0..batch.size).map(|_| rng.random_range(0..self.len)).collect();
        let all = BatchRows {
            obs: &mut batch.obs,
            actions: &mut batch.actions,
            rewards: &mut batch.rewards,
            next_obs: &mut batch.next_obs,
            terminated: &mut batch.terminated,
        };
        if batch.size < SPLIT_ROWS {
            return self.copy_rows(&picks, all);
        }
        let half = batch.size / 2;
        let (a, z) = all.split_at(half, self.obs_dim, self.act_dim);
        let (picks_a, picks_z) = picks.split_at(half);
        second_core::join(|| self.copy_rows(picks_a, a), || self.copy_rows(picks_z, z));
    }

    /// Copies transitions `picks` into consecutive rows of `rows`.
    fn copy_rows(&self, picks: &[usize], rows: BatchRows<'_>) {
        let (od, ad) = (self.obs_dim, self.act_dim);
        for (k, &i) in picks.iter().enumerate() {
            rows.obs[k * od..(k + 1) * od].copy_from_slice(self.obs(i));
            rows.actions[k * ad..(k + 1) * ad].copy_from_slice(self.action(i));
            rows.rewards[k] = self.rewards[i];
            rows.next_obs[k * od..(k + 1) * od].copy_from_slice(self.next_obs(i));
            rows.terminated[k] = if self.terminated(i) { 1.0 } else { 0.0 };
        }
    }

    /// The stored part of the buffer, borrowed: what a checkpoint writes, without copying it.
    pub fn columns(&self) -> BufferColumns<'_> {
        let n = self.len;
        let mut side_index: Vec<u32> = self.side_next.keys().map(|&k| k as u32).collect();
        side_index.sort_unstable();
        let side_values = side_index.iter().flat_map(|k| self.side_next[&(*k as usize)].iter().copied()).collect();
        BufferColumns {
            capacity: self.capacity,
            obs_dim: self.obs_dim,
            act_dim: self.act_dim,
            write: self.write,
            len: n,
            obs: &self.obs[..n * self.obs_dim],
            actions: &self.actions[..n * self.act_dim],
            rewards: &self.rewards[..n],
            flags: &self.flags[..n],
            side_index,
            side_values,
            newest_next: &self.newest_next,
        }
    }

    /// Everything needed to restore the buffer exactly, as named flat arrays (a copy).
    pub fn export(&self) -> BufferSnapshot {
        let c = self.columns();
        BufferSnapshot {
            capacity: c.capacity,
            obs_dim: c.obs_dim,
            act_dim: c.act_dim,
            write: c.write,
            len: c.len,
            obs: c.obs.to_vec(),
            actions: c.actions.to_vec(),
            rewards: c.rewards.to_vec(),
            flags: c.flags.to_vec(),
            side_index: c.side_index,
            side_values: c.side_values,
            newest_next: c.newest_next.to_vec(),
        }
    }

    /// The buffer a snapshot describes. Takes the snapshot's arrays over (a full buffer's are
    /// not copied), growing them to the capacity.
    pub(crate) fn import(s: BufferSnapshot) -> anyhow::Result<ReplayBuffer> {
        let ok = s.capacity > 0
            && s.len <= s.capacity
            && s.write < s.capacity
            && s.obs.len() == s.len * s.obs_dim
            && s.actions.len() == s.len * s.act_dim
            && s.rewards.len() == s.len
            && s.flags.len() == s.len
            && s.side_values.len() == s.side_index.len() * s.obs_dim
            && s.newest_next.len() == s.obs_dim
            && s.side_index.iter().all(|&i| (i as usize) < s.capacity);
        if !ok {
            anyhow::bail!("replay buffer snapshot is inconsistent (corrupt checkpoint?)");
        }
        fn grown<T: Clone + Default>(mut v: Vec<T>, len: usize) -> Vec<T> {
            v.resize(len, T::default());
            v
        }
        let side_next = s
            .side_index
            .iter()
            .enumerate()
            .map(|(k, idx)| (*idx as usize, s.side_values[k * s.obs_dim..(k + 1) * s.obs_dim].to_vec()))
            .collect();
        Ok(ReplayBuffer {
            capacity: s.capacity,
            obs_dim: s.obs_dim,
            act_dim: s.act_dim,
            obs: grown(s.obs, s.capacity * s.obs_dim),
            actions: grown(s.actions, s.capacity * s.act_dim),
            rewards: grown(s.rewards, s.capacity),
            flags: grown(s.flags, s.capacity),
            side_next,
            newest_next: s.newest_next,
            write: s.write,
            len: s.len,
        })
    }
}

/// A replay buffer's stored part, borrowed from it ([`ReplayBuffer::columns`]).
#[derive(Debug, Clone, PartialEq)]
pub struct BufferColumns<'a> {
    /// Slots allocated.
    pub capacity: usize,
    /// Length of one observation.
    pub obs_dim: usize,
    /// Length of one action.
    pub act_dim: usize,
    /// The slot the next transition goes to.
    pub write: usize,
    /// Slots holding a transition.
    pub len: usize,
    /// Observations, `capacity × obs_dim`.
    pub obs: &'a [f32],
    /// Actions, `capacity × act_dim`.
    pub actions: &'a [f32],
    /// Rewards, one per slot.
    pub rewards: &'a [f32],
    /// Terminated (bit 0) and truncated (bit 1) flags, one byte per slot.
    pub flags: &'a [u8],
    /// Slots whose next observation lives in the side table, ascending.
    pub side_index: Vec<u32>,
    /// Those next observations, `side_index.len() × obs_dim`, in `side_index` order.
    pub side_values: Vec<f32>,
    /// The newest transition's next observation.
    pub newest_next: &'a [f32],
}

/// A replay buffer's contents as flat arrays (a full buffer's slots are `0..len`).
#[derive(Debug, Clone, PartialEq)]
pub struct BufferSnapshot {
    /// Slots allocated.
    pub capacity: usize,
    /// Length of one observation.
    pub obs_dim: usize,
    /// Length of one action.
    pub act_dim: usize,
    /// The slot the next transition goes to.
    pub write: usize,
    /// Slots holding a transition.
    pub len: usize,
    /// Observations, `capacity × obs_dim`.
    pub obs: Vec<f32>,
    /// Actions, `capacity × act_dim`.
    pub actions: Vec<f32>,
    /// Rewards, one per slot.
    pub rewards: Vec<f32>,
    /// Terminated (bit 0) and truncated (bit 1) flags, one byte per slot.
    pub flags: Vec<u8>,
    /// Slots whose next observation lives in the side table, ascending.
    pub side_index: Vec<u32>,
    /// Those next observations, `side_index.len() × obs_dim`, in `side_index` order.
    pub side_values: Vec<f32>,
    /// The newest transition's next observation.
    pub newest_next: Vec<f32>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Feeds episodes of a counter "environment" whose observation is [t, episode].
    fn fill(buf: &mut ReplayBuffer, episodes: &[(usize, bool)]) -> Vec<(Vec<f32>, Vec<f32>, bool, bool)> {
        let mut all = Vec::new();
        for (e, &(len, terminated)) in episodes.iter().enumerate() {
            for t in 0..len {
                let obs = vec![t as f32, e as f32];
                let next = vec![t as f32 + 1.0, e as f32];
                let last = t + 1 == len;
                buf.add(&obs, &[t as f32 * 0.1], t as f32, &next, last && terminated, last && !terminated);
                all.push((obs, next, last && terminated, last && !terminated));
            }
        }
        all
    }

    #[test]
    fn next_observations_are_exact_across_episode_ends_and_wraparound() {
        let mut buf = ReplayBuffer::new(7, 2, 1);
        let all = fill(&mut buf, &[(3, false), (2, true), (4, false), (1, true)]);
        assert_eq!(buf.len(), 7);
        // The buffer holds the last 7 transitions, oldest at the write position.
        let kept = &all[all.len() - 7..];
        for (k, (obs, next, term, trunc)) in kept.iter().enumerate() {
            let i = (buf.write + k) % 7;
            assert_eq!(buf.obs(i), &obs[..]);
            assert_eq!(buf.terminated(i), *term);
            assert_eq!(buf.truncated(i), *trunc);
            if !term {
                assert_eq!(buf.next_obs(i), &next[..], "transition {k}");
            }
        }
        assert!(buf.side_next.len() <= 2, "only truncated ends need a stored next observation");
    }

    #[test]
    fn inconsistent_next_observation_is_kept_in_the_side_table() {
        let mut buf = ReplayBuffer::new(10, 1, 1);
        buf.add(&[0.0], &[0.0], 0.0, &[1.0], false, false);
        // The caller skipped a step (e.g. an unstable transition was dropped).
        buf.add(&[5.0], &[0.0], 0.0, &[6.0], false, false);
        assert_eq!(buf.next_obs(0), &[1.0]);
        assert_eq!(buf.next_obs(1), &[6.0]);
    }

    #[test]
    fn sampling_is_uniform_and_seeded_and_snapshots_round_trip() {
        let mut buf = ReplayBuffer::new(50, 2, 1);
        fill(&mut buf, &[(20, false), (15, true)]);
        let mut b1 = Batch::new(64, 2, 1);
        let mut b2 = Batch::new(64, 2, 1);
        buf.sample_into(&mut b1, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
        let restored = ReplayBuffer::import(buf.export()).unwrap();
        restored.sample_into(&mut b2, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
        assert_eq!(b1.obs, b2.obs);
        assert_eq!(b1.next_obs, b2.next_obs);
        assert_eq!(b1.terminated, b2.terminated);
        assert_eq!(buf.bytes_per_transition(), 4 * 4 + 1);
        let mut counts = vec![0usize; 35];
        let mut big = Batch::new(35_000, 2, 1);
        buf.sample_into(&mut big, &mut rand_chacha::ChaCha8Rng::seed_from_u64(4));
        for k in 0..big.size {
            let (t, e) = (big.obs[2 * k] as usize, big.obs[2 * k + 1] as usize);
            counts[e * 20 + t] += 1;
        }
        assert!(counts.iter().all(|&c| (800..1200).contains(&c)), "{counts:?}");
        let mut corrupt = buf.export();
        corrupt.rewards.pop();
        assert!(ReplayBuffer::import(corrupt).is_err());
    }

    /// Row by row, drawing each index just before copying it: what `sample_into` must equal.
    fn sample_row_by_row(buf: &ReplayBuffer, size: usize, rng: &mut impl Rng) -> Batch {
        let mut b = Batch::new(size, buf.obs_dim, buf.act_dim);
        for k in 0..size {
            let i = rng.random_range(0..buf.len());
            b.obs[k * buf.obs_dim..(k + 1) * buf.obs_dim].copy_from_slice(buf.obs(i));
            b.actions[k * buf.act_dim..(k + 1) * buf.act_dim].copy_from_slice(buf.action(i));
            b.rewards[k] = buf.reward(i);
            b.next_obs[k * buf.obs_dim..(k + 1) * buf.obs_dim].copy_from_slice(buf.next_obs(i));
            b.terminated[k] = if buf.terminated(i) { 1.0 } else { 0.0 };
        }
        b
    }

    #[test]
    fn sampling_in_halves_equals_row_by_row_with_and_without_the_helper() {
        let mut buf = ReplayBuffer::new(300, 2, 1);
        fill(&mut buf, &[(120, true), (90, false), (140, true), (7, false)]);
        second_core::with_and_without_helper(|helper| {
            // below the split, at it, odd, and a training batch
            for size in [1, SPLIT_ROWS - 1, SPLIT_ROWS, 257, 256] {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(size as u64);
                let mut got = Batch::new(size, 2, 1);
                buf.sample_into(&mut got, &mut rng);
                let after: u64 = rng.random();
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(size as u64);
                let want = sample_row_by_row(&buf, size, &mut rng);
                let what = format!("size {size}, helper {helper}");
                assert_eq!(got.obs, want.obs, "{what}");
                assert_eq!(got.actions, want.actions, "{what}");
                assert_eq!(got.rewards, want.rewards, "{what}");
                assert_eq!(got.next_obs, want.next_obs, "{what}");
                assert_eq!(got.terminated, want.terminated, "{what}");
                assert_eq!(after, rng.random::<u64>(), "the RNG advances as row by row ({what})");
            }
        });
    }
}
