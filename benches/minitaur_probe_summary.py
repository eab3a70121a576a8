#!/usr/bin/env python3
"""Summarises the probes of benches/minitaur_probes.sh into one CSV: per probe, what it changed
from the `base` run's config, the held-out return and falls (from `locobench eval`'s output in
held_out.txt), the temperature at the end of training, how many training episodes ended by the
time limit rather than a fall, and the wall time.

    python3 benches/minitaur_probe_summary.py PROBES_DIR OUT.csv
"""
import csv
import re
import sys
import tomllib
from pathlib import Path


def config(run):
    with open(run / "config.toml", "rb") as f:
        return tomllib.load(f)


def train_table(run):
    return config(run)["train"]


def env_options(run):
    return config(run)["env"].get("options", {})


def change(run, base):
    """The hyperparameters, then the env options, that differ from the base run's."""
    parts = []
    for ours, theirs in ((train_table(run), train_table(base)), (env_options(run), env_options(base))):
        keys = sorted(k for k in ours if k not in ("total_steps",) and ours[k] != theirs.get(k))
        parts += [f"{k}={ours[k]}".replace(" ", "") for k in keys]
    return ",".join(parts) or "none (the preset)"


def held_out(run):
    text = (run / "held_out.txt").read_text()
    m = re.search(r"return\s+mean\s+(\S+)\s+\[(\S+),\s*(\S+)\]", text)
    f = re.search(r"falls\s+(\d+)/(\d+)", text)
    if not (m and f):
        raise SystemExit(f"{run}/held_out.txt: no return or falls line")
    return float(m[1]), float(m[2]), float(m[3]), int(f[1]), int(f[2])


def training(run):
    rows = list(csv.DictReader(open(run / "metrics.csv")))
    episodes = [r for r in rows if r["kind"] == "episode"]
    limit = int(env_options(run).get("max_episode_steps", 1000))
    truncated = sum(1 for r in episodes if int(r["episode_length"]) >= limit)
    alphas = [float(r["alpha"]) for r in rows if r.get("alpha")]
    return len(episodes), truncated, (alphas[-1] if alphas else float("nan")), int(rows[-1]["step"])


def main():
    probes, out = Path(sys.argv[1]), Path(sys.argv[2])
    base = probes / "base"
    rows = []
    for run in sorted(p for p in probes.iterdir() if (p / "held_out.txt").is_file()):
        ret, lo, hi, falls, n = held_out(run)
        eps, trunc, alpha, steps = training(run)
        wall = (run / "wall_s.txt").read_text().strip() if (run / "wall_s.txt").is_file() else ""
        rows.append({
            "probe": run.name, "seed": config(run)["seed"], "change": change(run, base), "steps": steps, "return": ret, "return_low": lo,
            "return_high": hi, "falls": falls, "episodes": n, "final_alpha": alpha, "truncated": trunc,
            "training_episodes": eps, "wall_s": wall,
        })
    rows.sort(key=lambda r: (r["probe"] != "base", r["probe"]))
    tmp = out.with_suffix(".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    tmp.replace(out)
    print(f"wrote {out} ({len(rows)} probes)")


if __name__ == "__main__":
    main()
