"""`locobench.evaluate`: any policy on the protocol's held-out episodes, with the statistics
`locobench eval` prints (the same digits for a locobench policy), and clear errors for policies
and envs that do not fit."""
import pathlib
import subprocess
import warnings

import numpy as np
import pytest

import locobench

ROOT = pathlib.Path(__file__).resolve().parents[2]
PPO = ROOT / "models" / "policies" / "minitaur-ppo"


SHIPPED = sorted(p for p in (ROOT / "models" / "policies").iterdir() if (p / "policy.safetensors").is_file())


def test_every_policy_that_ships_is_tested_here():
    names = {p.name for p in SHIPPED}
    assert {"minitaur-ppo", "minitaur-ppo-robust", "minitaur-ppo-robust-com", "minitaur-sac", "minitaur-td3",
            "minitaur-command-ppo"} <= names


@pytest.mark.parametrize("shipped", SHIPPED, ids=lambda p: p.name)
def test_a_locobench_policy_gets_the_figures_locobench_eval_prints(binary, shipped):
    """Digit for digit, for every shipped policy: the robust ones trained under pushes, rough
    ground, latency and noise are scored in the nominal world by both."""
    result = locobench.evaluate(locobench.load_policy(shipped), episodes=4, seed=3)
    printed = subprocess.run([str(binary), "eval", "--policy", str(shipped), "--episodes", "4", "--seed", "3"],
                             check=True, capture_output=True, text=True).stdout.splitlines()
    assert printed[0].endswith("4 held-out episodes (protocol seed 3)")
    assert result["text"].splitlines() == printed[1:]
    assert result["episodes"] == 4 and len(result["episode_returns"]) == 4
    low, high = result["return_mean"][1:]
    assert low <= result["return_mean"][0] <= high


def test_options_and_reward_over_a_policys_world_agree_with_eval_option_and_reward(binary):
    """`evaluate(policy, options=..., reward=...)` lays them over the policy's evaluation world, as
    `eval --option --reward` does; the training perturbations stay off."""
    robust = ROOT / "models" / "policies" / "minitaur-ppo-robust"
    result = locobench.evaluate(locobench.load_policy(robust), episodes=2, seed=3, options={"payload_mass": 1.0},
                                reward={"energy": 0.0})
    printed = subprocess.run([str(binary), "eval", "--policy", str(robust), "--episodes", "2", "--seed", "3",
                              "--option", "payload_mass=1.0", "--reward", "energy=0"],
                             check=True, capture_output=True, text=True).stdout.splitlines()
    assert result["text"].splitlines() == printed[1:]
    assert result["reward_terms"]["energy"] == 0.0


