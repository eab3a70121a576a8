"""The evaluation protocol from Python: any policy on the held-out episodes `locobench eval` and
`locobench report` play, with the same statistics."""
import getpass
import hashlib
import os
import platform
import sys
import warnings

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


def _observation_normalizer(vec_normalize, obs_dim):
    """Observation -> observation normalised with the frozen statistics of an SB3 ``VecNormalize``
    (or the path of its ``.pkl``), as SB3 evaluates a model trained behind one (``training=False``):
    clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs) as float32. None when it does not
    normalise observations."""
    where = ""
    if isinstance(vec_normalize, (str, os.PathLike)):
        import pickle

        where = f" {os.fspath(vec_normalize)}"
        with open(vec_normalize, "rb") as f:
            try:
                vec_normalize = pickle.load(f)
            except Exception as e:  # an unpickling error can be of any type
                raise ValueError(f"vec_normalize{where}: not a VecNormalize pickle ({type(e).__name__}: {e})") from e
    if not getattr(vec_normalize, "norm_obs", True):
        return None
    rms = getattr(vec_normalize, "obs_rms", None)
    if rms is None or isinstance(rms, dict) or not hasattr(rms, "mean") or not hasattr(rms, "var"):
        raise ValueError(f"vec_normalize{where}: {type(vec_normalize).__name__} holds no observation statistics "
                         "(obs_rms.mean and obs_rms.var of one vector observation)")
    mean = np.asarray(rms.mean, dtype=np.float64)
    var = np.asarray(rms.var, dtype=np.float64)
    if mean.shape != (obs_dim,) or var.shape != (obs_dim,):
        raise ValueError(f"vec_normalize{where}: its statistics cover observations of shape {mean.shape}; "
                         f"the env's have ({obs_dim},)")
    scale = np.sqrt(var + float(getattr(vec_normalize, "epsilon", 1e-8)))
    clip = float(getattr(vec_normalize, "clip_obs", 10.0))

    def normalize(observation):
        return np.clip((np.asarray(observation, dtype=np.float64) - mean) / scale, -clip, clip).astype(np.float32)

    return normalize


def _act_function(policy, deterministic, act_dim, normalize=None):
    """Observation (list of floats) -> action (list of floats), checked for shape and NaN;
    ``normalize`` maps each observation first (a VecNormalize's frozen statistics)."""
    if isinstance(policy, TrainedPolicy):
        # The Rust actor's own float64 actions: the same bits as `locobench eval`.
        return policy._core.act
    prepare = normalize or (lambda observation: observation)
    if hasattr(policy, "predict"):
        def predict(observation):
            obs = np.asarray(prepare(observation), dtype=np.float32)
            action, _ = policy.predict(obs, deterministic=deterministic)
            return action
        raw = predict
    elif callable(policy):
        def call(observation):
            return policy(np.asarray(prepare(observation), dtype=np.float64))
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
             training_seed=None, steps=None, vec_normalize=None):
    """Plays ``policy`` on the protocol's held-out episodes and returns their statistics.

    ``policy``: anything with Stable-Baselines3's ``predict(obs, deterministic=...)``, a callable
    from observation to action, or a locobench policy (``load_policy``). ``env``: a Gymnasium id
    (``"locobench/Minitaur-v0"``), an env name (``"minitaur"``) with ``options`` and ``reward``
    weights, or a locobench env. For a locobench policy it defaults to the world ``locobench
    eval`` plays it in: the options it was trained with, its training perturbations switched off
    (the nominal world), and ``options`` and ``reward`` on top, as ``eval --option --reward``. The episodes are those of ``locobench eval --episodes EPISODES --seed SEED``
    (fresh envs, reset seeds from the held-out stream), acted deterministically unless told.

    Returns a dict: ``return_mean`` and ``return_iqm`` as (estimate, low, high) with 95% bootstrap
    intervals over episodes, ``return_std`` (sample), ``falls`` and ``fall_rate`` (Wilson
    interval), ``length``, ``speed`` (m/s), ``cost_of_transport``, ``reward_terms`` (means),
    ``episode_returns``, ``episode_falls``, and ``text``: the lines ``locobench eval`` prints.
    ``controller=True`` (Minitaur, Ant) adds ``controller``: the controller commanded to the
    policy's mean speed on the same episodes, its statistics and ``policy_better``, P(policy's
    return > controller's) over the paired episodes. ``pushes`` (velocity changes in m/s) adds
    ``pushes``: {level: (survived, episodes, (rate, low, high))} under the evaluation's push.

    ``vec_normalize``: the ``VecNormalize`` (or the path of its ``.pkl``) a model was trained
    behind. Its frozen observation statistics normalise every observation before ``predict``, as
    SB3's own evaluation does; without it a model trained so gets raw observations. Statistics of
    another size than the env's observations are a ValueError. (A locobench policy carries its
    own statistics and takes none.)

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
            # The world `locobench eval` builds: the run's options with its training
            # perturbations off, then the options and reward weights given here on top.
            pairs, weights = _core_arguments(options or {}, reward)
            core = _core.Env(policy.env_name, list(policy._core.evaluation_options) + pairs, weights)
        else:
            core = _core_env(env, options, reward)
        if core.name != policy.env_name:
            raise ValueError(f"the policy was trained on {policy.env_name}, not {core.name}")
        for line in policy._core.command_warnings(core):
            warnings.warn(line, stacklevel=2)
    else:
        if env is None:
            raise ValueError("env is needed for a policy that is not a locobench policy")
        core = _core_env(env, options, reward)
    low, _ = core.action_bounds
    normalize = None
    if vec_normalize is not None:
        if isinstance(policy, TrainedPolicy):
            raise ValueError("vec_normalize is for models trained behind SB3's VecNormalize: a locobench policy "
                             "normalises its observations itself")
        normalize = _observation_normalizer(vec_normalize, len(core.observation_bounds[0]))
    act = _act_function(policy, deterministic, len(low), normalize)
    meta = None
    if out is not None:
        meta = _meta(policy, label, author, policy_file, library, training_seed, steps)
    return _core.evaluate(core, act, int(episodes), int(seed), [float(p) for p in pushes], bool(controller), training,
                          None if out is None else os.fspath(out), meta)
