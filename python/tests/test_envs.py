"""The Python package, checked by the ecosystem's own tools and against Gymnasium's own envs."""
import math
import pathlib

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import locobench

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("env_id", sorted(locobench.ENV_IDS.values()))
def test_gymnasium_env_checker_passes(env_id):
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.observation_space.dtype == np.float64 and env.action_space.dtype == np.float32


def test_every_registered_env_has_an_id():
    assert sorted(locobench.env_names()) == sorted(locobench.ENV_IDS)


def test_options_and_reward_weights_are_keywords_and_terms_sum_to_the_reward():
    env = gym.make("locobench/Minitaur-v0", randomize_dynamics=False, max_episode_steps=50, reward={"drift": 1.0})
    env.reset(seed=3)
    steps = 0
    while True:
        obs, reward, terminated, truncated, info = env.step(np.zeros(8, dtype=np.float32))
        steps += 1
        terms = info["reward_terms"]
        assert set(terms) == {"distance", "energy", "drift", "shake"}
        assert math.isclose(sum(terms.values()), reward, rel_tol=1e-12, abs_tol=1e-15)
        if terminated or truncated:
            break
    assert truncated and steps == 50


def test_same_seed_same_trajectory():
    def run(seed):
        env = gym.make("locobench/HalfCheetah-v5")
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        out = [obs]
        for _ in range(20):
            out.append(env.step(rng.uniform(-1, 1, 6).astype(np.float32))[0])
        return np.array(out)

    assert np.array_equal(run(5), run(5))
    assert not np.array_equal(run(5), run(6))


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: gym.make("locobench/Minitaur-v0", no_such_option=1), "no_such_option"),
        (lambda: gym.make("locobench/Minitaur-v0", reward={"speed": 1.0}), "speed"),
        (lambda: gym.make("locobench/Minitaur-v0", max_episode_steps=-3), "max_episode_steps"),
        (lambda: gym.make("locobench/Minitaur-v0", payload_mass=-1.0), "payload_mass"),
        (lambda: gym.make("locobench/Minitaur-v0", terrain_step_height=0.5), "terrain_step_height"),
        (lambda: locobench.LocobenchEnv("no-such-env"), "no-such-env"),
        (lambda: locobench.LocobenchEnv("ant", render_mode="depth_array"), "render_mode='depth_array'"),
        (lambda: gym.make("locobench/Ant-v5", render_mode="rgb_array", camera="side"), "unknown camera 'side'"),
    ],
)
def test_bad_settings_raise_python_errors_naming_the_value(make, message):
    with pytest.raises((ValueError, TypeError, OverflowError)) as e:
        make()
    assert message in str(e.value)


def test_perturbations_are_options_and_change_the_world():
    # The robustness suite's perturbations reach Python envs as keywords: a heavier robot on
    # slippery ground stands differently from the nominal one under the same actions.
    def run(**options):
        env = gym.make("locobench/Minitaur-v0", randomize_dynamics=False, **options)
        env.reset(seed=3)
        action = np.zeros(8)
        return np.stack([env.step(action)[0] for _ in range(50)])

    nominal = run()
    assert np.array_equal(nominal, run())
    assert not np.array_equal(nominal, run(payload_mass=2.0, friction_scale=0.3))

    # Ant takes the world options it has a counterpart for; nominal values are Gymnasium's Ant.
    def ant(**options):
        env = gym.make("locobench/Ant-v5", **options)
        env.reset(seed=3)
        action = np.full(8, 0.5)
        return np.stack([env.step(action)[0] for _ in range(20)])

    plain = ant()
    assert np.array_equal(plain, ant(motor_strength=1.0, latency=0.0, slope=0.0))
    assert not np.array_equal(plain, ant(motor_strength=0.5, com_shift=0.1))
    with pytest.raises(ValueError, match="latency"):
        gym.make("locobench/Ant-v5", latency=2.0)


