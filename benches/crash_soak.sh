#!/usr/bin/env bash
# Crash soak (not part of the test command; tests/crash.rs is the quick, targeted version).
#
# Kills training runs with SIGKILL at random moments, continues each one the way a requeued
# cluster job does (the same command with --resume-if-exists, which also covers a run killed
# before its first checkpoint or before it wrote anything), and checks that the run directory
# then equals an unbroken run's byte for byte, except the wall-time and rate columns of
# metrics.csv and the wall time of each checkpoint's state.toml. Then the same for a sweep
# (the sweep process and its jobs killed together, then the sweep run again) and for `report`
# (killed, then run again: the same report files).
#
# Usage: bash benches/crash_soak.sh [KILLS_PER_ALGORITHM=50] [RESULTS_DIR]
# Writes RESULTS_DIR/crash-soak.csv (one line per kill) and RESULTS_DIR/crash-soak.md (the
# totals, the machine and the commit). Moments come from bash's RANDOM seeded with 7.
set -euo pipefail
cd "$(dirname "$0")/.."
kills=${1:-50}
results=${2:-benches/results/$(date +%F)-$(hostname -s)}
work=target/crash-soak
bin=target/release/locobench
# What the binary is built from, read before the build.
built_from="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src Cargo.toml Cargo.lock || echo ' with uncommitted changes')"
cargo build --release --locked -q
rm -rf "$work"
mkdir -p "$work" "$results"
RANDOM=7
csv="$results/crash-soak.csv"
echo "target,kill,delay_ms,killed,identical" >"$csv"

settings() {
  case "$1" in
    ppo) echo "hidden=[32,32],num_envs=2,num_steps=64,num_minibatches=2,update_epochs=2,eval_every=500,eval_episodes=2,checkpoint_every=300" ;;
    dqn) echo "hidden=[32,32],batch_size=64,exploration_steps=1000,learning_starts=300,eval_every=500,eval_episodes=2,checkpoint_every=300" ;;
    crossq) echo "hidden=[32,32],critic_hidden=[64,64],batch_size=64,warmup_steps=300,learning_starts=300,eval_every=500,eval_episodes=2,checkpoint_every=300" ;;
    *) echo "hidden=[32,32],batch_size=64,warmup_steps=300,learning_starts=300,eval_every=500,eval_episodes=2,checkpoint_every=300" ;;
  esac
}

train_cmd() { # algo out
  echo "$bin train --env inverted-pendulum --algo $1 --seed 5 --steps 3000 --set $(settings "$1") --out $2 --quiet --threads 1 --resume-if-exists"
}

# A listing of a directory's files with their normalised contents' hashes, one line each.
manifest() { # dir
  (cd "$1" && find . -type f | LC_ALL=C sort | while read -r f; do
    case "$(basename "$f")" in
      metrics.csv) h=$(cut -d, -f1-9,12 "$f" | sha256sum) ;;
      state.toml) h=$(grep -v '^wall_time' "$f" | sha256sum) ;;
      checksums.toml) h="(sums of the files above)" ;;
      *) h=$(sha256sum <"$f") ;;
    esac
    echo "$f ${h%% *}"
  done)
}

ms_now() { date +%s%3N; }

# Starts CMD in its own process group, kills the group after DELAY ms; prints 1 if it was
# killed, 0 if it had finished by then.
kill_after() { # delay_ms cmd...
  local delay=$1
  shift
  setsid "$@" >/dev/null 2>&1 &
  local pid=$!
  sleep "$(printf '%d.%03d' $((delay / 1000)) $((delay % 1000)))"
  if kill -0 "$pid" 2>/dev/null; then
    kill -KILL -- "-$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
    echo 1
  else
    wait "$pid" 2>/dev/null || true
    echo 0
  fi
}

