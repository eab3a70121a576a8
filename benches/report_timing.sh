#!/usr/bin/env bash
# Regenerates the committed report (benches/report.sh) twice with one binary, without and with
# videos, one after the other on an otherwise idle machine, and writes report-timing.csv into
# DIR (a benches/results/<date>-<machine>/ directory): wall time, the size of index.html, of the
# videos and of the whole report, and the clips. The report with videos is the committed one.
#
#   bash benches/report_timing.sh DIR
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:?usage: bash benches/report_timing.sh benches/results/<date>-<machine>}
mkdir -p "$dir"
cargo build --locked --release --quiet
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp target/release/locobench "$work/locobench"
size() { du -sb "$1" 2>/dev/null | cut -f1 || echo 0; }
row() {  # videos, seconds, report directory
  local clips=0 vbytes=0
  if [ -d "$3/videos" ]; then clips=$(ls "$3"/videos/*.mp4 | wc -l); vbytes=$(size "$3/videos"); fi
  echo "$1,$2,$(stat -c %s "$3/index.html"),$vbytes,$(size "$3"),$clips"
}
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')
{
  echo "# benches/report_timing.sh; cpu $cpu; $(nproc) cores; commit $(git rev-parse HEAD); one report at a time"
  echo "videos,wall_s,index_html_bytes,videos_bytes,report_bytes,clips"
} > "$work/timing.csv"
start=$(date +%s.%N)
LOCOBENCH="$work/locobench" LOCOBENCH_REPORT_VIDEOS=0 bash benches/report.sh "$work/plain" >/dev/null
mid=$(date +%s.%N)
row false "$(awk "BEGIN{printf \"%.1f\", $mid - $start}")" "$work/plain" >> "$work/timing.csv"
LOCOBENCH="$work/locobench" bash benches/report.sh benches/results/report >/dev/null
end=$(date +%s.%N)
row true "$(awk "BEGIN{printf \"%.1f\", $end - $mid}")" benches/results/report >> "$work/timing.csv"
mv "$work/timing.csv" "$dir/report-timing.csv"
cat "$dir/report-timing.csv"
