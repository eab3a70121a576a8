#!/usr/bin/env bash
# The browser test: opens a report (default: the committed one, benches/results/report) in
# Debian's headless Chromium and checks that its videos play and its first screen fits
# (tests/browser/check_report.py). Chromium runs on localhost only, with a debugging port for
# the checker, and is stopped by its process id when the test ends, whether it passed or not.
# Installs chromium (as root) and websocket-client into target/py-venv (python/test.sh makes it).
#
#   bash tests/browser/report.sh [REPORT_DIR]
set -euo pipefail
cd "$(dirname "$0")/../.."
report=${1:-benches/results/report}
if ! command -v chromium >/dev/null; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "browser test: skipped (needs Debian's chromium; run as root to install it)"
    exit 0
  fi
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null
fi
py=target/py-venv/bin/python
[ -x "$py" ] || { echo "browser test: $py is missing (python/test.sh makes it)"; exit 1; }
"$py" -m pip install -q "websocket-client>=1.6,<2"
work=$(mktemp -d)
port=$((9300 + RANDOM % 500))
chromium --headless=new --no-sandbox --disable-gpu --no-first-run --mute-audio \
  --autoplay-policy=no-user-gesture-required --allow-file-access-from-files \
  --remote-debugging-address=127.0.0.1 --remote-debugging-port="$port" \
  --user-data-dir="$work/profile" about:blank >"$work/chromium.log" 2>&1 &
pid=$!
cleanup() {
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
mkdir -p target/browser-test
"$py" tests/browser/check_report.py "$port" "$report" target/browser-test/first-screen.png
