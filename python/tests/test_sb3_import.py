"""`locobench.import_sb3`: SB3 models as locobench policies. Without Stable-Baselines3 installed,
the conversion's target is checked against a NumPy forward pass of each layout (PPO's tanh MLP
behind VecNormalize, SAC's squashed mean, TD3's tanh output); with it, converted models against
SB3's own `predict` on 100 observations (within 1e-5), and unsupported models refused."""
import os
import pathlib
import subprocess

import numpy as np
import pytest

import locobench
from locobench import _core

OBS, ACT = 28, 8  # Minitaur
ROOT_POLICY = pathlib.Path(__file__).resolve().parents[2] / "models" / "policies" / "minitaur-td3"


def _mlp(rng, sizes):
    return [(rng.normal(0, 0.3, (o, i)), rng.normal(0, 0.1, o)) for i, o in zip(sizes, sizes[1:])]


def _forward(layers, x, hidden):
    for k, (w, b) in enumerate(layers):
        x = w @ x + b
        if k < len(layers) - 1:
            x = hidden(x)
    return x


def _config(algo, hidden, extra="", options=()):
    env = _core.Env("minitaur", list(options), [])
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
    """Stable-Baselines3, which the test command installs (LOCOBENCH_REQUIRE_SB3=1: a missing one
    fails); a bare `pytest` run without it skips these tests."""
    if os.environ.get("LOCOBENCH_REQUIRE_SB3") == "1":
        import stable_baselines3
        return stable_baselines3
    return pytest.importorskip("stable_baselines3", reason="Stable-Baselines3 is optional (python/check_sb3.py)")


def _trained(sb3, algo, normalized, tmp_path):
    """A small SB3 model of `algo` on Minitaur, trained a little (so that no weight is at its
    initial value), saved to tmp_path/model.zip; behind VecNormalize when `normalized`."""
    import torch
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    locobench.register_envs()
    venv = make_vec_env("locobench/Minitaur-v0", n_envs=1, seed=0)
    norm = VecNormalize(venv, norm_reward=False) if normalized else None
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
    model.learn(96)
    model.save(tmp_path / "model.zip")
    if norm is not None:
        norm.save(tmp_path / "vecnormalize.pkl")
        norm.training = False  # frozen, as SB3 evaluates
    return model, norm


