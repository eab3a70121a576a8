#!/usr/bin/env bash
# Times the committed report's regeneration (benches/report.sh) with one binary, one report at a
# time on an otherwise idle machine: cold (an empty evaluation cache: every policy evaluated,
# every clip filmed, what a regeneration cost before the cache) and warm (the same again, nothing
# new: every number read from the cache), each without and with videos. Writes
# report-timing.csv into DIR (a benches/results/<date>-<machine>/ directory): wall time, the
# cache's reads and computations and the seconds it spent on keys, lookups and writes (summed
# over threads: what the cold report paid for the cache beyond evaluating), the size of
# index.html, of the videos and of the whole report, and the clips. The report with videos, and its cache, are the committed ones; the warm report
# must be the same bytes as the cold one, or the script fails.
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
row() {  # cache state, videos, seconds, report directory, report's output
  local clips=0 vbytes=0 counts
  if [ -d "$4/videos" ]; then clips=$(ls "$4"/videos/*.mp4 | wc -l); vbytes=$(size "$4/videos"); fi
  counts=$(grep -o '[0-9]* read, [0-9]* computed' "$5" | awk '{print $1","$3}')
  overhead=$(grep -o '[0-9.]* s on keys' "$5" | awk '{print $1}')
  echo "$1,$2,$3,$counts,$overhead,$(stat -c %s "$4/index.html"),$vbytes,$(size "$4"),$clips"
}
fingerprint() { (cd "$1" && find . -type f -print0 | sort -z | xargs -0 sha256sum); }
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')
{
  echo "# benches/report_timing.sh; cpu $cpu; $(nproc) cores; commit $(git rev-parse HEAD); one report at a time"
  echo "cache,videos,wall_s,read,computed,cache_overhead_s,index_html_bytes,videos_bytes,report_bytes,clips"
} > "$work/timing.csv"
timed() {  # cache state, videos (true/false), out, cache dir
  local start end
  start=$(date +%s.%N)
  if [ "$2" = true ]; then v=1; else v=0; fi
  LOCOBENCH="$work/locobench" LOCOBENCH_REPORT_VIDEOS=$v LOCOBENCH_REPORT_CACHE="$4" \
    bash benches/report.sh "$3" > "$work/out.txt"
  end=$(date +%s.%N)
  row "$1" "$2" "$(awk "BEGIN{printf \"%.1f\", $end - $start}")" "$3" "$work/out.txt" >> "$work/timing.csv"
}
committed=benches/results/report
cache=benches/results/report-cache
rm -rf "$committed" "$cache"
timed cold false "$work/plain" "$work/plain-cache"
timed cold true "$committed" "$cache"
fingerprint "$work/plain" > "$work/plain.cold"
fingerprint "$committed" > "$work/videos.cold"
timed warm false "$work/plain" "$work/plain-cache"
timed warm true "$committed" "$cache"
fingerprint "$work/plain" | cmp - "$work/plain.cold"
fingerprint "$committed" | cmp - "$work/videos.cold"
mv "$work/timing.csv" "$dir/report-timing.csv"
cat "$dir/report-timing.csv"
