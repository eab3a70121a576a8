"""N copies of a locobench environment stepped together in Rust, as a Gymnasium vector env."""
import numbers
import os

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from locobench import _core
from locobench.envs import LocobenchEnv, _core_arguments, _float64_actions

_NO_RENDERING = (
    "render_mode={!r}: the vector env does not render its copies; film single envs made with "
    "gymnasium.make(..., render_mode='rgb_array') (what SB3's make_vec_env and VecVideoRecorder use), "
    "or a policy with `locobench record --video`"
)


class LocobenchVectorEnv(VectorEnv):
    """``num_envs`` copies of the locobench environment ``name``, stepped in Rust over ``threads``
    threads (default: every core, at most one per copy) with the GIL released.

    Keywords are env options and ``reward`` weights, as for :class:`locobench.LocobenchEnv`.
    ``gymnasium.make_vec("locobench/Minitaur-v0", num_envs=8)`` builds one.

    Autoreset is Gymnasium's same-step mode (``metadata["autoreset_mode"]``): where a copy's
    episode ends, ``step`` returns the next episode's first observation, and ``infos["final_obs"]``
    and ``infos["final_info"]`` (masked by ``infos["_final_obs"]``) hold the ended episode's last
    observation and info. Seeds: ``reset(seed=s)`` starts copy ``i`` from
    ``locobench.episode_seed(s, i, 0)`` and its ``k``-th next episode from
    ``episode_seed(s, i, k)``, so a copy's trajectory depends on the seed and its own actions only
    and the numbers are the same bit for bit whatever ``threads`` is.
    """

    def __init__(self, name, num_envs, threads=None, render_mode=None, reward=None, **options):
        if render_mode is not None:
            raise ValueError(_NO_RENDERING.format(render_mode))
        if not isinstance(num_envs, numbers.Integral) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, not {num_envs!r}")
        if threads is None:
            threads = min(int(num_envs), os.cpu_count() or 1)
        if not isinstance(threads, numbers.Integral) or threads < 1:
            raise ValueError(f"threads must be a positive integer, not {threads!r}")
        single = LocobenchEnv(name, reward=reward, **options)
        pairs, weights = _core_arguments(options, reward)
        self._core = _core.VecEnv(name, int(num_envs), int(threads), pairs, weights)
        self.name = single.name
        self.num_envs = int(num_envs)
        self.threads = int(threads)
        self.render_mode = None
        self.metadata = dict(single.metadata, autoreset_mode=AutoresetMode.SAME_STEP)
        self.single_observation_space = single.observation_space
        self.single_action_space = single.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._seed = None

    def reset(self, *, seed=None, options=None):
        """Starts an episode in every copy. Without a seed: the first reset draws one from the
        operating system, later ones continue deterministically from the previous seed."""
        if options:
            raise ValueError("reset(options=...) is not supported: give env options to gymnasium.make_vec")
        if seed is None:
            seed = self._next_seed()
        elif not isinstance(seed, numbers.Integral) or isinstance(seed, bool) or seed < 0:
            raise ValueError(
                f"seed must be a non-negative integer (copy i's episodes are seeded from it), not {seed!r}"
            )
        super().reset(seed=int(seed))
        self._seed = int(seed)
        obs = self._core.reset(self._seed)
        return np.asarray(obs, dtype=np.float64), {}

    def _next_seed(self):
        if self._seed is None:
            return int(np.random.SeedSequence().generate_state(1, np.uint64)[0] >> np.uint64(1))
        return int(np.random.default_rng(self._seed).integers(0, 2**63 - 1))

    def step(self, actions):
        out = self._core.step_gym(actions)
        if out is None:  # not a float64 or float32 array of shape (num_envs, action dim)
            actions = _float64_actions(actions, self.action_space.shape, "actions", " (num_envs, action dim)")
            out = self._core.step_gym(actions)
        if type(out[4]) is tuple:  # the copies' infos differ in their names: batched here
            obs, rewards, terminated, truncated, (final_obs, step_infos) = out
            out = obs, rewards, terminated, truncated, self._batch(final_obs, step_infos)
        return out

    def _step_with_dicts(self, a):
        """The step through one info dict per copy, batched by Gymnasium's ``_add_info``: what
        ``step`` builds in Rust, kept as the reference the tests compare it with and as the former
        step ``python/bench_speed.py`` measures."""
        obs, rewards, terminated, truncated, final_obs, step_infos = self._core.step(a.tolist())
        return (
            np.asarray(obs, dtype=np.float64),
            np.asarray(rewards, dtype=np.float64),
            np.asarray(terminated, dtype=bool),
            np.asarray(truncated, dtype=bool),
            self._batch(final_obs, step_infos),
        )

    def _batch(self, final_obs, step_infos):
        """Gymnasium's ``_add_info`` batching of one info dict per copy, a copy whose episode ended
        with its last observation and info under ``final_obs`` and ``final_info``."""
        infos = {}
        for i, info in enumerate(step_infos):
            if final_obs[i] is None:
                infos = self._add_info(infos, info, i)
            else:
                last = {"final_obs": np.asarray(final_obs[i], dtype=np.float64), "final_info": info}
                infos = self._add_info(infos, last, i)
        return infos

    def render(self):
        return None