@pytest.mark.parametrize("normalized", [True, False], ids=["vecnormalize", "raw"])
@pytest.mark.parametrize("algo", ["PPO", "PPO-relu", "SAC", "TD3", "DDPG"])
def test_a_converted_sb3_model_acts_as_sb3_predicts(tmp_path, algo, normalized, binary, sb3):
    model, norm = _trained(sb3, algo, normalized, tmp_path)
    out = locobench.import_sb3(tmp_path / "model.zip", tmp_path / "policy", "locobench/Minitaur-v0",
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
    source = (tmp_path / "policy" / "source.toml").read_text()
    assert f"step = {model.num_timesteps}" in source, "the budget the model counted"


def test_evaluate_feeds_an_sb3_model_what_its_vecnormalize_gives_it(tmp_path, sb3):
    """`evaluate(model, vec_normalize=...)` (the object or its .pkl) gives the model SB3's frozen
    normalisation, as SB3's own evaluation does: each observation predict sees is
    `normalize_obs` of the env's."""
    model, norm = _trained(sb3, "TD3", True, tmp_path)
    seen, raw = [], []
    predict = model.predict

    def spy(observation, **kwargs):
        seen.append(np.asarray(observation))
        return predict(observation, **kwargs)

    model.predict = spy
    by_path = locobench.evaluate(model, "minitaur", episodes=1, vec_normalize=tmp_path / "vecnormalize.pkl")
    by_object = locobench.evaluate(model, "minitaur", episodes=1, vec_normalize=norm)
    assert by_path["episode_returns"] == by_object["episode_returns"]
    by_hand = locobench.evaluate(lambda obs: raw.append(obs) or predict(norm.normalize_obs(obs), deterministic=True)[0],
                                 "minitaur", episodes=1)
    assert by_hand["episode_returns"] == by_path["episode_returns"]
    n = len(raw)
    assert len(seen) == 2 * n
    for obs, normed in zip(raw, seen[:n]):
        assert np.array_equal(normed, norm.normalize_obs(obs))
    with pytest.raises(ValueError, match=r"shape \(28,\); the env's have \(11,\)"):
        locobench.evaluate(model, "hopper", episodes=1, vec_normalize=norm)


def test_unsupported_sb3_models_are_refused_by_name(tmp_path, sb3):
    import gymnasium as gym
    import sb3_contrib
    import torch
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    locobench.register_envs()
    env = "locobench/InvertedPendulum-v5"

    def refused(model, match, target=env):
        with pytest.raises(ValueError, match=match):
            locobench.import_sb3(model, tmp_path / "p", target)
        assert not (tmp_path / "p").exists()

    refused(sb3.PPO("MlpPolicy", env, policy_kwargs=dict(activation_fn=torch.nn.ELU), device="cpu"),
            "ELU layers are not supported")
    refused(sb3.SAC("MlpPolicy", env, policy_kwargs=dict(activation_fn=torch.nn.Tanh), device="cpu"),
            "Tanh activations are not supported")
    refused(sb3.SAC("MlpPolicy", env, device="cpu"), r"observations \(4,\).*hopper", "hopper")
    refused(sb3.A2C("MlpPolicy", env, device="cpu"), "A2C is not supported")
    refused(sb3.SAC("MlpPolicy", env, device="cpu"), "unknown env 'locobench/Nope-v0'", "locobench/Nope-v0")

    class Images(gym.Env):  # the smallest image NatureCNN takes
        observation_space = gym.spaces.Box(0, 255, (36, 36, 3), np.uint8)
        action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

        def reset(self, seed=None, options=None):
            return self.observation_space.sample(), {}

        def step(self, action):
            return self.observation_space.sample(), 0.0, False, False, {}

    refused(sb3.PPO("CnnPolicy", Images(), device="cpu"), "CnnPolicy is not supported")
    refused(sb3_contrib.RecurrentPPO("MlpLstmPolicy", env, device="cpu"), r"RecurrentPPO \(recurrent\) is not supported")

    class Extractor(BaseFeaturesExtractor):
        def __init__(self, space):
            super().__init__(space, 16)
            self.net = torch.nn.Linear(space.shape[0], 16)

        def forward(self, x):
            return torch.relu(self.net(x))

    refused(sb3.SAC("MlpPolicy", env, policy_kwargs=dict(features_extractor_class=Extractor), device="cpu"),
            r"custom features extractor \(Extractor\) is not supported")
    refused(sb3.PPO("MlpPolicy", env, use_sde=True, device="cpu"), r"gSDE \(use_sde=True\) is not supported")


def test_an_imported_policy_is_a_report_row_labelled_with_its_source(tmp_path, binary):
    """`report --runs` takes an exported policy that `import_sb3` wrote (here through the same
    `_core.import_policy` call, with a TD3 actor made in NumPy): its own row, labelled as imported
    with its library, model file and the steps its source states, or 'steps unknown'."""
    rng = np.random.default_rng(4)
    layers = _mlp(rng, [OBS, 16, ACT])
    tensors = {f"actor.{i}.{p}": t for i, (w, b) in enumerate(layers) for p, t in (("weight", w), ("bias", b))}
    source = ('library = "stable-baselines3 2.9.2"\nalgorithm = "TD3"\nmodel_file = "td3-minitaur.zip"\n'
              'model_sha256 = "ab12"\nvec_normalize = false\n')
    _core.import_policy(str(tmp_path / "td3-sb3-seed0"), _payload(tensors), _config("td3", [16]), source + "step = 300000\n")
    _core.import_policy(str(tmp_path / "td3-other-seed0"), _payload(tensors), _config("td3", [16]), source)
    report = tmp_path / "report"
    done = subprocess.run([str(binary), "report", "--runs", str(tmp_path / "td3-sb3-seed0"), str(tmp_path / "td3-other-seed0"),
                           "--out", str(report), "--episodes", "2", "--push-episodes", "0"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    md = (report / "README.md").read_text()
    assert "| td3-sb3 (imported, stable-baselines3 2.9.2) | 300k | 1 of 1 | 2 |" in md, md
    assert "| td3-other (imported, stable-baselines3 2.9.2) | steps unknown | 1 of 1 | 2 |" in md, md
    assert "imported from stable-baselines3 2.9.2 (td3-minitaur.zip, SHA-256 ab12), trained for 300k" in md
    assert "its training steps not stated" in md
    held_out = (report / "held_out.csv").read_text()
    assert "td3-sb3 (imported" in held_out

    # An imported policy whose env this build does not know: an error naming it, no report.
    config = tmp_path / "td3-other-seed0" / "config.toml"
    config.write_text(config.read_text().replace('name = "minitaur"', 'name = "minitaur-x"'))
    elsewhere = tmp_path / "report-2"
    done = subprocess.run([str(binary), "report", "--runs", str(tmp_path / "td3-other-seed0"), "--out", str(elsewhere),
                           "--episodes", "2"], capture_output=True, text=True)
    assert done.returncode != 0 and "td3-other-seed0: its env in config.toml" in done.stderr, done.stderr
    assert "unknown environment 'minitaur-x'" in done.stderr and not (elsewhere / "index.html").exists()


def test_evaluate_applies_a_vecnormalizes_frozen_statistics(tmp_path):
    """A model trained behind VecNormalize sees the observations SB3's own evaluation gives it:
    clip((obs - mean) / sqrt(var + epsilon), +-clip_obs); statistics of another size are refused."""

    class Stats:  # the attributes of SB3's RunningMeanStd and VecNormalize
        def __init__(self, n):
            self.mean, self.var = np.linspace(-1, 1, n), np.linspace(0.5, 2, n)

    class Normalize:
        def __init__(self, n):
            self.obs_rms, self.clip_obs, self.epsilon, self.norm_obs = Stats(n), 5.0, 1e-8, True

    norm = Normalize(11)
    seen = []

    class Model:
        def predict(self, observation, deterministic=True):
            seen.append(observation)
            return np.zeros(3, dtype=np.float32), None

    plain = []
    locobench.evaluate(lambda obs: plain.append(obs) or np.zeros(3), "hopper", episodes=1)
    locobench.evaluate(Model(), "hopper", episodes=1, vec_normalize=norm)
    assert len(seen) == len(plain)
    for raw, normed in zip(plain, seen):
        expected = np.clip((raw - norm.obs_rms.mean) / np.sqrt(norm.obs_rms.var + 1e-8), -5, 5).astype(np.float32)
        assert normed.dtype == np.float32 and np.array_equal(normed, expected)
    with pytest.raises(ValueError, match=r"shape \(28,\); the env's have \(11,\)"):
        locobench.evaluate(Model(), "hopper", episodes=1, vec_normalize=Normalize(28))
    (tmp_path / "junk.pkl").write_bytes(b"not a pickle")
    with pytest.raises(ValueError, match="junk.pkl: not a VecNormalize pickle"):
        locobench.evaluate(Model(), "hopper", episodes=1, vec_normalize=tmp_path / "junk.pkl")
    with pytest.raises(ValueError, match="normalises its observations itself"):
        locobench.evaluate(locobench.load_policy(ROOT_POLICY), episodes=1, vec_normalize=norm)


def test_external_episodes_join_the_group_played_under_their_options(tmp_path, binary):
    """A report with two groups in one env (the shipped PPO under the default reward, an imported
    policy under energy weight 0): episodes evaluated outside under energy weight 0 join as a row
    compared in that group's env; under options no group has, they are refused by name."""
    rng = np.random.default_rng(5)
    layers = _mlp(rng, [OBS, 16, ACT])
    tensors = {f"actor.{i}.{p}": t for i, (w, b) in enumerate(layers) for p, t in (("weight", w), ("bias", b))}
    energy0 = tmp_path / "energy0-seed0"
    _core.import_policy(str(energy0), _payload(tensors), _config("td3", [16], options=[("energy_weight", "0.0")]),
                        'library = "test 1.0"\nstep = 1000\n')
    zero = lambda obs: np.zeros(ACT)  # noqa: E731
    locobench.evaluate(zero, "minitaur", episodes=2, reward={"energy": 0.0}, out=tmp_path / "zero-energy0", label="zero")
    locobench.evaluate(zero, "minitaur", episodes=2, reward={"drift": 0.5}, out=tmp_path / "zero-drift", label="zero")
    ppo = pathlib.Path(__file__).resolve().parents[2] / "models" / "policies" / "minitaur-ppo"

    def report(external):
        return subprocess.run([str(binary), "report", "--runs", str(ppo), str(energy0), "--out", str(tmp_path / "r"),
                               "--episodes", "2", "--push-episodes", "0", "--no-cache", "--external", str(external)],
                              capture_output=True, text=True)

    done = report(tmp_path / "zero-energy0")
    assert done.returncode == 0, done.stderr
    assert "| zero (external) | steps unknown | 1 of 1 | 2 |" in (tmp_path / "r" / "README.md").read_text()
    refused = report(tmp_path / "zero-drift")
    assert refused.returncode != 0 and "zero-drift: played minitaur under other options or rewards" in refused.stderr
    assert "none of its 2 groups there matches" in refused.stderr and "drift_weight" in refused.stderr, refused.stderr
