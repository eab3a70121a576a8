"""`locobench train --tensorboard DIR`, read back with TensorBoard's own reader: every value of
every metrics.csv row is a scalar at the row's step, and after a kill and a resume TensorBoard
shows the resumed run's values, not the ones the killed stretch logged past its checkpoint."""
import csv
import os
import subprocess

import numpy as np
import pytest

SETTINGS = (
    "hidden=[16,16],batch_size=32,warmup_steps=200,learning_starts=200,eval_every=500,eval_episodes=2,"
    "checkpoint_every=300"
)


def scalars(logdir):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(logdir), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def expected(run):
    """{tag: [(step, value)]} as metrics.csv holds them, values rounded to float32."""
    out = {}
    with open(run / "metrics.csv") as f:
        for row in csv.DictReader(f):
            for column, value in row.items():
                if column in ("kind", "step") or value == "":
                    continue
                out.setdefault(f"{row['kind']}/{column}", []).append((int(row["step"]), float(np.float32(value))))
    return out


def close(tag, got, want):
    """Equal to float32, but for the columns metrics.csv rounds (rate to 0.1, wall time to 1 ms)."""
    atol = {"steps_per_s": 0.05, "wall_time": 5e-4}.get(tag.split("/")[1], 0.0)
    return np.allclose([v for _, v in got], [v for _, v in want], rtol=1e-6, atol=atol)


def test_every_metric_reaches_tensorboard_and_a_resume_replaces_what_a_kill_left(tmp_path, binary):
    train = [str(binary), "train", "--env", "inverted-pendulum", "--algo", "td3", "--seed", "3", "--steps", "1500",
             "--set", SETTINGS, "--quiet", "--threads", "1"]

    whole, whole_tb = tmp_path / "whole", tmp_path / "whole-tb"
    subprocess.run(train + ["--out", str(whole), "--tensorboard", str(whole_tb)], check=True)
    got, want = scalars(whole_tb), expected(whole)
    assert sorted(got) == sorted(want)
    assert {"eval/eval_mean", "eval/eval_std", "episode/episode_return", "episode/critic_loss"} <= set(got)
    for tag in want:
        assert [s for s, _ in got[tag]] == [s for s, _ in want[tag]], tag
        assert close(tag, got[tag], want[tag]), tag

    # Killed mid-run (after checkpoints at about 300, 600 and 900 steps), then resumed.
    run, tb = tmp_path / "run", tmp_path / "tb"
    env = dict(os.environ, LOCOBENCH_FAULT="step:1200")
    killed = subprocess.run(train + ["--out", str(run), "--tensorboard", str(tb)], env=env)
    assert killed.returncode == -9
    subprocess.run([str(binary), "train", "--resume", str(run), "--tensorboard", str(tb), "--quiet"], check=True)
    assert len(list(tb.glob("events.out.tfevents.*"))) == 2
    got, want = scalars(tb), expected(run)
    for tag in want:
        assert [s for s, _ in got[tag]] == [s for s, _ in want[tag]], tag
        assert close(tag, got[tag], want[tag]), tag
    # The same numbers as the unbroken run (its wall-clock columns aside).
    for tag in ("eval/eval_mean", "episode/episode_return", "episode/critic_loss"):
        assert got[tag] == scalars(whole_tb)[tag], tag


def test_training_clips_reach_tensorboard_as_animated_gifs(tmp_path, binary):
    """With --video-every, each filmed evaluation is an image summary `eval/video` at its step: the
    GIF beside the run, which TensorBoard's image dashboard plays."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    run, tb = tmp_path / "run", tmp_path / "tb"
    subprocess.run([str(binary), "train", "--env", "inverted-pendulum", "--algo", "td3", "--seed", "3", "--steps",
                    "1000", "--set", SETTINGS, "--quiet", "--threads", "1", "--out", str(run), "--tensorboard",
                    str(tb), "--video-every", "1"], check=True)
    acc = EventAccumulator(str(tb), size_guidance={"images": 0})
    acc.Reload()
    assert "eval/video" in acc.Tags()["images"]
    images = acc.Images("eval/video")
    eval_steps = [int(r["step"]) for r in csv.DictReader(open(run / "metrics.csv")) if r["kind"] == "eval"]
    assert [i.step for i in images] == eval_steps
    for image in images:
        assert image.encoded_image_string == (run / "videos" / f"eval-step-{image.step}.gif").read_bytes()
        assert image.encoded_image_string.startswith(b"GIF89a")
        assert (image.width, image.height) == (320, 240)
