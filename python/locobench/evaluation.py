"""The evaluation protocol from Python: any policy on the held-out episodes `locobench eval` and
`locobench report` play, with the same statistics."""
import getpass
import hashlib
import os
import platform
import sys

import numpy as np

from locobench import _core
from locobench.envs import ENV_IDS, LocobenchEnv, _core_arguments
from locobench.policies import TrainedPolicy

_NAMES = {gym_id: name for name, gym_id in ENV_IDS.items()}


def _core_env(env, options, reward):
    """A `_core.Env` for an env id or name (with options and reward weights) or a locobench env."""
    if isinstance(env, str):
        name = _NAMES.get(env, env)
        if name not in ENV_IDS:
            raise ValueError(f"unknown env {env!r}: one of {sorted(ENV_IDS.values())} (or {sorted(ENV_IDS)})")
        pairs, weights = _core_arguments(options or {}, reward)
        return _core.Env(name, pairs, weights)
    if options or reward:
        raise ValueError("options and reward apply to an env given by name; this env was made with its own")
    unwrapped = getattr(env, "unwrapped", env)
    if isinstance(unwrapped, LocobenchEnv):
        return unwrapped._core
    raise TypeError(f"env must be an env id, an env name or a locobench env, not {type(env).__name__}")


def _act_function(policy, deterministic, act_dim):
    """Observation (list of floats) -> action (list of floats), checked for shape and NaN."""
    if isinstance(policy, TrainedPolicy):
        # The Rust actor's own float64 actions: the same bits as `locobench eval`.
        return policy._core.act
    if hasattr(policy, "predict"):
        def predict(observation):
            action, _ = policy.predict(np.asarray(observation, dtype=np.float32), deterministic=deterministic)
            return action
        raw = predict
    elif callable(policy):
        def call(observation):
            return policy(np.asarray(observation, dtype=np.float64))
        raw = call
    else:
        raise TypeError(f"policy must have SB3's predict or be a callable, not {type(policy).__name__}")

    def act(observation):
        a = np.asarray(raw(observation))
        if a.dtype.kind not in "fiu":
            raise TypeError(f"the policy returned dtype {a.dtype}, not numbers")
        if a.size != act_dim or a.ndim > 1 and a.shape[0] != 1:
            raise ValueError(f"the policy returned an action of shape {a.shape}; the env takes ({act_dim},)")
        a = a.astype(np.float64).ravel()
        if not np.all(np.isfinite(a)):
            raise ValueError(f"the policy returned a non-finite action: {a}")
        return a.tolist()

    return act


def _library(policy):
    """(library, version) of the package a policy object comes from."""
    if isinstance(policy, TrainedPolicy):
        from importlib.metadata import PackageNotFoundError, version
        try:
            return "locobench", version("locobench")
        except PackageNotFoundError:
            return "locobench", "unknown"
    root = (getattr(type(policy), "__module__", "") or "").split(".")[0]
    if root in ("", "builtins", "__main__", "numpy"):
        return "python", platform.python_version()
    return root.replace("_", "-"), str(getattr(sys.modules.get(root), "__version__", "unknown"))


def _meta(policy, label, author, policy_file, library, training_seed, steps):
    if not label:
        raise ValueError("out= needs label= (the row's name in the report)")
    lib, version = library if library else _library(policy)
    digest = ""
    if policy_file is not None:
        with open(policy_file, "rb") as f:
            digest = hashlib.sha256(f.read()).hexdigest()
    return {
        "label": str(label),
        "library": lib,
        "library_version": version,
        "policy_file": "" if policy_file is None else os.fspath(policy_file),
        "policy_sha256": digest,
        "author": author or getpass.getuser(),
        "seed": None if training_seed is None else int(training_seed),
        "steps": None if steps is None else int(steps),
    }


def evaluate(policy, env=None, *, episodes=50, seed=0, deterministic=True, options=None, reward=None,
             controller=False, pushes=(), out=None, label=None, author=None, policy_file=None, library=None,
             training_seed=None, steps=None):
    """Plays ``policy`` on the protocol's held-out episodes and returns their statistics.

    ``policy``: anything with Stable-Baselines3's ``predict(obs, deterministic=...)``, a callable
    from observation to action, or a locobench policy (``load_policy``). ``env``: a Gymnasium id
    (``"locobench/Minitaur-v0"``), an env name (``"minitaur"``) with ``options`` and ``reward``
    weights, or a locobench env; for a locobench policy it defaults to the env the policy was
    trained in. The episodes are those of ``locobench eval --episodes EPISODES --seed SEED``
    (fresh envs, reset seeds from the held-out stream), acted deterministically unless told.

    Returns a dict: ``return_mean`` and ``return_iqm`` as (estimate, low, high) with 95% bootstrap
    intervals over episodes, ``return_std`` (sample), ``falls`` and ``fall_rate`` (Wilson
    interval), ``length``, ``speed`` (m/s), ``cost_of_transport``, ``reward_terms`` (means),
    ``episode_returns``, ``episode_falls``, and ``text``: the lines ``locobench eval`` prints.
    ``controller=True`` (Minitaur, Ant) adds ``controller``: the controller commanded to the
    policy's mean speed on the same episodes, its statistics and ``policy_better``, P(policy's
    return > controller's) over the paired episodes. ``pushes`` (velocity changes in m/s) adds
    ``pushes``: {level: (survived, episodes, (rate, low, high))} under the evaluation's push.

    ``out=DIR`` writes the episodes (``episodes.csv``) and their provenance (``external.toml``:
    ``label``, the library and its version, found from the policy's package unless
    ``library=(name, version)`` says, ``policy_file`` and its SHA-256, the machine, ``author``,
    ``training_seed`` and ``steps``) for ``locobench report --external DIR``, which adds them as
    a row beside the report's own, marked as evaluated outside locobench. Runs with one label are
    one row, their seeds pooled.
    """
    training = None
    if isinstance(policy, TrainedPolicy):
        training = policy._core.training
        if env is None:
            core = _core.Env(policy.env_name, list(policy._core.env_options), [])
            if options or reward:
                raise ValueError("options and reward apply to an env given by name: pass env= as well")
        else:
            core = _core_env(env, options, reward)
        if core.name != policy.env_name:
            raise ValueError(f"the policy was trained on {policy.env_name}, not {core.name}")
    else:
        if env is None:
            raise ValueError("env is needed for a policy that is not a locobench policy")
        core = _core_env(env, options, reward)
    low, _ = core.action_bounds
    act = _act_function(policy, deterministic, len(low))
    meta = None
    if out is not None:
        meta = _meta(policy, label, author, policy_file, library, training_seed, steps)
    return _core.evaluate(core, act, int(episodes), int(seed), [float(p) for p in pushes], bool(controller), training,
                          None if out is None else os.fspath(out), meta)
