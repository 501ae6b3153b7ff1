#!/usr/bin/env bash
# Issue 25's closed-loop figures of one checkpoint: bash docs/policy3d/box/eval.sh CKPT OUT [quick]
# (PY=python by default; run from anywhere). Seeds 5000-7049 are never used to choose a checkpoint: pilots and
# checkpoint choices use seeds 9100+ (quick: the static / linear open-loop rows on those seeds only).
set -e
ck=$1; out=$2; mode=${3:-full}; PY=${PY:-python}
cd "$(dirname "$0")/../../.."; export MUJOCO_GL=egl; mkdir -p "$out"
mt="$PY -m scenarios.moving_target --source policy --checkpoint $ck --plane-z-m 0 --quiet"
if [ "$mode" = quick ]; then
  $mt --target static --mode open_loop --episodes 60 --seed 9100 --json $out/q_static_open.json > $out/q_static_open.txt
  $mt --target linear --mode open_loop --episodes 30 --seed 9200 --json $out/q_linear_open.json > $out/q_linear_open.txt
  echo QUICK DONE; exit 0
fi
$mt --target static --mode open_loop --episodes 200 --seed 5000 --json $out/static_open.json > $out/static_open.txt
$mt --target linear --mode open_loop --episodes 50 --seed 6000 --json $out/linear_open.json > $out/linear_open.txt
for t in reversal random_walk; do
  $mt --target $t --mode open_loop --episodes 20 --seed 6000 --json $out/${t}_open.json > $out/${t}_open.txt
done
for t in static linear; do
  $mt --target $t --mode hybrid --episodes 50 --seed 7000 --json $out/${t}_hybrid.json > $out/${t}_hybrid.txt
done
$PY -m policy.bench --checkpoint $ck --threads 2 --json $out/bench_t2.json > $out/bench_t2.txt
$PY docs/policy3d/analyze.py $out > $out/summary.txt
echo EVAL DONE
