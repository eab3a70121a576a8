"""Compare tracking grids (`locobench track --out GRID.csv`) with the controller's, point by point.

    python3 benches/track_grid_compare.py CONTROLLER.csv GRID.csv [GRID.csv ...]

Prints one Markdown row per grid: at the points where the controller is meant to work
(0.25-1.5 m/s, every yaw rate in its grid), how many have a speed RMS error no larger than the
controller's, going straight and turning; how many have a yaw-rate RMS error and a cost of
transport no larger; the falls there; and the falls above 1.5 m/s, where it does not work.
Grids must hold the same points as the controller's (the same `--speeds` and `--yaw-rates`).
"""

import csv
import sys

CONTROLLER_TOP_SPEED = 1.5


def read(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"{path}: no grid points")
    return {(float(r["speed"]), float(r["yaw_rate"])): r for r in rows}


def compare(controller, grid, name):
    missing = sorted(set(controller) - set(grid))
    if missing:
        sys.exit(f"{name}: lacks the controller's grid points {missing}")
    inside = [p for p in controller if p[0] <= CONTROLLER_TOP_SPEED]
    straight = [p for p in inside if p[1] == 0.0]
    turning = [p for p in inside if p[1] != 0.0]

    def no_worse(points, column):
        return sum(float(grid[p][column]) <= float(controller[p][column]) for p in points)

    def falls(points):
        return sum(int(grid[p]["falls"]) for p in points), sum(int(grid[p]["episodes"]) for p in points)

    outside = [p for p in grid if p[0] > CONTROLLER_TOP_SPEED]
    f_in, n_in = falls(inside)
    f_out, n_out = falls(outside)
    return (
        f"| {name} | {no_worse(straight, 'speed_rms')}/{len(straight)} "
        f"| {no_worse(turning, 'speed_rms')}/{len(turning)} "
        f"| {no_worse(inside, 'yaw_rate_rms')}/{len(inside)} "
        f"| {no_worse(inside, 'cost_of_transport')}/{len(inside)} "
        f"| {f_in}/{n_in} | {f_out}/{n_out} |"
    )


def main(argv):
    if len(argv) < 3:
        sys.exit(__doc__)
    controller = read(argv[1])
    print(
        "| grid | straight: speed RMS <= controller's | turning: speed RMS <= controller's "
        "| yaw-rate RMS <= controller's | cost of transport <= controller's "
        f"| falls 0.25-{CONTROLLER_TOP_SPEED} m/s | falls above {CONTROLLER_TOP_SPEED} m/s |"
    )
    print("|---|---|---|---|---|---|---|")
    for path in argv[2:]:
        print(compare(controller, read(path), path))


if __name__ == "__main__":
    main(sys.argv)
