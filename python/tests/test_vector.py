"""The vector env: Gymnasium's same-step autoreset, per-copy seeds, and the same numbers on any
thread count."""
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import locobench


def rollout(envs, seed, steps, action_seed=0):
    """Observations, rewards, ends and final observations of `steps` random steps."""
    rng = np.random.default_rng(action_seed)
    obs, _ = envs.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        a = rng.uniform(-1, 1, size=envs.action_space.shape).astype(np.float32)
        obs, reward, terminated, truncated, info = envs.step(a)
        final = info.get("final_obs", np.full(envs.num_envs, None, dtype=object))
        out += [obs, reward, terminated, truncated]
        out += [f if f is not None else np.zeros(0) for f in final]
    return out


def test_make_vec_builds_the_rust_vector_env_in_same_step_mode():
    envs = gym.make_vec("locobench/Hopper-v5", num_envs=3, reset_noise_scale=0.01)
    assert isinstance(envs.unwrapped, locobench.LocobenchVectorEnv)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert envs.observation_space.shape == (3, 11) and envs.action_space.shape == (3, 3)
    assert envs.observation_space.dtype == np.float64 and envs.action_space.dtype == np.float32
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, 11) and info == {}
    obs, reward, terminated, truncated, info = envs.step(np.zeros((3, 3), dtype=np.float32))
    assert obs.shape == (3, 11) and reward.shape == (3,) and reward.dtype == np.float64
    assert terminated.dtype == bool and truncated.dtype == bool
    assert info["reward_terms"]["forward"].shape == (3,) and info["_reward_terms"].all()


def test_each_copy_is_the_single_env_with_its_episode_seeds():
    """Copy i replays a single env reset with episode_seed(seed, i, k) for its k-th episode,
    including across the automatic reset (a 5-step time limit)."""
    envs = locobench.LocobenchVectorEnv("half-cheetah", num_envs=3, threads=2, max_episode_steps=5)
    single = locobench.LocobenchEnv("half-cheetah", max_episode_steps=5)
    seed = 11
    obs, _ = envs.reset(seed=seed)
    actions = np.random.default_rng(1).uniform(-1, 1, size=(7, 3, 6)).astype(np.float32)
    expected = []
    for i in range(3):
        o, _ = single.reset(seed=locobench.episode_seed(seed, i, 0))
        copy = [(o, None, None, None)]
        for t in range(7):
            o, r, term, trunc, _ = single.step(actions[t, i])
            last = o
            if term or trunc:
                o, _ = single.reset(seed=locobench.episode_seed(seed, i, 1))
            copy.append((o, r, trunc, last if trunc else None))
        expected.append(copy)
    for i in range(3):
        np.testing.assert_array_equal(obs[i], expected[i][0][0])
    for t in range(7):
        obs, reward, terminated, truncated, info = envs.step(actions[t])
        for i in range(3):
            o, r, trunc, last = expected[i][t + 1]
            np.testing.assert_array_equal(obs[i], o)
            assert reward[i] == r and truncated[i] == trunc and not terminated[i]
            if last is None:
                assert "final_obs" not in info or info["final_obs"][i] is None
            else:
                assert info["_final_obs"][i] and info["_final_info"][i]
                np.testing.assert_array_equal(info["final_obs"][i], last)
                assert info["final_info"]["_reward_terms"][i]


def assert_same_infos(ours, theirs, path="infos"):
    assert set(ours) == set(theirs), f"{path}: keys {sorted(ours)} vs {sorted(theirs)}"
    for key in theirs:
        a, b = ours[key], theirs[key]
        if isinstance(b, dict):
            assert_same_infos(a, b, f"{path}[{key!r}]")
        else:
            assert a.dtype == b.dtype and a.shape == b.shape, f"{path}[{key!r}]: {a.dtype}{a.shape} vs {b.dtype}{b.shape}"
            for x, y in zip(a, b):
                if isinstance(y, np.ndarray) or isinstance(x, np.ndarray):
                    np.testing.assert_array_equal(x, y)
                else:
                    assert x == y, f"{path}[{key!r}]: {a} vs {b}"


@pytest.mark.parametrize("threads", [1, 2])
def test_infos_batched_in_rust_equal_gymnasiums_batching_of_each_copys_dict(threads):
    """The step's infos, batched in Rust, are what Gymnasium's ``_add_info`` makes of the copies'
    info dicts (same keys, masks, values and dtypes), with episodes ending in none of the copies,
    in all of them (a 7-step time limit) and in some (a 12-step limit, which some copies' falls
    come before); actions in any memory layout (a transposed view here) step alike. Each step's
    arrays are its own: a result kept is not overwritten by later steps."""
    ended = []
    for limit in (7, 12):
        fast = locobench.LocobenchVectorEnv("hopper", num_envs=3, threads=threads, max_episode_steps=limit)
        slow = locobench.LocobenchVectorEnv("hopper", num_envs=3, threads=threads, max_episode_steps=limit)
        fast.reset(seed=4)
        slow.reset(seed=4)
        rng = np.random.default_rng(2)
        for _ in range(30):
            a = rng.uniform(-1, 1, size=(3, 3))
            out = fast.step(np.ascontiguousarray(a.T).T)
            ref = slow._step_with_dicts(a)
            for x, y in zip(out[:4], ref[:4]):
                np.testing.assert_array_equal(x, y)
                assert x.dtype == y.dtype
            assert_same_infos(out[4], ref[4])
            ended.append(out[4].get("_final_obs", np.zeros(3, dtype=bool)).sum())
    assert 0 in ended and 3 in ended and any(0 < e < 3 for e in ended), ended
    first = fast.step(np.zeros((3, 3)))
    kept = [first[0], first[1], first[4]["reward_terms"]["forward"]]
    copies = [x.copy() for x in kept]
    fast.step(np.ones((3, 3)))
    for x, y in zip(kept, copies):
        np.testing.assert_array_equal(x, y)