def test_bad_actions_raise_and_leave_the_episode_intact():
    env = gym.make("locobench/HalfCheetah-v5").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(5))
    with pytest.raises(ValueError, match="NaN|finite"):
        env.step(np.array([0, 0, np.nan, 0, 0, 0]))
    with pytest.raises(TypeError, match="dtype"):
        env.step(np.array(["a"] * 6))
    obs, *_ = env.step(np.zeros(6))
    assert obs.shape == (17,)


def test_stepping_before_reset_is_an_error():
    env = locobench.LocobenchEnv("hopper")
    with pytest.raises(ValueError, match="reset"):
        env.step(np.zeros(3))


def test_controller_walks_minitaur_at_its_command():
    controller = locobench.Controller("minitaur", speed=1.0)
    env = controller.env
    obs, _ = env.reset(seed=0)
    start = env.unwrapped.state[0][0]
    for _ in range(300):
        action, _ = controller.predict(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        assert not terminated
    distance = env.unwrapped.state[0][0] - start
    assert 2.0 < distance < 3.3, distance  # 3 s, ramping to 1 m/s over the first second


def test_controller_refuses_an_env_in_the_wrong_action_mode():
    with pytest.raises(ValueError, match="action_mode"):
        locobench.Controller(gym.make("locobench/Minitaur-v0"), speed=0.5)


def test_a_trained_policy_predicts_like_sb3_and_is_deterministic():
    policy = locobench.load_policy(ROOT / "models/policies/minitaur-td3")
    env = policy.make_env()
    obs, _ = env.reset(seed=11)
    action, state = policy.predict(obs)
    assert action.shape == (8,) and action.dtype == np.float32 and state is None
    assert np.array_equal(action, policy.predict(obs)[0])
    batch, _ = policy.predict(np.stack([obs, obs]))
    assert batch.shape == (2, 8) and np.array_equal(batch[0], action)
    total = 0.0
    for _ in range(200):
        obs, reward, terminated, truncated, _ = env.step(policy.predict(obs)[0])
        total += reward
        if terminated or truncated:
            break
    assert total > 0.5, total  # it walks forward
    with pytest.raises(ValueError, match="entries"):
        policy.predict(np.zeros(5))


@pytest.mark.parametrize("env_id", sorted(locobench.ENV_IDS.values()))
def test_every_env_renders_rgb_arrays_offscreen(env_id):
    env = gym.make(env_id, render_mode="rgb_array", width=96, height=64)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (64, 96, 3) and frame.dtype == np.uint8
    assert frame.std() > 5, "a blank frame"
    assert np.array_equal(frame, env.render()), "the same state rendered twice differs"
    env.step(env.action_space.sample())
    check_env(env.unwrapped)  # with the render check this time


def test_rgb_array_list_collects_a_frame_per_step_since_the_last_render():
    env = gym.make("locobench/Minitaur-v0", render_mode="rgb_array_list", width=64, height=48)
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    frames = env.render()
    assert len(frames) == 4 and all(f.shape == (48, 64, 3) for f in frames)
    env.step(env.action_space.sample())
    assert len(env.render()) == 1
    # "human" is Gymnasium's: its HumanRendering wrapper shows our rgb_array frames in a window.


def test_gymnasiums_record_video_writes_a_playable_file(tmp_path):
    pytest.importorskip("moviepy")
    env = gym.make("locobench/HalfCheetah-v5", render_mode="rgb_array", width=160, height=120, max_episode_steps=30)
    env = gym.wrappers.RecordVideo(env, str(tmp_path), episode_trigger=lambda e: True, disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        done = terminated or truncated
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1
    import subprocess

    probe = subprocess.run(
        ["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
         "stream=nb_read_frames,width,height", "-of", "csv=p=0", str(videos[0])],
        capture_output=True, text=True, check=True,
    )
    # The reset's frame and one per step.
    assert probe.stdout.strip() == "160,120,31"


def test_missing_or_corrupt_policy_files_raise(tmp_path):
    with pytest.raises(FileNotFoundError, match="no_such_dir"):
        locobench.load_policy(tmp_path / "no_such_dir")
    bad = tmp_path / "bad"
    bad.mkdir()
    source = ROOT / "models/policies/minitaur-td3"
    (bad / "config.toml").write_text((source / "config.toml").read_text())
    (bad / "policy.safetensors").write_bytes(b"not a safetensors file")
    with pytest.raises(RuntimeError):
        locobench.load_policy(bad)


def test_policy_device_is_checked():
    source = ROOT / "models/policies/minitaur-td3"
    with pytest.raises(ValueError, match="unknown device 'tpu'"):
        locobench.load_policy(source, device="tpu")
    if not locobench._core.CUDA_BUILT:
        with pytest.raises(RuntimeError, match="without the `cuda` feature"):
            locobench.load_policy(source, device="cuda")
    # on the CPU, the same policy as without the argument
    obs = [0.1] * len(locobench.load_policy(source).make_env().observation_space.low)
    a, _ = locobench.load_policy(source, device="cpu").predict(obs)
    b, _ = locobench.load_policy(source).predict(obs)
    assert (a == b).all()


# Same model, same start, same actions; MuJoCo 4.0 (PyPI) there, Debian's 2.2.2 here. Rounding
# differences between the engines grow along a trajectory (HalfCheetah's from 1e-15 at the first
# step to 1e-10 by step 40), so each is compared over its first steps.
@pytest.mark.parametrize("name, gym_id, steps", [("half-cheetah", "HalfCheetah-v5", 30), ("walker2d", "Walker2d-v5", 30)])
def test_matches_gymnasiums_own_mujoco_env_on_replayed_actions(name, gym_id, steps):
    mujoco = pytest.importorskip("mujoco")
    assert mujoco
    theirs = gym.make(gym_id).unwrapped
    ours = locobench.LocobenchEnv(name)
    obs_theirs, _ = theirs.reset(seed=0)
    ours.reset(seed=0)
    ours.set_state(theirs.data.qpos.copy(), theirs.data.qvel.copy())
    rng = np.random.default_rng(1)
    for t in range(steps):
        a = rng.uniform(-1, 1, theirs.action_space.shape).astype(np.float32)
        o1, r1, term1, _, _ = theirs.step(a)
        o2, r2, term2, _, _ = ours.step(a)
        np.testing.assert_allclose(o2, o1, rtol=0, atol=1e-9, err_msg=f"step {t}")
        # Gymnasium squares the float32 action in float32 for its control cost; we square in f64.
        assert abs(r1 - r2) < 1e-6 and term1 == term2
        if term1:
            break


def test_a_command_task_takes_a_joystick_command_on_a_live_env():
    env = gym.make("locobench/MinitaurCommand-v0", schedule="0:0.5:0")
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.command == (0.5, 0.0)
    assert tuple(obs[-2:]) == (0.5, 0.0)
    env.unwrapped.set_command(1.0, 0.2)
    obs, reward, *_ , info = env.step(env.action_space.sample() * 0)
    assert env.unwrapped.command == (1.0, 0.2)
    assert tuple(obs[-2:]) == (1.0, 0.2)
    assert info["metrics"]["command_speed"] == 1.0
    assert abs(sum(info["reward_terms"].values()) - reward) < 1e-12
    # the held command lasts until the next reset, which goes back to the schedule
    env.reset(seed=1)
    assert env.unwrapped.command == (0.5, 0.0)


def test_only_command_tasks_take_a_command():
    env = gym.make("locobench/Minitaur-v0")
    env.reset(seed=0)
    assert env.unwrapped.command is None
    with pytest.raises(ValueError, match="takes no velocity command"):
        env.unwrapped.set_command(1.0, 0.0)
