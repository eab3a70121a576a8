"""Env steps per second through the Python API, beside Gymnasium's own MuJoCo envs, in one run.

    python python/bench_speed.py [STEPS] > benches/results/<date>-<machine>/python-speed.csv

Per env: (1) locobench through gymnasium.make (wrappers, NumPy conversions), (2) the same env's
raw binding call per step (one Python-to-Rust crossing), (3) the same steps looped in Rust (no
crossing), (4) Gymnasium's own v5 env (MuJoCo 4.0 from PyPI) through gymnasium.make, and (5) the
vector env (8 copies, the class gymnasium.make_vec builds) on one thread and on two, and (6) the
same vector env's steps looped in Rust on one thread and on two: the gain a second thread can
give on this machine, which (5) approaches as the Python side of a step shrinks; (7) the vector
env's former step, which batched one info dict per copy through Gymnasium's `_add_info`; (8) two
processes at once, each looping a vector env of half the copies in Rust on one thread (so each
core steps as many copies as each of two threads does): the machine's own ceiling for a second
core, with nothing shared and nothing to wait for. (1) to (4) take turns, thirty rounds of a tenth
of STEPS each, and (5) to (8) ninety, in reverse order every other round: each rate is the median
over the rounds, and each gain from a second thread or process is the median of the rounds' own
ratios (the two runs of a ratio follow each other within a fraction of a second, so a shared
machine's slow stretches cancel out of them), with a 95% percentile-bootstrap interval over the
rounds (2000 resamples, seeded). The goal for (5) is the machine's own ceiling: its gain at least
(8)'s, which the last column gives as the median of the rounds' (5) gain over (8) gain. The
binding's overhead per step is the median of the rounds' (2) - (3). Zero actions; episodes reset
when they end.

    python python/bench_speed.py [STEPS [ENV ...]]    (ENV: locobench names; default all four)
"""
import multiprocessing
import os
import platform
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np

import locobench

ENVS = [("half-cheetah", "HalfCheetah-v5"), ("hopper", "Hopper-v5"), ("ant", "Ant-v5"), ("minitaur", None)]


def gym_loop(env):
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.reset(seed=0)

    def run(n):
        for _ in range(n):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()

    return run


def raw_loop(env):
    core = env.unwrapped._core
    action = [0.0] * env.action_space.shape[0]
    core.reset(0)

    def run(n):
        for _ in range(n):
            _, _, term, trunc, _ = core.step(action)
            if term or trunc:
                core.reset(None)

    return run


def rust_loop(env):
    core = env.unwrapped._core
    action = [0.0] * env.action_space.shape[0]
    core.reset(0)
    return lambda n: core.step_repeat(action, n)


VEC_COPIES = 8
# What a second thread (or process) gives, each with its interval's bounds beside it.
GAINS = ["vec8_2_threads_gain", "vec8_rust_2_threads_gain", "vec8_dicts_2_threads_gain", "vec8_rust_2_processes_gain",
         # The goal: the vector env's gain from a second thread over what two independent
         # processes gain on the same machine in the same rounds (1.00 or more meets it).
         "vec8_over_processes"]


