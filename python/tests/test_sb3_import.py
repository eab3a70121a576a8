"""`locobench.import_sb3`: SB3 models as locobench policies. Without Stable-Baselines3 installed,
the conversion's target is checked against a NumPy forward pass of each layout (PPO's tanh MLP
behind VecNormalize, SAC's squashed mean, TD3's tanh output); with it, converted models against
SB3's own `predict` on 100 observations (within 1e-5), and unsupported models refused."""
import subprocess

import numpy as np
import pytest

import locobench
from locobench import _core

OBS, ACT = 28, 8  # Minitaur


def _mlp(rng, sizes):
    return [(rng.normal(0, 0.3, (o, i)), rng.normal(0, 0.1, o)) for i, o in zip(sizes, sizes[1:])]


def _forward(layers, x, hidden):
    for k, (w, b) in enumerate(layers):
        x = w @ x + b
        if k < len(layers) - 1:
            x = hidden(x)
    return x


def _config(algo, hidden, extra=""):
    env = _core.Env("minitaur", [], [])
    return (f'format = 3\nseed = 0\ncrate_version = "test"\n\n[env]\nname = "minitaur"\n\n[env.options]\n'
            f"{env.options}\n[train]\nalgo = \"{algo}\"\nhidden = {hidden}\n{extra}")


def _payload(tensors):
    return [(k, list(np.shape(v)), np.asarray(v, dtype=np.float64).ravel().tolist()) for k, v in tensors.items()]


def _observations(rng, n=20):
    return [rng.normal(0, 1.5, OBS) for _ in range(n)]


@pytest.mark.parametrize("activation", ["tanh", "relu"])
def test_the_ppo_layout_with_vecnormalize_acts_as_its_numpy_forward_pass(tmp_path, activation):
    rng = np.random.default_rng(0)
    layers = _mlp(rng, [OBS, 16, 16, ACT])
    mean, var = rng.normal(0, 1, OBS), rng.uniform(0.1, 4, OBS)
    tensors = {f"actor.mean.{i}.{p}": t for i, (w, b) in enumerate(layers) for p, t in (("weight", w), ("bias", b))}
    tensors.update({"actor.log_std": np.zeros((1, ACT)), "actor.obs_mean": mean, "actor.obs_var": var,
                    "actor.obs_count": np.array([1000.0])})
    section = "clip_observations = 5.0\n" + ('activation = "relu"\n' if activation == "relu" else "")
    config = _config("ppo", [16, 16], "normalize_observations = true\n\n[train.ppo]\n" + section)
    _core.import_policy(str(tmp_path / "p"), _payload(tensors), config, "test = true\n")
    policy = locobench.load_policy(tmp_path / "p")
    for obs in _observations(rng):
        x = np.clip((obs - mean) / np.sqrt(var + 1e-8), -5, 5)
        hidden = np.tanh if activation == "tanh" else (lambda h: np.maximum(h, 0))
        expected = np.clip(_forward(layers, x, hidden), -1, 1)
        assert np.allclose(policy.predict(obs)[0], expected, atol=1e-5)


def test_the_sac_and_td3_layouts_act_as_their_numpy_forward_passes(tmp_path):
    rng = np.random.default_rng(1)
    relu = lambda x: np.maximum(x, 0)  # noqa: E731
    sac = _mlp(rng, [OBS, 16, 16, 2 * ACT])
    tensors = {f"actor.{i}.{p}": t for i, (w, b) in enumerate(sac) for p, t in (("weight", w), ("bias", b))}
    _core.import_policy(str(tmp_path / "sac"), _payload(tensors), _config("sac", [16, 16]), "")
    td3 = _mlp(rng, [OBS, 16, ACT])
    mean, var = rng.normal(0, 1, OBS), rng.uniform(0.1, 4, OBS)
    tensors = {f"actor.{i}.{p}": t for i, (w, b) in enumerate(td3) for p, t in (("weight", w), ("bias", b))}
    tensors.update({"actor.obs_mean": mean, "actor.obs_inv_std": 1 / np.sqrt(var + 1e-8)})
    config = _config("td3", [16], "normalize_observations = true\n")
    _core.import_policy(str(tmp_path / "td3"), _payload(tensors), config, "")
    sac_policy, td3_policy = locobench.load_policy(tmp_path / "sac"), locobench.load_policy(tmp_path / "td3")
    for obs in _observations(rng):
        assert np.allclose(sac_policy.predict(obs)[0], np.tanh(_forward(sac, obs, relu)[:ACT]), atol=1e-5)
        x = np.clip((obs - mean) / np.sqrt(var + 1e-8), -10, 10)
        assert np.allclose(td3_policy.predict(obs)[0], np.tanh(_forward(td3, x, relu)), atol=1e-5)


