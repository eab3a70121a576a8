#!/usr/bin/env bash
# CrossQ on Humanoid: end-to-end training speed per critic width, so a 1M-step run can be sized
# before it starts. Per width: `train --env humanoid --algo crossq` for 9000 steps (learning
# starts at 5000), then steps per second over the episodes that end after step 5500, from the
# run's metrics (wall_time). Prints one line per width and writes OUT (default
# target/crossq-widths.csv).
#
#   bash benches/crossq_widths.sh [WIDTHS...]       (default 256 512 1024)
#   LOCOBENCH=BINARY THREADS=N OUT=FILE             (default: the release build, 1 thread)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${LOCOBENCH:-}
if [ -z "$bin" ]; then
  cargo build --locked --release --quiet
  bin=./target/release/locobench
fi
widths=("$@")
[ ${#widths[@]} -eq 0 ] && widths=(256 512 1024)
out=${OUT:-target/crossq-widths.csv}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$(dirname "$out")"
echo "critic_width,threads,steps,seconds,steps_per_s" > "$out.tmp"
for w in "${widths[@]}"; do
  "$bin" train --env humanoid --algo crossq --seed 0 --steps 9000 --threads "${THREADS:-1}" --quiet \
    --set "critic_hidden=[$w,$w],eval_every=1000000,checkpoint_every=1000000" --out "$work/w$w" >/dev/null
  python3 - "$work/w$w/metrics.csv" "$w" "${THREADS:-1}" >> "$out.tmp" <<'PY'
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if r["kind"] == "episode" and int(r["step"]) >= 5500]
steps = int(rows[-1]["step"]) - int(rows[0]["step"])
seconds = float(rows[-1]["wall_time"]) - float(rows[0]["wall_time"])
print(f"{sys.argv[2]},{sys.argv[3]},{steps},{seconds:.1f},{steps / seconds:.1f}")
PY
  tail -1 "$out.tmp" | awk -F, '{printf "critic width %s: %s steps/s (%s steps in %s s after learning starts)\n", $1, $5, $3, $4}'
done
mv "$out.tmp" "$out"