def test_a_command_policy_on_a_fixed_command_agrees_with_eval(binary):
    """A command-task policy given one command through `options`, as `eval --option schedule=...`
    gives it: the same episodes, the same digits, and the same warning for a command outside the
    policy's training range."""
    policy = ROOT / "models" / "policies" / "minitaur-command-ppo"
    schedule = "0:1.0:0 4:1.5:0.3"
    result = locobench.evaluate(locobench.load_policy(policy), episodes=2, seed=3, options={"schedule": schedule})
    done = subprocess.run([str(binary), "eval", "--policy", str(policy), "--episodes", "2", "--seed", "3",
                           "--option", f"schedule={schedule}"], check=True, capture_output=True, text=True)
    assert result["text"].splitlines() == done.stdout.splitlines()[1:]
    assert "tracking_speed" in result["reward_terms"]
    outside = subprocess.run([str(binary), "eval", "--policy", str(policy), "--episodes", "1",
                              "--option", "schedule=0:3.0:0"], check=True, capture_output=True, text=True)
    assert "outside" in outside.stderr and "speed_range [0, 2.5]" in outside.stderr
    # evaluate warns with eval's words, and stays quiet inside the range
    with pytest.warns(UserWarning, match=r"command speed 3 m/s lies outside .*speed_range \[0, 2.5\]"):
        locobench.evaluate(locobench.load_policy(policy), episodes=1, options={"schedule": "0:3.0:0"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        locobench.evaluate(locobench.load_policy(policy), episodes=1, options={"schedule": schedule})


def test_a_robust_policys_env_is_nominal_unless_asked():
    policy = locobench.load_policy(ROOT / "models" / "policies" / "minitaur-ppo-robust")
    training = dict(policy._core.env_options)
    nominal = dict(policy._core.evaluation_options)
    perturbations = set(training) - set(nominal)
    assert perturbations, "the robust policy trained under perturbations"
    assert all(nominal[k] == training[k] for k in nominal)
    default = locobench.LocobenchEnv("minitaur")._core
    env = policy.make_env().unwrapped._core
    assert all(env.option_value(k) == default.option_value(k) for k in perturbations), perturbations
    assert any(default.option_value(k) != training[k] for k in perturbations)
    perturbed = policy.make_env(perturbed=True).unwrapped._core
    assert all(perturbed.option_value(k) == training[k] for k in perturbations)


def test_any_callable_or_predict_plays_the_same_episodes():
    zero = locobench.evaluate(lambda obs: np.zeros(3), "locobench/Hopper-v5", episodes=3)
    again = locobench.evaluate(lambda obs: np.zeros(3), "hopper", episodes=3)
    assert zero["episode_returns"] == again["episode_returns"]
    assert set(zero["reward_terms"]) >= {"forward", "healthy"}

    class Predictor:  # SB3's interface
        def predict(self, observation, deterministic=True):
            assert deterministic and observation.dtype == np.float32
            return np.zeros(3, dtype=np.float32), None

    assert locobench.evaluate(Predictor(), "hopper", episodes=3)["episode_returns"] == zero["episode_returns"]
    other = locobench.evaluate(lambda obs: np.zeros(3), "hopper", episodes=3, seed=1)
    assert other["episode_returns"] != zero["episode_returns"], "another protocol seed, other episodes"


def test_the_controller_at_the_policys_speed_and_pushes():
    result = locobench.evaluate(locobench.load_policy(PPO), episodes=2, controller=True, pushes=[0.25, 1.0])
    c = result["controller"]
    assert c is not None and abs(c["commanded"] - round(result["speed"], 3)) < 1e-9
    assert 0.0 <= c["policy_better"][0] <= 1.0 and c["episodes"] == 2
    assert set(result["pushes"]) == {0.25, 1.0}
    survived, n, (rate, low, high) = result["pushes"][0.25]
    assert n == 2 and 0 <= survived <= 2 and low <= rate <= high


def test_policies_and_envs_that_do_not_fit_are_clear_errors():
    with pytest.raises(ValueError, match=r"shape \(2,\); the env takes \(3,\)"):
        locobench.evaluate(lambda obs: np.zeros(2), "hopper", episodes=1)
    with pytest.raises(ValueError, match="non-finite"):
        locobench.evaluate(lambda obs: np.full(3, np.nan), "hopper", episodes=1)
    with pytest.raises(TypeError, match="not numbers"):
        locobench.evaluate(lambda obs: ["a", "b", "c"], "hopper", episodes=1)
    with pytest.raises(ZeroDivisionError):
        locobench.evaluate(lambda obs: 1 / 0, "hopper", episodes=1)
    with pytest.raises(ValueError, match="unknown env"):
        locobench.evaluate(lambda obs: np.zeros(3), "locobench/Hopper-v9", episodes=1)
    with pytest.raises(ValueError, match="trained on minitaur, not hopper"):
        locobench.evaluate(locobench.load_policy(PPO), "hopper", episodes=1)
    with pytest.raises(ValueError, match="has no controller"):
        locobench.evaluate(lambda obs: np.zeros(3), "hopper", episodes=1, controller=True)
    with pytest.raises(ValueError, match="push level"):
        locobench.evaluate(lambda obs: np.zeros(3), "hopper", episodes=1, pushes=[-1.0])
    with pytest.raises(TypeError, match="predict or be a callable"):
        locobench.evaluate(42, "hopper", episodes=1)


def test_external_episodes_become_a_report_row_beside_ours(tmp_path, binary):
    """evaluate(..., out=DIR) writes the episodes with their provenance; `report --external`
    adds them as one row per label, marked as external, with the statistics computed from them;
    files from another protocol or env options, or damaged ones, are refused by name."""
    zero = lambda obs: np.zeros(8)  # noqa: E731
    results = []
    for s in (0, 1):
        results.append(locobench.evaluate(zero, "minitaur", episodes=2, out=tmp_path / f"zero-{s}", label="zero",
                                          training_seed=s, steps=1000, author="test"))
    meta = (tmp_path / "zero-0" / "external.toml").read_text()
    assert 'label = "zero"' in meta and 'library = "python"' in meta and 'author = "test"' in meta
    binary = str(binary)
    report = tmp_path / "report"

    def run_report(*external):
        return subprocess.run([binary, "report", "--runs", str(PPO), "--out", str(report), "--episodes", "2",
                               "--push-episodes", "0", "--external", *map(str, external)],
                              capture_output=True, text=True)

    done = run_report(tmp_path / "zero-0", tmp_path / "zero-1")
    assert done.returncode == 0, done.stderr
    md = (report / "README.md").read_text()
    assert "| zero (external) | 1k | 2 of 2 | 2 |" in md, md
    assert "evaluated outside locobench" in md
    rows = [line.split(",") for line in (report / "held_out.csv").read_text().splitlines()]
    row = next(r for r in rows if r[1] == "zero (external)")
    per_seed = [np.mean(r["episode_returns"]) for r in results]
    assert abs(float(row[6]) - np.mean(per_seed)) < 1e-12, (row, per_seed)
    assert "zero (external)" in (report / "versus_controller.csv").read_text()

    locobench.evaluate(zero, "minitaur", episodes=3, out=tmp_path / "three", label="zero")
    refused = run_report(tmp_path / "three")
    assert refused.returncode != 0 and "three: 3 episodes with protocol seed 0" in refused.stderr
    locobench.evaluate(zero, "minitaur", episodes=2, options={"randomize_dynamics": False}, out=tmp_path / "other",
                       label="zero")
    refused = run_report(tmp_path / "other")
    assert refused.returncode != 0 and "other options or rewards" in refused.stderr and "randomize_dynamics" in refused.stderr
    episodes = tmp_path / "zero-1" / "episodes.csv"
    lines = episodes.read_text().splitlines()
    lines[2] = lines[2].replace(",", ",x", 1)
    episodes.write_text("\n".join(lines) + "\n")
    refused = run_report(tmp_path / "zero-1")
    assert refused.returncode != 0 and "episodes.csv, line 3" in refused.stderr, refused.stderr
    with pytest.raises(ValueError, match="label"):
        locobench.evaluate(zero, "minitaur", episodes=1, out=tmp_path / "nolabel")
