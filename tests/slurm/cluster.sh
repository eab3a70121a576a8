#!/usr/bin/env bash
# `locobench sweep --slurm` against a real Slurm, not a mock: a one-node cluster on localhost
# (munged, slurmctld and slurmd started here with a private key, config and state under a
# temporary directory; stopped by their process ids at the end, also when a case fails).
#
#   1. bad input: no sbatch on the PATH, then an unknown partition: clear errors, nothing
#      recorded, and the same command then submits from the same directory;
#   2. a 2-algorithm x 2-seed InvertedPendulum sweep through sbatch gives metrics identical, bit
#      for bit, to the same sweep run locally (wall-clock columns aside);
#   3. a task warned with SIGUSR1 (what `--signal=B:USR1@N` sends before a time limit)
#      checkpoints at the end of its episode, requeues itself, resumes, and finishes with the
#      numbers of an uninterrupted run.
#
# Needs root (it installs Debian's slurm-wlm and munge when missing). Uses the locobench binary
# that `cargo test` builds (target/debug/locobench), or $LOCOBENCH_BIN.
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=$(realpath "${LOCOBENCH_BIN:-target/debug/locobench}")
[ -x "$bin" ] || { echo "slurm test: no locobench binary at $bin (run cargo test or build first)" >&2; exit 2; }

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  echo "slurm test: installing slurm-wlm and munge"
  apt-get update -q >/dev/null
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge >/dev/null
fi

work=$(mktemp -d /tmp/locobench-slurm.XXXXXX)
chmod 755 "$work"
daemon_pids=()
stepds_before=$(pgrep -x slurmstepd || true)
export SLURM_CONF="$work/slurm.conf"

