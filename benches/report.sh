#!/usr/bin/env bash
# Regenerates the committed report, benches/results/report/, from the committed runs: every run
# with saved policies is evaluated under the report's protocol (50 held-out episodes per seed,
# 20 per push level); runs kept as config.toml + metrics.csv only give learning curves and are
# listed as having no policy. Each algorithm's best row is filmed (report --videos) unless
# LOCOBENCH_REPORT_VIDEOS=0. LOCOBENCH=BINARY runs that binary instead of building one.
#
# Evaluations and clips are kept in an evaluation cache (LOCOBENCH_REPORT_CACHE, default
# benches/results/report-cache, committed beside the report): a regeneration with nothing new
# reads every number from it and keeps every clip already in OUT/videos, so only new runs are
# evaluated; entries this report does not use are pruned. LOCOBENCH_REPORT_CACHE=off computes
# everything (report --no-cache). benches/report_timing.sh measures it cold and warm.
#
#   bash benches/report.sh [OUT] [REPORT OPTIONS...]      (default benches/results/report)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-benches/results/report}
bin=${LOCOBENCH:-}
if [ -z "$bin" ]; then
  cargo build --locked --release --quiet
  bin=./target/release/locobench
fi
videos=(--videos)
[ "${LOCOBENCH_REPORT_VIDEOS:-1}" = 0 ] && videos=()
r=benches/results
runs=(
  # Minitaur: TD3 (the preset: normalised observations, rewards x 100), SAC and DDPG with the
  # policies they saved at 100k and 300k; the preset's seed 1 at 1M (its actor was shipped as
  # minitaur-td3 before the layer-normalised TD3 below); earlier runs kept without policies.
  $r/minitaur/*-with-policies
  $r/minitaur/td3-norm-rs100-seed1-1m
  $r/minitaur/td3-norm-rs100-seed{0,2,3,4} $r/minitaur/sac-seed0-1m $r/minitaur/sac-seed1
  # Ant
  $r/ant/*-with-policies
  $r/ant/{td3,ddpg}-seed{0,1}-300k $r/ant/sac-seed{0,1,2,3,4}-300k
  # HalfCheetah and Humanoid: curves only
  $r/half-cheetah/{td3,sac,ddpg}-seed{0,1}-300k
  $r/humanoid/td3-seed{0,1}-300k $r/humanoid/sac-seed1-300k $r/humanoid/td3-seed2-300k $r/humanoid/td3-cleanrl-seed{0,1,2}-300k
  # PPO with CleanRL's settings, 1M steps, with their policies; PPO and the branching DQN on Minitaur
  $r/{half-cheetah,walker2d}/ppo-seed{0,1,2}-1m $r/hopper/ppo-seed{0,1,2,3,4,5,6,7,8,9}-1m
  $r/minitaur/ppo-8envs-seed{0,1,2}-2m $r/minitaur/dqn-seed0-300k $r/inverted-pendulum/dqn-seed0
  # The branching DQN on Walker2d with S003's notch actions (walker2d-notch), 1M steps
  $r/walker2d/dqn-notch-seed{0,1,2}
  # PPO with rl-baselines3-zoo's tuned HalfCheetah settings (docs/training.md), 1M steps
  $r/half-cheetah/ppo-zoo-seed{0,1,2}-1m
  # PPO trained for robustness (random shoves, rough ground, latency, sensor noise, slopes),
  # 2M steps, policies at 1M and 2M; evaluated in the nominal env like every row
  $r/minitaur/ppo-robust-seed{0,1,2}-2m
  # The same with a random centre of mass (random_com_shift_max=0.15), 2M steps; with a wider one
  # (0.25) from scratch, 2M steps; the 0.15 runs' 2M actors fine-tuned with the wider one; and
  # fine-tuned so, with the distance term capped at 1.6 m/s (max_rewarded_speed), 500k and 1M
  $r/minitaur/ppo-robust-com-seed{0,1,2}-2m
  $r/minitaur/ppo-robust-com25-seed{0,1,2}-2m
  $r/minitaur/ppo-robust-com25-ft-seed{0,1,2}-500k
  $r/minitaur/ppo-robust-com25-cap1.6-ft-seed{0,1,2}-{500k,1m}
  # SAC on Minitaur with Freeman's reward (no energy cost; drift weights 0, 0.5 and 1), 500k
  $r/minitaur/sac-energy0-*500k
  # SAC on Minitaur with the 100k probes' changes combined (normalised observations, rewards x100,
  # a 1k warm-up, 50 Hz control), seeds 0-2 with policies at 100k, 300k and 500k (seed 1 also
  # 1M); TD3 with the same changes, seed 0, 100k and 300k
  $r/minitaur/sac-combined-seed{0,1,2} $r/minitaur/td3-combined-seed0
  # Freeman's env (PyBullet's Minitaur at 100 Hz, no energy cost) with the agent-side changes
  # (normalised observations, rewards x100, a 1k warm-up), seeds 0-2, 500k
  $r/minitaur/sac-freeman-norm-seed{0,1,2}
  # CrossQ with 256-wide critics, policies at 100k and 300k; on Minitaur with SAC's four combined
  # changes, seeds 0-2 with policies at 100k, 300k and 500k
  $r/{half-cheetah,ant,humanoid}/crossq-256-seed{0,1,2}
  $r/minitaur/crossq-combined-seed{0,1,2}
  # TD3 and SAC with those four changes and layer-normalised critics (critic_layer_norm): TD3
  # seeds 0-2 with policies at 100k, 300k and 500k (seed 0's 300k actor is the shipped
  # minitaur-td3); SAC and DDPG seed 0 to 300k; TD3 the same with Adam at 3e-4 (CleanRL's rate)
  # instead of 1e-3, seeds 0-2 to 300k
  $r/minitaur/td3-combined-ln-seed{0,1,2} $r/minitaur/{sac,ddpg}-combined-ln-seed0
  $r/minitaur/td3-combined-ln-lr3e4-seed{0,1,2}
  # The same TD3 keeping at each budget its best evaluated actor (budget_policy=best, TD7's policy
  # checkpoints) of 10-, 20- and 50-episode in-training evaluations, or the one with fewest falls
  # in 50 (budget_policy=fewest_falls), seeds 0-2 to 500k (the 50-episode best to 300k); SAC with
  # layer-normalised critics and CrossQ's optimiser settings, seeds 0-2 (seed 0 to 500k)
  $r/minitaur/td3-combined-ln-{best,best20,best50,ff50}-seed{0,1,2}
  $r/minitaur/sac-combined-ln-crossqopt-seed{0,1,2}
  # TD3's actor on CrossQ's critics (CrossQ's td3_mode) with the same four changes, keeping its
  # best actor of 20-episode evaluations, seeds 0-2 with policies at 100k, 300k and 500k
  $r/minitaur/crossq-td3-combined-best20-seed{0,1,2}
  # CrossQ's combined settings keeping the best actor of 20-episode evaluations on fresh starts
  $r/minitaur/crossq-combined-fresh20-seed{0,1,2}
  # The 20-episode TD3 with every foot's friction scaled by 1.2 in training (held-out unchanged)
  $r/minitaur/td3-combined-ln-best20-fric1.2-seed{0,1,2}
  # Humanoid toward 1M with policies at each budget it has reached: SAC's preset, seed 0 (it
  # replaces the earlier curves-only sac-seed0-300k, the same seed and settings on older code), and
  # CrossQ with 512-wide critics, seed 0
  $r/humanoid/sac-seed0-1m $r/humanoid/crossq-512-seed0
  # PPO on the velocity-command task (minitaur-command), with its policies: the report's
  # same-command section puts them beside the controller on the same commands
  $r/minitaur-command/ppo-seed{0,1,2}-6m
  # The same 6M actors fine-tuned 2M steps for closer tracking (narrower kernels, yaw rate weighted
  # 1.0) with a battery drawn down to 6 V
  $r/minitaur-command/ppo-6m-ft-track-seed{0,1,2}
)
existing=()
for d in "${runs[@]}"; do
  if [ -d "$d" ]; then existing+=("$d"); else echo "not committed (yet): $d" >&2; fi
done
# Peers evaluated outside locobench (locobench.evaluate(out=...)), one row per label with a seed per
# directory (benches/sb3_peer.py): Stable-Baselines3's PPO on Minitaur with rl-baselines3-zoo's
# settings and on HalfCheetah with locobench's own PPO settings; SB3's SAC and TD3 on Minitaur with
# rl-baselines3-zoo's settings (benches/sb3_offpolicy_peer.py), at the last budget each run reached.
external=()
offpolicy=()
for run in $r/minitaur/sb3-{sac,td3}-seed*; do
  last=$(ls -d "$run"/external-* 2>/dev/null | sort -V | tail -1)
  [ -n "$last" ] && offpolicy+=("$last")
done
for d in $r/minitaur/sb3-ppo-seed*-1m/external $r/half-cheetah/sb3-ppo*-seed*-1m/external "${offpolicy[@]}"; do
  [ -d "$d" ] && external+=(--external "$d")
done
# The newest committed robustness suite of each env (cargo bench --bench robustness) becomes that
# env's robustness section: Minitaur's in the dated directory, Ant's and minitaur-command's (at
# one command for every contender) in their folders.
robustness=()
for f in robustness.csv ant/robustness.csv minitaur-command/robustness.csv; do
  suite=$(ls -d $r/20??-??-??-*/$f 2>/dev/null | sort | tail -1)
  [ -n "$suite" ] && robustness+=(--robustness "$(dirname "$suite")")
done
cache=${LOCOBENCH_REPORT_CACHE:-benches/results/report-cache}
if [ "$cache" = off ]; then cache_args=(--no-cache); else cache_args=(--cache "$cache" --prune-cache); fi
# No chart of an earlier layout left behind: everything goes but the clips, which the report
# keeps where the cache vouches for their bytes and removes where it shows them no more.
if [ -d "$out" ]; then find "$out" -mindepth 1 -maxdepth 1 ! -name videos -exec rm -rf {} +; fi
"$bin" report --runs "${existing[@]}" "${external[@]}" --out "$out" "${videos[@]}" "${robustness[@]}" \
  "${cache_args[@]}" "${@:2}"
