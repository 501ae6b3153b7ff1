#!/usr/bin/env bash
set -e
ck=$1; out=$2
cd "$(dirname "$0")/../.."; . .venv/bin/activate; export MUJOCO_GL=egl; mkdir -p $out
mt="python -m scenarios.moving_target --source policy --checkpoint $ck --plane-z-m 0 --quiet"
$mt --target static --mode open_loop --episodes 200 --seed 5000 --json $out/static_open.json > $out/static_open.txt
$mt --target linear --mode open_loop --episodes 50 --seed 6000 --json $out/linear_open.json > $out/linear_open.txt
echo EVAL A DONE
