#!/usr/bin/env bash
# The main job, a short real demo (a few minutes on 2 cores once built):
#   1. SAC learns to balance InvertedPendulum, recorded into a rerun file as it learns;
#   2. a sweep: TD3 and DDPG learn it too, two seeds each, two processes side by side;
#   3. three Minitaur walking policies (trained with SAC for 300k steps, TD3 for 1M and PPO for
#      1M, shipped in models/policies/, retrain them with the commands in their READMEs) are
#      evaluated and recorded, beside the Raibert/QP baseline controller at 0.35 m/s and at
#      1.5 m/s, its fastest; the PPO policy is filmed beside the controller at its speed;
#   4. the two robust PPO policies (trained under shoves, rough ground, latency, sensor noise and
#      slopes, the second also with a random centre of mass) and the PPO policy meet the
#      controller in a short robustness suite (3 axes, 3 episodes per level; `cargo bench --bench
#      robustness` is the full one);
#   5. a report evaluates every policy on the same held-out episodes, beside the controller
#      across its speeds and under pushes, with the suite's section, and films each algorithm's
#      best policy.
# Everything goes under demo/; the paths are printed at the end.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release --quiet
bin=target/release/locobench
out=demo
policy=models/policies/minitaur-sac
td3_policy=models/policies/minitaur-td3
ppo_policy=models/policies/minitaur-ppo
robust_policy=models/policies/minitaur-ppo-robust
robust_com_policy=models/policies/minitaur-ppo-robust-com
rm -rf "$out"
mkdir -p "$out"
"$bin" envs
"$bin" train --env inverted-pendulum --algo sac --seed 0 --out "$out/run-inverted-pendulum-sac" \
  --record "$out/inverted-pendulum-training.rrd" --quiet
"$bin" eval --policy "$out/run-inverted-pendulum-sac" --episodes 10
"$bin" sweep --env inverted-pendulum --algo td3,ddpg --seeds 2 --jobs 2 --out "$out/pendulum-sweep"
"$bin" sweep status "$out/pendulum-sweep"
for p in "$policy" "$td3_policy" "$ppo_policy" "$robust_policy" "$robust_com_policy"; do "$bin" eval --policy "$p" --episodes 10; done
"$bin" baseline --env minitaur --speed 0.35,1.5 --episodes 3 --seed 0
"$bin" record --env minitaur --policy raibert --speed 0.35 --out "$out/minitaur-raibert.rrd"
"$bin" record --policy "$policy" --out "$out/minitaur-sac.rrd"
"$bin" record --policy "$td3_policy" --out "$out/minitaur-td3.rrd"
"$bin" record --policy "$ppo_policy" --out "$out/minitaur-ppo.rrd"
"$bin" record --policy "$ppo_policy" --side-by-side controller --caption --seed 100 \
  --video "$out/minitaur-ppo-vs-controller.mp4"
"$bin" robustness --env minitaur --policy "ppo=$ppo_policy" --policy "ppo-robust=$robust_policy" \
  --policy "ppo-robust-com=$robust_com_policy" \
  --controller 1.5 --axes push_lateral,terrain,latency --episodes 3 --seed 100 --out "$out/robustness"
"$bin" report --runs "$out/run-inverted-pendulum-sac" "$out/pendulum-sweep" "$policy" "$td3_policy" "$ppo_policy" \
  "$robust_policy" "$robust_com_policy" --out "$out/report" --episodes 3 --push-episodes 2 --videos --robustness "$out/robustness"
echo
echo "Report (open in a browser):   $(pwd)/$out/report/index.html  (Markdown: $out/report/README.md)"
echo "Video (PPO beside the controller): $(pwd)/$out/minitaur-ppo-vs-controller.mp4"
echo "Robustness suite (CSV):       $(pwd)/$out/robustness/robustness.csv"
echo "rerun recordings:             $(pwd)/$out/*.rrd  (viewer: pip install rerun-sdk==0.36.3; rerun FILE)"
echo "Training runs:                $(pwd)/$out/run-inverted-pendulum-sac, $(pwd)/$out/pendulum-sweep/runs/"
