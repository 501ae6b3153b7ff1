#!/usr/bin/env bash
# Issue 25, CPU training run 2 of the box layout (the pilot, docs/policy3d/box/pilot1, was run 1):
# 2,400 more scenes, their token cache beside the pilot's, stage 2 continued from the pilot's weights.
# bash docs/policy3d/box/run2/run.sh WORK   (WORK: a scratch directory; PY=python by default)
set -e
work=$1; PY=${PY:-python}
cd "$(dirname "$0")/../../../.."; export MUJOCO_GL=egl; mkdir -p "$work"
here=docs/policy3d/box
# 1. data: new scenes (seed 4,500,000; the pilot's were 4,000,000), 14-24 min with 2 workers
$PY -m scenarios.collect --episodes 2400 --seed 4500000 --cameras box_front box_side --frame-gap-s 0.4 \
  --expert-lead velocity --motion all --duration-s 1.5 --plane-z-m 0 --holdout-box-m 0.5 0.65 0.0 0.3 \
  --workers 2 --out "$work/box_g04b"
# 2. their tokens, by mmact_3d.pt's frozen tokenizers (the pilot's cache has the same fingerprint)
$PY -m policy.token_cache --data "$work/box_g04b" --checkpoint policy/checkpoints/mmact_3d.pt \
  --cameras box_front box_side --out $here/run2/tokens_box_g04_s4500000.npz
# 3. the pilot's weights (run 1: python -m policy.train ... --out $work/s2, see ../pilot1/README.md)
[ -f "$work/s2/stage2.pt" ] || { echo "run the pilot first: ../pilot1/README.md" >&2; exit 2; }
# 4. stage 2 on both caches, continued from the pilot
$PY -m policy.train --tokens-cache $here/pilot1/tokens_box_g04_s4000000.npz $here/run2/tokens_box_g04_s4500000.npz \
  --stage 2 --init "$work/s2/stage2.pt" --out "$work/s3" --steps 5000 --time-budget-s 4800 --batch-size 16 \
  --aux-batch-size 2 --lr 2e-4 --dropout 0.1 --threads 2 --save-every 250 --ball-tokens 1 --aux-positions 2 \
  --mm2a-image-frames 1 --cameras box_front box_side
