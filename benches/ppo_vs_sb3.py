"""locobench's PPO beside Stable-Baselines3's PPO with the same settings on HalfCheetah: time to
train 1M steps and the held-out return, per seed, into benches/results/<date>-<machine>/ppo-vs-sb3.csv.

Both sides train with CleanRL's `ppo_continuous_action.py` settings (locobench's PPO defaults;
`benches/sb3_peer.py half-cheetah-cleanrl` sets SB3 to them), one core each, on the same machine:

- SB3: `benches/sb3_peer.py half-cheetah-cleanrl SEED 1000000 benches/results/half-cheetah/sb3-ppo-cleanrl-seedSEED-1m`;
  its wall and CPU time of training come from the run's run.toml, or, for runs from before
  sb3_peer.py recorded CPU time, from a log of samples of the process's CPU seconds beside its
  progress rows (`--cpu-log`, lines `unix_s seed cpu_s progress_row`, sampled from
  /proc/PID/stat), taken at its last progress row (the end of training, before the held-out
  evaluation);
- locobench: `/usr/bin/time -f "%e %U %S" locobench train --env half-cheetah --algo ppo --seed SEED
  --steps 1000000 --threads 1 --out DIR` (`--ours DIR`, holding seedN/ and timeN.txt), which
  includes its periodic evaluation (10 episodes every 10k steps) that the SB3 run does not do.

The held-out return is `locobench.evaluate` on the protocol's 50 episodes (seed 0) for both: SB3's
from its held_out.json, ours from the committed run's policy at 1M, whose metrics the rerun must
reproduce (checked here, timing columns aside).

    python benches/ppo_vs_sb3.py --ours target/hc-ppo-rerun --cpu-log target/sb3-hc/cpu.log \
        --out benches/results/<date>-<machine>/ppo-vs-sb3.csv --note "..."
"""
import argparse
import csv
import json
import pathlib
import platform
import subprocess

import locobench

ROOT = pathlib.Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benches" / "results"
SEEDS = (0, 1, 2)


def cpu_at_end(log, seed, steps):
    """CPU seconds of the SB3 run of `seed` at its last sampled progress row of `steps` steps."""
    best = None
    for line in open(log):
        parts = line.split()
        if len(parts) < 4 or int(parts[1]) != seed:
            continue
        row = parts[3].split(",")
        if int(row[0]) >= steps:
            return float(parts[2])
        best = parts
    raise SystemExit(f"{log}: no sample of seed {seed} at {steps} steps (last: {best})")


def metrics_without_timing(path):
    """metrics.csv rows without the steps_per_s and wall_time columns."""
    rows = list(csv.reader(open(path)))
    drop = [rows[0].index("steps_per_s"), rows[0].index("wall_time")]
    return [[v for i, v in enumerate(r) if i not in drop] for r in rows]


def crate_version():
    import tomllib
    return tomllib.loads((ROOT / "Cargo.toml").read_text())["package"]["version"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ours", required=True, type=pathlib.Path)
    ap.add_argument("--cpu-log", type=pathlib.Path, help="for runs whose run.toml has no cpu_time_s")
    ap.add_argument("--out", required=True, type=pathlib.Path, help="benches/results/<date>-<machine>/ppo-vs-sb3.csv")
    ap.add_argument("--note", default="")
    args = ap.parse_args()
    rows = []
    for seed in SEEDS:
        sb3 = RESULTS / f"half-cheetah/sb3-ppo-cleanrl-seed{seed}-1m"
        run = dict(line.split(" = ", 1) for line in (sb3 / "run.toml").read_text().splitlines() if " = " in line)
        held = json.loads((sb3 / "held_out.json").read_text())
        steps = int(run["steps"])
        rows.append(dict(implementation="stable-baselines3 " + run["stable_baselines3"].strip('"'),
                         seed=seed, steps=steps, wall_s=float(run["wall_time_s"]),
                         cpu_s=float(run["cpu_time_s"]) if "cpu_time_s" in run else cpu_at_end(args.cpu_log, seed, steps),
                         held_out=held["return_mean"]))
    for seed in SEEDS:
        rerun = args.ours / f"seed{seed}"
        committed = RESULTS / f"half-cheetah/ppo-seed{seed}-1m"
        if metrics_without_timing(rerun / "metrics.csv") != metrics_without_timing(committed / "metrics.csv"):
            raise SystemExit(f"{rerun}/metrics.csv differs from {committed}/metrics.csv beyond its timing columns")
        wall, user, system = (float(v) for v in (args.ours / f"time{seed}.txt").read_text().split()[-3:])
        policy = locobench.load_policy(str(committed), budget=1_000_000)
        held = locobench.evaluate(policy, "locobench/HalfCheetah-v5", episodes=50, seed=0)
        rows.append(dict(implementation="locobench " + crate_version(), seed=seed, steps=1_000_000,
                         wall_s=wall, cpu_s=user + system, held_out=held["return_mean"]))
    cpu = platform.processor() or "unknown"
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    commit = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], capture_output=True, text=True,
                            cwd=ROOT).stdout.strip()
    out = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    with open(tmp, "w") as f:
        f.write(f"# machine: {cpu}; commit {commit}; env locobench/HalfCheetah-v5, 1M steps per run, both with "
                f"CleanRL's ppo_continuous_action.py settings, one core each; held-out: 50 episodes, protocol "
                f"seed 0; command: python benches/ppo_vs_sb3.py (see its docstring for the runs)"
                + (f"; {args.note}" if args.note else "") + "\n")
        f.write("implementation,seed,steps,wall_s,cpu_s,held_out_return,held_out_low,held_out_high\n")
        for r in rows:
            m, lo, hi = r["held_out"]
            f.write(f"{r['implementation']},{r['seed']},{r['steps']},{r['wall_s']:.1f},{r['cpu_s']:.1f},"
                    f"{m:.2f},{lo:.2f},{hi:.2f}\n")
    tmp.replace(out)
    print(out.read_text())


if __name__ == "__main__":
    main()
