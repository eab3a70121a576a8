"""Stable-Baselines3 models as locobench policies: `import_sb3` writes an SB3 PPO, SAC, TD3 or DDPG
MLP policy (with its VecNormalize statistics) as an exported locobench policy, which `locobench
eval`, `record` and `report` then run in Rust.

The layouts are SB3 2.x's (`stable_baselines3/common/policies.py`, `sac/policies.py`,
`td3/policies.py`):
- PPO: `mlp_extractor.policy_net` (Linear, Tanh or ReLU, ...), `action_net`, and a
  state-independent `log_std`: locobench's PPO actor (an MLP with that activation and `log_std`,
  `agents::ppo`), deterministic action the mean clipped to the action bounds.
- SAC: `actor.latent_pi` (Linear, ReLU, ...), `actor.mu` and `actor.log_std`: locobench's SAC actor,
  whose last layer gives the mean and the log-std side by side; deterministic action tanh(mean).
- TD3 and DDPG: `actor.mu` (Linear, ReLU, ..., Linear, Tanh): locobench's deterministic actor.
- VecNormalize: observations become clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs),
  as locobench's own observation normalisation computes them.
"""
import hashlib
import os

import numpy as np

from locobench import _core
from locobench.evaluation import _core_env

_ALGOS = {"PPO": "ppo", "SAC": "sac", "TD3": "td3", "DDPG": "ddpg"}


def _linear_chain(sequential, activations, what, output_tanh=False):
    """The (weight, bias) of each Linear in `sequential` and the activation between them (one of
    `activations`, the same after every Linear but the last, None with one layer); with
    `output_tanh` (TD3's and DDPG's actor), Tanh must follow the last."""
    import torch.nn as nn

    modules = list(sequential)
    if output_tanh:
        if not modules or not isinstance(modules[-1], nn.Tanh):
            raise ValueError(f"{what}: the last layer is not followed by Tanh, as a deterministic actor's is")
        modules = modules[:-1]
    layers, acts = [], []
    for m in modules:
        if isinstance(m, nn.Linear):
            layers.append((m.weight.detach().cpu().double().numpy(), m.bias.detach().cpu().double().numpy()))
        elif isinstance(m, (nn.ReLU, nn.Tanh)):
            acts.append(type(m).__name__)
        else:
            raise ValueError(f"{what}: {type(m).__name__} layers are not supported (an MLP of Linear and "
                             f"{' or '.join(activations)} layers is)")
    wrong = [a for a in acts if a not in activations]
    if wrong:
        raise ValueError(f"{what}: {wrong[0]} activations are not supported: locobench's actor uses "
                         f"{' or '.join(activations)}")
    if len(set(acts)) > 1:
        raise ValueError(f"{what}: mixed activations ({', '.join(sorted(set(acts)))}) are not supported: "
                         "locobench's actor uses one between every layer")
    return layers, (acts[0] if acts else None)


def _check_mlp_policy(model):
    from stable_baselines3.common.torch_layers import FlattenExtractor

    policy = model.policy
    kind = type(policy).__name__
    if "Cnn" in kind or "MultiInput" in kind:
        raise ValueError(f"{kind} is not supported: import_sb3 converts MLP policies on vector observations")
    if "Recurrent" in type(model).__name__ or "Lstm" in kind:
        raise ValueError(f"{type(model).__name__} (recurrent) is not supported: import_sb3 converts MLP policies")
    extractor = getattr(policy, "features_extractor", None) or getattr(getattr(policy, "actor", None),
                                                                       "features_extractor", None)
    if extractor is not None and not isinstance(extractor, FlattenExtractor):
        raise ValueError(f"a custom features extractor ({type(extractor).__name__}) is not supported")
    if getattr(policy, "use_sde", False) or getattr(getattr(policy, "actor", None), "use_sde", False):
        raise ValueError("gSDE (use_sde=True) is not supported")