total_kills=0
total_same=0
summary=""
for algo in td3 sac ppo crossq dqn; do
  ref="$work/$algo-whole"
  t0=$(ms_now)
  $(train_cmd "$algo" "$ref") >/dev/null
  span=$(($(ms_now) - t0))
  manifest "$ref" >"$work/$algo-whole.manifest"
  n=0
  same=0
  i=0
  while [ "$n" -lt "$kills" ]; do
    i=$((i + 1))
    run="$work/$algo-$i"
    delay=$(((RANDOM * 32768 + RANDOM) % span))
    # shellcheck disable=SC2046
    k=$(kill_after "$delay" $(train_cmd "$algo" "$run"))
    if [ "$k" = 1 ]; then
      $(train_cmd "$algo" "$run") >/dev/null 2>"$run.resume.err" || true
      ident=0
      if [ -d "$run" ] && diff -q <(manifest "$run") "$work/$algo-whole.manifest" >/dev/null; then
        ident=1
        same=$((same + 1))
        rm -rf "$run" "$run.resume.err"
      fi
      n=$((n + 1))
      echo "$algo,$n,$delay,1,$ident" >>"$csv"
    else
      rm -rf "$run"
    fi
  done
  echo "crash soak: $algo: $same of $n kills resumed to the unbroken run (run span ${span} ms)"
  summary+="| $algo | $n | $same | $span |"$'\n'
  total_kills=$((total_kills + n))
  total_same=$((total_same + same))
done

# A command killed at random moments (with its children, as a job scheduler would) and run again,
# KILLS times, each time compared with an unbroken run's output.
soak_command() { # name label kills cmd_fn manifest_fn message
  local name=$1 label=$2 count=$3 cmd=$4 list=$5 message=$6
  $($cmd "$work/$name-whole") >/dev/null
  $list "$work/$name-whole" >"$work/$name-whole.manifest"
  local t0 span n=0 same=0 i=0 out delay k ident
  t0=$(ms_now)
  $($cmd "$work/$name-timing") >/dev/null
  span=$(($(ms_now) - t0))
  while [ "$n" -lt "$count" ]; do
    i=$((i + 1))
    out="$work/$name-$i"
    delay=$(((RANDOM * 32768 + RANDOM) % span))
    # shellcheck disable=SC2046
    k=$(kill_after "$delay" $($cmd "$out"))
    if [ "$k" = 1 ]; then
      $($cmd "$out") >/dev/null 2>&1 || true
      ident=0
      if diff -q <($list "$out") "$work/$name-whole.manifest" >/dev/null; then
        ident=1
        same=$((same + 1))
      fi
      n=$((n + 1))
      echo "$name,$n,$delay,1,$ident" >>"$csv"
    fi
    rm -rf "$out"
  done
  echo "crash soak: $name: $same of $n kills $message (span ${span} ms)"
  summary+="| $label | $n | $same | $span |"$'\n'
  total_kills=$((total_kills + n))
  total_same=$((total_same + same))
}

# A sweep killed with its jobs, then run again.
sweep_cmd() { # out
  echo "$bin sweep --env inverted-pendulum --algo td3,sac --grid set.tau=0.005,0.01 --seeds 1 --jobs 2 --steps 2000 --set $(settings td3) --out $1"
}
sweep_manifest() { manifest "$1/runs"; }
soak_command sweep "sweep (2 algorithms x 2 taus, 2 jobs at a time)" $((kills / 5)) sweep_cmd sweep_manifest \
  "resumed to the unbroken sweep"

# `report` killed, then run again over the same runs.
report_cmd() { # out
  echo "$bin report --runs $work/sweep-whole/runs --episodes 5 --out $1"
}
soak_command report report $((kills / 5)) report_cmd manifest "gave the unbroken report"

{
  echo "# Crash soak"
  echo
  echo "\`bash benches/crash_soak.sh $kills\`, the binary built from commit $built_from,"
  echo "on $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores."
  echo "Each kill is SIGKILL at a moment drawn uniformly over an unbroken run's wall time; the run is"
  echo "then continued with the same command and \`--resume-if-exists\` and compared, file by file, with"
  echo "the unbroken run (metrics.csv without its wall-time and rate columns, state.toml without its"
  echo "wall time). Per-kill lines: crash-soak.csv."
  echo
  echo "| what | kills | identical after resuming | unbroken run (ms) |"
  echo "|---|---|---|---|"
  printf '%s' "$summary"
  echo
  echo "Total: $total_same of $total_kills identical."
} >"$results/crash-soak.md"
cat "$results/crash-soak.md"
[ "$total_same" -eq "$total_kills" ]
