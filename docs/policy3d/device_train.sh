#!/usr/bin/env bash
# Stage 2 of the 3-D policy on the accelerator, in ONE device call, from a carried token cache.
#
# The device machine has torch but neither the frames (431 MB) nor MuJoCo; stage 2 needs only tokens. Here, first:
#   python -m policy.token_cache --data /work/runs3d/demos3d --checkpoint policy/checkpoints/mmact_3d.pt \
#       --out .carry/tokens3d.npz            # 12,000 samples -> 9 MB; .carry/ is in .git/info/exclude
# then the device call (the 15 device-minutes of a session: start ~2 min + this command ~9 min):
#   run(command="bash docs/policy3d/device_train.sh", carry=[".carry"], timeout_s=600)
# Everything under $OUT comes back: stage2.pt (12 MB), MODEL_CARD.md, train.log, gpu.txt.
# Then here: copy stage2.pt to policy/checkpoints/mmact_3d.pt only after docs/policy3d/evalA.sh / evalB.sh
# measured it (the card's rows), never on the training figures alone.
#
# The same script runs on the CPU for a check of the path (DEVICE=cpu BUDGET_S=20 EVAL_SAMPLES=16).
set -euo pipefail
export PYTHONUNBUFFERED=1
OUT=${OUT:-/tmp/device_train_out}
DEVICE=${DEVICE:-cuda}
CACHE=${CACHE:-.carry/tokens3d.npz}
INIT=${INIT:-policy/checkpoints/mmact_3d.pt}
BUDGET_S=${BUDGET_S:-420}          # training loop wall clock; loading (~20 s) and the evaluation come on top
BATCH=${BATCH:-128}
LR=${LR:-4e-4}
EVAL_SAMPLES=${EVAL_SAMPLES:-256}
mkdir -p "$OUT"
PY=$(command -v python3 || command -v python)
{ date -u; uname -m; "$PY" -c 'import torch, numpy, tokenizers; print("torch", torch.__version__, "cuda", torch.cuda.is_available(), "numpy", numpy.__version__, "tokenizers", tokenizers.__version__)'; } > "$OUT/gpu.txt" 2>&1
if command -v nvidia-smi > /dev/null; then nvidia-smi --query-gpu=name,memory.total --format=csv >> "$OUT/gpu.txt" 2>&1 || true; fi
cat "$OUT/gpu.txt"
[ -f "$CACHE" ] || { echo "no token cache $CACHE: make it first (see the head of this script)" >&2; exit 2; }
WORK=$(mktemp -d)
set -o pipefail
"$PY" -m policy.train --tokens-cache "$CACHE" --stage 2 --init "$INIT" --out "$WORK/s2" --device "$DEVICE" \
  --batch-size "$BATCH" --aux-batch-size $(( BATCH >= 8 ? BATCH / 8 : 1 )) --lr "$LR" --dropout 0 --known-prefix-max 8 \
  --steps 100000 --time-budget-s "$BUDGET_S" --save-every 0 --eval-samples "$EVAL_SAMPLES" --no-progress \
  2>&1 | tee "$OUT/train.log"
cp "$WORK/s2/stage2.pt" "$WORK/s2/MODEL_CARD.md" "$OUT/"
echo "DEVICE TRAIN DONE: $OUT/stage2.pt"