def _toml(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(value)


def import_sb3(model, out_dir, env, *, vec_normalize=None, options=None):
    """Writes ``model`` (an SB3 PPO, SAC, TD3 or DDPG model, or the path of its ``.zip``) as an
    exported locobench policy in ``out_dir`` for ``env`` (an env id such as
    ``"locobench/Minitaur-v0"`` or name, with ``options``), with the observation statistics of
    ``vec_normalize`` (a ``VecNormalize`` or the path of its ``.pkl``) when the model was trained
    behind one. Returns the policy's path; ``locobench eval --policy OUT_DIR`` evaluates it, and
    ``locobench report --runs OUT_DIR`` makes it a row labelled as imported, with its source and,
    where the model counted any (``num_timesteps``), the steps it was trained for.

    Unsupported policies (CNN, multi-input, recurrent, gSDE, custom feature extractors,
    activations other than the actor's) are a ValueError naming what is not supported.
    """
    import stable_baselines3
    import torch

    source_file = None
    if isinstance(model, (str, os.PathLike)):
        source_file = os.fspath(model)
        model = _load_model(source_file)
    name = type(model).__name__
    _check_mlp_policy(model)
    if name not in _ALGOS:
        raise ValueError(f"{name} is not supported: import_sb3 converts PPO, SAC, TD3 and DDPG")
    algo = _ALGOS[name]
    core = _core_env(env, options, None)
    obs_dim, act_dim = len(core.observation_bounds[0]), len(core.action_bounds[0])
    if model.observation_space.shape != (obs_dim,) or model.action_space.shape != (act_dim,):
        raise ValueError(f"the model takes observations {model.observation_space.shape} and actions "
                         f"{model.action_space.shape}; {core.name} has ({obs_dim},) and ({act_dim},)")
    low, high = core.action_bounds
    if not (np.allclose(model.action_space.low, low) and np.allclose(model.action_space.high, high)):
        raise ValueError(f"the model's action bounds differ from {core.name}'s ({low}, {high})")

    tensors, train = {}, {"algo": algo}
    policy = model.policy
    if algo == "ppo":
        layers, activation = _linear_chain(policy.mlp_extractor.policy_net, ("Tanh", "ReLU"), "PPO's policy network")
        action_net = policy.action_net
        layers.append((action_net.weight.detach().cpu().double().numpy(),
                       action_net.bias.detach().cpu().double().numpy()))
        for i, (w, b) in enumerate(layers):
            tensors[f"actor.mean.{i}.weight"], tensors[f"actor.mean.{i}.bias"] = w, b
        tensors["actor.log_std"] = policy.log_std.detach().cpu().double().numpy().reshape(1, -1)
        train["weight_init"] = "orthogonal"
    elif algo == "sac":
        actor = policy.actor
        layers, _ = _linear_chain(actor.latent_pi, ("ReLU",), "SAC's actor")
        w = np.concatenate([actor.mu.weight.detach().cpu().double().numpy(),
                            actor.log_std.weight.detach().cpu().double().numpy()])
        b = np.concatenate([actor.mu.bias.detach().cpu().double().numpy(),
                            actor.log_std.bias.detach().cpu().double().numpy()])
        layers.append((w, b))
        for i, (w, b) in enumerate(layers):
            tensors[f"actor.{i}.weight"], tensors[f"actor.{i}.bias"] = w, b
    else:
        layers, _ = _linear_chain(policy.actor.mu, ("ReLU",), f"{name}'s actor", output_tanh=True)
        for i, (w, b) in enumerate(layers):
            tensors[f"actor.{i}.weight"], tensors[f"actor.{i}.bias"] = w, b
    train["hidden"] = [int(w.shape[0]) for w, _ in layers[:-1]]
    section = {}
    if algo == "ppo" and activation == "ReLU":
        section["activation"] = "relu"

    if vec_normalize is not None:
        if isinstance(vec_normalize, (str, os.PathLike)):
            import pickle

            with open(vec_normalize, "rb") as f:
                vec_normalize = pickle.load(f)
        if not getattr(vec_normalize, "norm_obs", True):
            vec_normalize = None
    # Explicit either way: locobench's PPO normalises observations by default, SB3's only behind
    # VecNormalize.
    train["normalize_observations"] = vec_normalize is not None
    if algo == "ppo" and vec_normalize is None:
        # PPO's actor always holds its statistics; switched off, they are Gymnasium's prior, unused.
        tensors["actor.obs_mean"], tensors["actor.obs_var"] = np.zeros(obs_dim), np.ones(obs_dim)
        tensors["actor.obs_count"] = np.array([1e-4])
    if vec_normalize is not None:
        rms = vec_normalize.obs_rms
        mean, var = np.asarray(rms.mean, dtype=np.float64), np.asarray(rms.var, dtype=np.float64)
        if mean.shape != (obs_dim,):
            raise ValueError(f"the VecNormalize statistics cover {mean.shape} observations; the env has ({obs_dim},)")
        clip, eps = float(vec_normalize.clip_obs), float(vec_normalize.epsilon)
        if eps != 1e-8:
            raise ValueError(f"VecNormalize epsilon {eps} is not supported (locobench normalises with 1e-8)")
        if algo == "ppo":
            tensors["actor.obs_mean"] = mean
            tensors["actor.obs_var"] = var
            tensors["actor.obs_count"] = np.array([float(rms.count)])
            section["clip_observations"] = clip
        else:
            if clip != 10.0:
                raise ValueError(f"VecNormalize clip_obs {clip} is not supported for {name} (locobench clips at 10)")
            tensors["actor.obs_mean"] = mean
            tensors["actor.obs_inv_std"] = 1.0 / np.sqrt(var + eps)

    lines = ["format = 3", "seed = 0", 'crate_version = "imported"', "", "[env]", f"name = {_toml(core.name)}",
             "", "[env.options]", core.options.strip(), "", "[train]"]
    lines += [f"{k} = {_toml(v)}" for k, v in train.items()]
    if section:
        lines += ["", f"[train.{algo}]"] + [f"{k} = {_toml(v)}" for k, v in section.items()]
    config = "\n".join(lines) + "\n"

    digest = hashlib.sha256(open(source_file, "rb").read()).hexdigest() if source_file else ""
    source = "\n".join([
        "# A Stable-Baselines3 model converted by locobench.import_sb3",
        f"library = {_toml('stable-baselines3 ' + stable_baselines3.__version__)}",
        f"torch = {_toml(torch.__version__)}",
        f"algorithm = {_toml(name)}",
        f"model_file = {_toml(source_file or '')}",
        f"model_sha256 = {_toml(digest)}",
        f"vec_normalize = {_toml(vec_normalize is not None)}",
    ] + (
        # The budget it was trained for, as SB3 counts it: `locobench report --runs OUT_DIR`
        # makes its row at that budget.
        [f"step = {int(model.num_timesteps)}"] if int(getattr(model, "num_timesteps", 0) or 0) > 0 else []
    )) + "\n"
    payload = [(k, list(np.shape(v)), np.asarray(v, dtype=np.float64).ravel().tolist()) for k, v in tensors.items()]
    return _core.import_policy(os.fspath(out_dir), payload, config, source)


def _load_model(path):
    """Loads an SB3 ``.zip`` with the class it was saved from, told by its policy class's module
    (``stable_baselines3.<algo>.policies``; PPO's is ``common.policies``). TD3 and DDPG share a
    policy class: DDPG is the one without target smoothing and policy delay."""
    import base64
    import json
    import zipfile

    import stable_baselines3

    with zipfile.ZipFile(path) as z:
        data = json.loads(z.read("data").decode())
    serialized = data.get("policy_class", {}).get(":serialized:", "")
    module = base64.b64decode(serialized) if serialized else b""
    if b"stable_baselines3.sac" in module:
        cls = stable_baselines3.SAC
    elif b"stable_baselines3.td3" in module:
        ddpg = data.get("policy_delay") == 1 and data.get("target_policy_noise") == 0.0
        cls = stable_baselines3.DDPG if ddpg else stable_baselines3.TD3
    elif b"stable_baselines3.common.policies" in module:
        cls = stable_baselines3.PPO
    else:
        raise ValueError(f"{path}: not a PPO, SAC, TD3 or DDPG model of Stable-Baselines3")
    return cls.load(path, device="cpu")
