#!/usr/bin/env bash
set -e
ck=$1; out=$2  # evalB also takes DATA and the stage-0 checkpoint: evalB.sh CKPT OUT DATA S0B_CKPT
cd "$(dirname "$0")/../.."; . .venv/bin/activate; export MUJOCO_GL=egl; mkdir -p $out
mt="python -m scenarios.moving_target --source policy --checkpoint $ck --plane-z-m 0 --quiet"
for t in static linear; do $mt --target $t --mode hybrid --episodes 20 --seed 7000 --json $out/${t}_hybrid.json > $out/${t}_hybrid.txt; done
for t in reversal random_walk; do $mt --target $t --mode open_loop --episodes 20 --seed 6000 --json $out/${t}_open.json > $out/${t}_open.txt; done
$mt --target static --mode open_loop inpaint --episodes 20 --seed 8000 --json $out/inpaint_static.json > $out/inpaint_static.txt
$mt --target linear --mode open_loop inpaint --episodes 20 --seed 8000 --json $out/inpaint_linear.json > $out/inpaint_linear.txt
python -m scenarios.moving_target --source policy --target static --mode open_loop inpaint --episodes 20 --seed 8000 --quiet --json $out/old_inpaint_static.json > $out/old_inpaint_static.txt
# the same planar seeds with the new checkpoint: the old one's own scenes (balls at 0.1 m), both on its seeds
$mt --plane-z-m 0.1 --target static --mode open_loop inpaint --episodes 20 --seed 8000 --json $out/new_inpaint_planar.json > $out/new_inpaint_planar.txt
python docs/policy3d/forget.py $ck $3 $4 $out/forget.json > $out/forget.txt 2>&1
echo EVAL B DONE