def test_float32_actions_step_as_their_float64_values():
    """float32 actions (what SB3 and CleanRL policies give) go to Rust as they are and step
    exactly as the same values in float64; the binding leaves arrays of other types and shapes to the
    Python side (None, without stepping), which converts them or refuses them by name."""
    ours = locobench.LocobenchVectorEnv("half-cheetah", num_envs=4, threads=2)
    ref = locobench.LocobenchVectorEnv("half-cheetah", num_envs=4, threads=2)
    ours.reset(seed=9)
    ref.reset(seed=9)
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.uniform(-1, 1, size=(4, 6)).astype(np.float32)
        out, expected = ours.step(a), ref.step(a.astype(np.float64))
        for x, y in zip(out[:4], expected[:4]):
            np.testing.assert_array_equal(x, y)
        assert_same_infos(out[4], expected[4])
    for other in (np.zeros((4, 6), dtype=np.int64), np.zeros((4, 5), dtype=np.float32), np.zeros(24), [[0.0] * 6] * 4):
        assert ours._core.step_gym(other) is None
    a = np.zeros((4, 6), dtype=np.int64)
    out, expected = ours.step(a), ref.step(a.astype(np.float64))
    for x, y in zip(out[:4], expected[:4]):
        np.testing.assert_array_equal(x, y)
    with pytest.raises(ValueError, match=r"actions shape \(4, 5\), expected \(4, 6\)"):
        ours.step(np.zeros((4, 5), dtype=np.float32))
    with pytest.raises(TypeError, match="actions dtype <U1 is not numeric"):
        ours.step(np.full((4, 6), "a"))


def test_same_numbers_on_one_thread_and_two():
    one = rollout(locobench.LocobenchVectorEnv("hopper", num_envs=4, threads=1), seed=5, steps=60)
    two = rollout(locobench.LocobenchVectorEnv("hopper", num_envs=4, threads=2), seed=5, steps=60)
    assert len(one) == len(two)
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a, b)
    other = rollout(locobench.LocobenchVectorEnv("hopper", num_envs=4, threads=2), seed=6, steps=60)
    assert not np.array_equal(one[0], other[0])


def test_unseeded_resets_continue_deterministically_from_the_last_seed():
    a = locobench.LocobenchVectorEnv("inverted-pendulum", num_envs=2)
    b = locobench.LocobenchVectorEnv("inverted-pendulum", num_envs=2)
    first_a, _ = a.reset(seed=3)
    first_b, _ = b.reset(seed=3)
    np.testing.assert_array_equal(first_a, first_b)
    second_a, _ = a.reset()
    second_b, _ = b.reset()
    np.testing.assert_array_equal(second_a, second_b)
    assert not np.array_equal(first_a, second_a)


def test_bad_input_is_refused_with_a_message():
    envs = locobench.LocobenchVectorEnv("hopper", num_envs=2)
    with pytest.raises(ValueError, match="before reset"):
        envs.step(np.zeros((2, 3)))
    envs.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        envs.step(np.zeros((3, 3)))
    bad = np.zeros((2, 3))
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="copy 1"):
        envs.step(bad)
    with pytest.raises(TypeError):
        envs.step(np.array([["a"] * 3] * 2))
    with pytest.raises(ValueError, match="seed"):
        envs.reset(seed=-1)
    with pytest.raises(ValueError, match="num_envs"):
        locobench.LocobenchVectorEnv("hopper", num_envs=0)
    with pytest.raises(ValueError, match="threads"):
        locobench.LocobenchVectorEnv("hopper", num_envs=2, threads=0)
    with pytest.raises(ValueError, match="no_such_option"):
        locobench.LocobenchVectorEnv("hopper", num_envs=2, no_such_option=1)


@pytest.mark.skipif(locobench._core.BUILD_PROFILE == "release", reason="a release build runs the whole benchmark")
def test_the_speed_benchmark_refuses_a_dev_build():
    import pathlib
    import subprocess
    import sys

    root = pathlib.Path(__file__).resolve().parents[2]
    assert locobench._core.BUILD_PROFILE == "dev"
    out = subprocess.run([sys.executable, str(root / "python/bench_speed.py"), "10"], capture_output=True, text=True)
    assert out.returncode != 0 and out.stdout == ""
    assert "is a dev build" in out.stderr and "bash python/install.sh" in out.stderr, out.stderr
    out = subprocess.run([sys.executable, str(root / "python/bench_speed.py"), "10", "hopper", "walker"],
                         capture_output=True, text=True)
    assert out.returncode != 0 and out.stdout == "" and "unknown env 'walker'" in out.stderr, out.stderr


def test_the_speed_benchmark_gives_each_gain_a_seeded_bootstrap_interval():
    import importlib.util
    import pathlib

    import numpy as np

    path = pathlib.Path(__file__).resolve().parents[2] / "python/bench_speed.py"
    spec = importlib.util.spec_from_file_location("bench_speed", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    ratios = np.random.default_rng(7).normal(1.8, 0.05, size=90)
    median, low, high = bench.median_interval(ratios)
    assert median == np.median(ratios) and low < median < high
    assert bench.median_interval(ratios) == (median, low, high), "the same seed gives the same interval"
    assert bench.median_interval(ratios, seed=1) != (median, low, high)
    # Four times the spread: an interval about four times as wide, around the same centre.
    wide = bench.median_interval(1.8 + 4 * (ratios - 1.8))
    assert 3 < (wide[2] - wide[1]) / (high - low) < 5
    assert bench.median_interval(np.full(90, 1.75)) == (1.75, 1.75, 1.75)