def test_tensors_that_do_not_fit_the_env_are_refused_and_nothing_is_written(tmp_path):
    rng = np.random.default_rng(2)
    layers = _mlp(rng, [OBS + 1, 16, ACT])  # one observation too many
    tensors = {f"actor.{i}.{p}": t for i, (w, b) in enumerate(layers) for p, t in (("weight", w), ("bias", b))}
    with pytest.raises(RuntimeError, match=r"actor.0.weight has shape \[16, 29\].*needs \[16, 28\]"):
        _core.import_policy(str(tmp_path / "bad"), _payload(tensors), _config("td3", [16]), "")
    assert not (tmp_path / "bad").exists()
    layers = _mlp(rng, [OBS, 16, ACT])
    tensors = {f"actor.{i}.{p}": t for i, (w, b) in enumerate(layers) for p, t in (("weight", w), ("bias", b))}
    del tensors["actor.1.bias"]
    with pytest.raises(RuntimeError, match="lacks the tensor"):
        _core.import_policy(str(tmp_path / "bad"), _payload(tensors), _config("td3", [16]), "")


@pytest.fixture
def sb3():
    return pytest.importorskip("stable_baselines3", reason="Stable-Baselines3 is optional (python/check_sb3.py)")


@pytest.mark.parametrize("algo", ["PPO", "PPO-relu", "SAC", "TD3", "DDPG"])
def test_a_converted_sb3_model_acts_as_sb3_predicts(tmp_path, algo, binary, sb3):
    import torch
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    locobench.register_envs()
    venv = make_vec_env("locobench/Minitaur-v0", n_envs=1, seed=0)
    norm = VecNormalize(venv, norm_reward=False) if algo in ("PPO", "PPO-relu", "TD3") else None
    kwargs = dict(policy_kwargs=dict(net_arch=[32, 32]), seed=0, device="cpu")
    if algo == "PPO-relu":
        # rl-baselines3-zoo's MuJoCo policy settings: separate ReLU networks, no orthogonal init
        kwargs["policy_kwargs"] = dict(net_arch=dict(pi=[32, 32], vf=[48, 48]), activation_fn=torch.nn.ReLU,
                                       log_std_init=-2, ortho_init=False)
    if algo.startswith("PPO"):
        kwargs.update(n_steps=64, batch_size=32, n_epochs=1)
    else:
        kwargs.update(learning_starts=32, buffer_size=1000)
    model = getattr(sb3, algo.split("-")[0])("MlpPolicy", norm or venv, **kwargs)
    model.learn(96)  # trained a little, so that no weight is at its initial value
    path = tmp_path / "model.zip"
    model.save(path)
    if norm is not None:
        norm.save(tmp_path / "vecnormalize.pkl")
    out = locobench.import_sb3(path, tmp_path / "policy", "locobench/Minitaur-v0",
                               vec_normalize=tmp_path / "vecnormalize.pkl" if norm else None)
    policy = locobench.load_policy(tmp_path / "policy")
    rng = np.random.default_rng(3)
    for obs in rng.normal(0, 2, (100, OBS)).astype(np.float32):
        x = norm.normalize_obs(obs) if norm else obs
        expected, _ = model.predict(x, deterministic=True)
        assert np.allclose(policy.predict(obs)[0], expected, atol=1e-5), algo
    printed = subprocess.run([str(binary), "eval", "--policy", str(tmp_path / "policy"), "--episodes", "2"],
                             check=True, capture_output=True, text=True).stdout
    assert "2 held-out episodes" in printed and out.endswith("policy.safetensors")


def test_unsupported_sb3_models_are_refused_by_name(tmp_path, sb3):
    import torch

    locobench.register_envs()
    env = "locobench/InvertedPendulum-v5"
    model = sb3.PPO("MlpPolicy", env, policy_kwargs=dict(activation_fn=torch.nn.ELU), device="cpu")
    with pytest.raises(ValueError, match="ELU layers are not supported"):
        locobench.import_sb3(model, tmp_path / "p", env)
    model = sb3.SAC("MlpPolicy", env, policy_kwargs=dict(activation_fn=torch.nn.Tanh), device="cpu")
    with pytest.raises(ValueError, match="Tanh activations are not supported"):
        locobench.import_sb3(model, tmp_path / "p", env)
    model = sb3.SAC("MlpPolicy", env, device="cpu")
    with pytest.raises(ValueError, match=r"observations \(4,\).*hopper"):
        locobench.import_sb3(model, tmp_path / "p", "hopper")
    model = sb3.A2C("MlpPolicy", env, device="cpu")
    with pytest.raises(ValueError, match="A2C is not supported"):
        locobench.import_sb3(model, tmp_path / "p", env)
    assert not (tmp_path / "p").exists()
