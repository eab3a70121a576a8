#!/usr/bin/env python3
"""Pools benches/minitaur_friction_falls.sh's CSV per contender family and friction scale.

Prints a Markdown table: falls per seed, pooled, and a 95% Wilson interval for the pooled rate.
Usage: python3 benches/friction_falls_summary.py benches/results/minitaur/friction-falls/falls.csv
"""
import csv
import math
import sys


def wilson(k, n, z=1.959963984540054):
    """The same interval as locobench::evaluation::stats::wilson (src/evaluation/stats.rs), which
    `eval` prints per run; pooled counts over seeds are not something the CLI takes."""
    p = k / n
    d = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / d
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return max(0.0, centre - half), min(1.0, centre + half)


def family(row):
    if row["contender"] == "controller":
        return f"controller, {row['budget']} m/s commanded"
    # A run directory ends in -seedN: the family is the name without it.
    name = row["contender"].rstrip("/").split("/")[-1]
    return name.rsplit("-seed", 1)[0] + f" at {int(row['budget']) // 1000}k"


def main(path):
    pooled = {}
    for row in csv.DictReader(open(path, newline="")):
        entry = pooled.setdefault((family(row), row["friction_scale"]), [0, 0, []])
        entry[0] += int(row["falls"])
        entry[1] += int(row["episodes"])
        entry[2].append(row["falls"])
    print("| contender | friction scale | falls per seed | pooled | 95% Wilson |")
    print("|---|---|---|---|---|")
    for (name, scale), (k, n, per_seed) in pooled.items():
        lo, hi = wilson(k, n)
        print(f"| {name} | {scale} | {', '.join(per_seed)} | {k}/{n} | {lo:.2f}-{hi:.2f} |")


if __name__ == "__main__":
    main(sys.argv[1])