stop_cluster() {
  set +e
  # Cancel what is still queued or running and let slurmd see it end, then stop the daemons.
  if [ ${#daemon_pids[@]} -eq 3 ]; then
    scancel --full $(squeue -h -o %A 2>/dev/null | sort -u) 2>/dev/null
    for _ in $(seq 30); do [ -z "$(squeue -h 2>/dev/null)" ] && break; sleep 1; done
  fi
  for pid in "${daemon_pids[@]}"; do kill "$pid" 2>/dev/null; done
  for pid in "${daemon_pids[@]}"; do wait "$pid" 2>/dev/null; done
  # A job step whose slurmd is gone waits for it forever: end the ones this test started.
  for pid in $(pgrep -x slurmstepd); do
    grep -qx "$pid" <<<"$stepds_before" || kill -9 "$pid" 2>/dev/null
  done
  pkill -f "$work/" 2>/dev/null
  rm -rf "$work"
}
trap stop_cluster EXIT

start_cluster() {
  mungekey -c -k "$work/munge.key"
  chmod 600 "$work/munge.key"
  munged -F -f --key-file="$work/munge.key" --socket="$work/munge.sock" --pid-file="$work/munged.pid" \
    --log-file="$work/munged.log" --seed-file="$work/munged.seed" >"$work/munged.out" 2>&1 &
  daemon_pids+=($!)
  local host mem port
  host=$(hostname -s)
  mem=$(awk '/MemTotal/ { print int($2 / 1024 * 0.8) }' /proc/meminfo)
  # Ports off Slurm's defaults, so that a real installation on the machine is not disturbed.
  port=$((20000 + RANDOM % 20000))
  mkdir -p "$work/state" "$work/spool"
  cat >"$SLURM_CONF" <<EOF
ClusterName=locobench-test
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$work/munge.sock
CredType=cred/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MpiDefault=none
NodeName=$host NodeAddr=127.0.0.1 CPUs=$(nproc) RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  sleep 1
  slurmctld -D -f "$SLURM_CONF" >"$work/slurmctld.out" 2>&1 &
  daemon_pids+=($!)
  slurmd -D -f "$SLURM_CONF" >"$work/slurmd.out" 2>&1 &
  daemon_pids+=($!)
  for _ in $(seq 60); do
    if sinfo -h -o %T 2>/dev/null | grep -qx idle; then
      echo "slurm test: one-node cluster up ($(sinfo -h -o '%P %D %T %c CPUs'))"
      return 0
    fi
    sleep 1
  done
  echo "slurm test: the node never became idle" >&2
  tail -n 20 "$work"/*.log "$work"/*.out >&2
  return 1
}

passed=0
failed=0
check() { # NAME COMMAND...
  local name=$1
  shift
  if "$@"; then
    echo "slurm test: $name ... ok"
    passed=$((passed + 1))
  else
    echo "slurm test: $name ... FAILED"
    failed=$((failed + 1))
  fi
}

# Waits until `sweep status` counts N finished jobs; fails on a failed job or after $2 s.
wait_finished() { # DIR N TIMEOUT
  local status
  for _ in $(seq "$3"); do
    status=$("$bin" sweep status "$1")
    if grep -q "$2 finished" <<<"$status"; then return 0; fi
    if grep -Eq '[1-9][0-9]* failed' <<<"$status"; then
      echo "$status" >&2
      return 1
    fi
    sleep 1
  done
  echo "timed out; last status:" >&2
  echo "$status" >&2
  tail -n 20 "$1"/logs/* >&2
  return 1
}

# metrics.csv without the wall-clock columns (steps_per_s, wall_time).
same_metrics() { # RUN_DIR_A RUN_DIR_B
  if ! cmp -s <(cut -d, -f1-9 "$1/metrics.csv") <(cut -d, -f1-9 "$2/metrics.csv"); then
    echo "metrics differ: $1 vs $2" >&2
    diff <(cut -d, -f1-9 "$1/metrics.csv") <(cut -d, -f1-9 "$2/metrics.csv") | head -n 10 >&2
    return 1
  fi
  [ "$(grep -c '^eval' "$1/metrics.csv")" -ge 2 ] || { echo "no evaluations in $1" >&2; return 1; }
}

sweep_args=(--env inverted-pendulum --algo td3,sac --seeds 2 --steps 3000
  --set 'hidden=[32,32],batch_size=64,warmup_steps=500,learning_starts=500,eval_every=1000,eval_episodes=3')

case_bad_input() {
  local dir=$work/sweep out
  if out=$(PATH=/nonexistent "$bin" sweep "${sweep_args[@]}" --out "$dir" --slurm 2>&1); then
    echo "submitted without sbatch on the PATH" >&2
    return 1
  fi
  grep -q "needs Slurm's \`sbatch\` on the PATH" <<<"$out" || { echo "$out" >&2; return 1; }
  if out=$("$bin" sweep "${sweep_args[@]}" --out "$dir" --slurm --partition no-such-partition 2>&1); then
    echo "an unknown partition was accepted" >&2
    return 1
  fi
  grep -q "sbatch rejected" <<<"$out" && grep -qi "partition" <<<"$out" || { echo "$out" >&2; return 1; }
  [ -x "$dir/slurm.sh" ] && [ ! -e "$dir/slurm.toml" ] || { echo "a failed submission was recorded" >&2; return 1; }
}

case_same_numbers_as_local() {
  local dir=$work/sweep out
  out=$("$bin" sweep "${sweep_args[@]}" --out "$dir" --slurm --max-parallel 2) || { echo "$out" >&2; return 1; }
  echo "$out"
  grep -q "submitted .* as Slurm job" <<<"$out" || return 1
  wait_finished "$dir" 4 900 || return 1
  # Submitting again finds nothing left to do.
  out=$("$bin" sweep "${sweep_args[@]}" --out "$dir" --slurm)
  grep -q "nothing to submit: 4 jobs finished" <<<"$out" || { echo "$out" >&2; return 1; }
  "$bin" sweep status "$dir"
  "$bin" sweep "${sweep_args[@]}" --out "$work/local" --jobs 2 >/dev/null || return 1
  local job
  for job in td3-seed0 td3-seed1 sac-seed0 sac-seed1; do
    same_metrics "$dir/runs/$job" "$work/local/runs/$job" || return 1
  done
}

case_warning_signal_requeues_and_resumes() {
  local args=(--env inverted-pendulum --algo td3 --seeds 1 --steps 30000
    --set 'hidden=[32,32],batch_size=64,warmup_steps=500,learning_starts=500,eval_every=2000,eval_episodes=3')
  local dir=$work/signal run=$work/signal/runs/td3-seed0 job
  "$bin" sweep "${args[@]}" --out "$dir" --slurm >/dev/null || return 1
  job=$(sed -n 's/^job_id = "\([0-9]*\)"$/\1/p' "$dir/slurm.toml")
  # Warn once the run has evaluated twice, i.e. well inside training.
  for _ in $(seq 600); do
    [ -f "$run/metrics.csv" ] && [ "$(grep -c '^eval' "$run/metrics.csv")" -ge 2 ] && break
    sleep 0.5
  done
  [ "$(grep -c '^eval' "$run/metrics.csv")" -ge 2 ] || { echo "the run never got going" >&2; return 1; }
  scancel --signal=USR1 --batch "${job}_0"
  for _ in $(seq 120); do grep -q "requeueing" "$dir/logs/td3-seed0.log" && break; sleep 0.5; done
  grep -q "requeueing" "$dir/logs/td3-seed0.log" || { tail "$dir/logs/td3-seed0.log" >&2; return 1; }
  # Slurm holds a requeued job for a while before it may start again; this test does not wait.
  for _ in $(seq 20); do scontrol update JobId="${job}_0" StartTime=now 2>/dev/null && break; sleep 0.5; done
  wait_finished "$dir" 1 900 || return 1
  grep -q "stopped at step" "$dir/logs/td3-seed0.log" && grep -q "holds this run already: resuming" "$dir/logs/td3-seed0.log" || {
    cat "$dir/logs/td3-seed0.log" >&2
    return 1
  }
  grep -E "^== |stopped at step|resuming|finished" "$dir/logs/td3-seed0.log" | sed 's/^/    /'
  "$bin" sweep "${args[@]}" --out "$work/signal-local" --jobs 1 >/dev/null || return 1
  same_metrics "$run" "$work/signal-local/runs/td3-seed0"
}

start_cluster
check "bad input: no sbatch, unknown partition" case_bad_input
check "sweep through sbatch = local sweep, bit for bit" case_same_numbers_as_local
check "SIGUSR1 before the limit: checkpoint, requeue, resume, same numbers" case_warning_signal_requeues_and_resumes
echo "slurm: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
