#!/usr/bin/env bash
# Issue 13 figures: camera perception, latency compensation, curving targets (expert source, hybrid).
cd "$(dirname "$0")/../.."
. .venv/bin/activate
export MUJOCO_GL=egl
# the single-frame expert (--expert-lead none), as the issue measured them
mt="python -m scenarios.moving_target --source expert --expert-lead none --mode hybrid --episodes 20 --quiet"
out=docs/perception
for tgt in linear static jump; do
  $mt --target $tgt --perception camera --json $out/camera_$tgt.json > $out/camera_$tgt.txt
done
$mt --target linear --perception-latency-ms 0 --json $out/oracle_lat0.json > $out/oracle_lat0.txt
$mt --target linear --perception-latency-ms 100 --json $out/oracle_lat100.json > $out/oracle_lat100.txt
for f in cv imm; do
  $mt --target circle --speed 0.4 --filter $f --json $out/circle_$f.json > $out/circle_$f.txt
done
for s in 0 100; do  # the coordinated-turn IMM (circle_tracking.md)
  $mt --target circle --speed 0.4 --filter imm-ct --seed $s --json $out/circle_imm-ct_s$s.json > $out/circle_imm-ct_s$s.txt
done
$mt --target linear --filter imm --json $out/linear_imm.json > $out/linear_imm.txt
$mt --target jump --filter imm --json $out/jump_imm.json > $out/jump_imm.txt
for lat in 0 100; do $mt --target linear --filter imm --perception-latency-ms $lat --json $out/oracle_imm_lat$lat.json > $out/oracle_imm_lat$lat.txt; done
for lat in 0 100; do $mt --target linear --filter imm-ct --perception-latency-ms $lat --json $out/oracle_immct_lat$lat.json > $out/oracle_immct_lat$lat.txt; done
$mt --target jump --filter imm-ct --json $out/jump_imm-ct.json > $out/jump_imm-ct.txt
echo PERCEPTION DONE