def vec_loop(name, threads, dicts=False):
    """The vector env's step; with `dicts`, the step that batches one info dict per copy through
    Gymnasium's `_add_info` (what the vector env did before it built its infos from columns)."""
    envs = locobench.LocobenchVectorEnv(name, VEC_COPIES, threads=threads)
    actions = np.zeros(envs.action_space.shape, dtype=np.float32)
    envs.reset(seed=0)
    step = envs._step_with_dicts if dicts else envs.step

    def run(n):
        for _ in range(n // VEC_COPIES):
            step(actions)

    return run


def interleaved(loops, n, rounds):
    """Steps per second of each loop in each of `rounds` rounds of `n` steps (an array per loop).
    The loops take turns within a round, in reverse order every other round, so that a slow stretch
    of a shared machine, and a loop's place in the round, fall on all of them alike."""
    for loop in loops:
        loop(n)
    rates = [[] for _ in loops]
    for r in range(rounds):
        for i in range(len(loops)) if r % 2 == 0 else reversed(range(len(loops))):
            start = time.perf_counter()
            loops[i](n)
            rates[i].append(n / (time.perf_counter() - start))
    return [np.array(r) for r in rates]


def median_interval(ratios, resamples=2000, seed=0):
    """The median of `ratios` and its 95% percentile-bootstrap interval: rounds drawn with
    replacement, `resamples` times, from a generator seeded with `seed`."""
    ratios = np.asarray(ratios, dtype=float)
    rng = np.random.default_rng(seed)
    medians = np.median(rng.choice(ratios, size=(resamples, len(ratios)), replace=True), axis=1)
    low, high = np.percentile(medians, [2.5, 97.5])
    return np.median(ratios), low, high


def vec_rust_loop(name, threads, copies=VEC_COPIES):
    envs = locobench.LocobenchVectorEnv(name, copies, threads=threads)
    actions = [[0.0] * envs.single_action_space.shape[0]] * copies
    envs.reset(seed=0)
    return lambda n: envs._core.step_repeat(actions, n // copies)


def _process_worker(name, conn):
    """Loops its own one-thread vector env of half the copies in Rust for the number of steps it
    receives, until None."""
    run = vec_rust_loop(name, 1, VEC_COPIES // 2)
    while (n := conn.recv()) is not None:
        run(n)
        conn.send(None)


class TwoProcesses:
    """Two processes (spawned: no threads inherited), each with a vector env of half the copies on
    one thread (so each core steps as many copies as each of two threads does); a call with `n`
    has each loop n / 2 steps at the same time and returns when both are done."""

    def __init__(self, name):
        ctx = multiprocessing.get_context("spawn")
        self.conns, self.procs = [], []
        for _ in range(2):
            ours, theirs = ctx.Pipe()
            proc = ctx.Process(target=_process_worker, args=(name, theirs), daemon=True)
            proc.start()
            self.conns.append(ours)
            self.procs.append(proc)

    def __call__(self, n):
        for conn in self.conns:
            conn.send(n // 2)
        for conn in self.conns:
            conn.recv()

    def close(self):
        for conn, proc in zip(self.conns, self.procs):
            conn.send(None)
            proc.join()


def cpu():
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor()


def main():
    steps = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    names = sys.argv[2:] or [name for name, _ in ENVS]
    unknown = [n for n in names if n not in dict(ENVS)]
    if unknown:
        sys.exit(f"python/bench_speed.py: unknown env {unknown[0]!r} (one of {', '.join(n for n, _ in ENVS)})")
    if locobench._core.BUILD_PROFILE != "release":
        sys.exit(f"python/bench_speed.py: locobench's extension ({locobench._core.__file__}) is a "
                 f"{locobench._core.BUILD_PROFILE} build, whose Rust code is unoptimised (python/test.sh installs one); "
                 "install a release build first: bash python/install.sh VENV")
    commit = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], capture_output=True, text=True).stdout.strip()
    if subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "src", "python", "Cargo.toml"]).returncode != 0:
        commit += "+dirty"
    flags = open("/proc/cpuinfo").read()
    simd = "avx512" if "avx512f" in flags else "avx2" if "avx2" in flags else "sse"
    note = os.environ.get("LOCOBENCH_BENCH_NOTE", "")
    print(f"# machine: {cpu()} ({simd}), {os.cpu_count()} cores; commit {commit}; release build; "
          f"python {platform.python_version()}, "
          f"gymnasium {gym.__version__}; command: python python/bench_speed.py {' '.join(sys.argv[1:]) or steps}"
          + (f"; {note}" if note else ""))
    print("env,locobench_gym_steps_per_s,locobench_raw_steps_per_s,locobench_rust_steps_per_s,binding_overhead_us,"
          "gymnasium_steps_per_s,vec8_1_thread_steps_per_s,vec8_2_threads_steps_per_s,"
          "vec8_rust_1_thread_steps_per_s,vec8_rust_2_threads_steps_per_s,"
          "vec8_dicts_1_thread_steps_per_s,vec8_dicts_2_threads_steps_per_s,vec8_rust_2_processes_steps_per_s,"
          + ",".join(f"{g},{g}_low,{g}_high" for g in GAINS))
    for name, gym_id in ENVS:
        if name not in names:
            continue
        ours = [gym.make(locobench.ENV_IDS[name]) for _ in range(3)]
        single = [gym_loop(ours[0]), raw_loop(ours[1]), rust_loop(ours[2])]
        single += [gym_loop(gym.make(gym_id))] if gym_id else []
        g, raw, rust, *theirs = interleaved(single, steps // 10, rounds=30)
        overhead = np.median(1 / raw - 1 / rust) * 1e6
        g, raw, rust = np.median(g), np.median(raw), np.median(rust)
        theirs = np.median(theirs[0]) if theirs else float("nan")
        loops = [vec_loop(name, t) for t in (1, 2)] + [vec_rust_loop(name, t) for t in (1, 2)]
        loops += [vec_loop(name, t, dicts=True) for t in (1, 2)]
        processes = TwoProcesses(name)
        runs = interleaved(loops + [processes], steps // 10, rounds=90)
        processes.close()
        vec1, vec2, rust1, rust2, dicts1, dicts2, procs2 = runs
        rates = ",".join(f"{np.median(r):.0f}" for r in runs)
        ratios = [vec2 / vec1, rust2 / rust1, dicts2 / dicts1, procs2 / rust1]
        ratios.append(ratios[0] / ratios[3])
        gains = ",".join(f"{v:.3f}" for r in ratios for v in median_interval(r))
        print(f"{name},{g:.0f},{raw:.0f},{rust:.0f},{overhead:.2f},{theirs:.0f},{rates},{gains}", flush=True)


if __name__ == "__main__":
    main()
