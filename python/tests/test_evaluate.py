"""`locobench.evaluate`: any policy on the protocol's held-out episodes, with the statistics
`locobench eval` prints (the same digits for a locobench policy), and clear errors for policies
and envs that do not fit."""
import pathlib
import subprocess

import numpy as np
import pytest

import locobench

ROOT = pathlib.Path(__file__).resolve().parents[2]
PPO = ROOT / "models" / "policies" / "minitaur-ppo"


def locobench_binary():
    for profile in ("debug", "release"):
        path = ROOT / "target" / profile / "locobench"
        if path.exists():
            return path
    pytest.fail("no target/debug/locobench: build it first (cargo build; scripts/test.sh does)")


def test_a_locobench_policy_gets_the_figures_locobench_eval_prints():
    result = locobench.evaluate(locobench.load_policy(PPO), episodes=4, seed=3)
    printed = subprocess.run([str(locobench_binary()), "eval", "--policy", str(PPO), "--episodes", "4", "--seed", "3"],
                             check=True, capture_output=True, text=True).stdout.splitlines()
    assert printed[0].endswith("4 held-out episodes (protocol seed 3)")
    assert result["text"].splitlines() == printed[1:]
    assert result["episodes"] == 4 and len(result["episode_returns"]) == 4
    low, high = result["return_mean"][1:]
    assert low <= result["return_mean"][0] <= high


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
