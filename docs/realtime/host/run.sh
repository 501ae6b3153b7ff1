#!/usr/bin/env bash
# Is the host or the stack behind the real-time figures? The empty 1 kHz loop (host_check) and the stack's real-time
# run (hybrid, served expert, 10 x 6 s), interleaved, three pairs; then the empty loop with half the work.
# bash docs/realtime/host/run.sh [OUT]   (2026-12-03: about 9 minutes on the 2-core test machine)
set -euo pipefail
OUT=${1:-docs/realtime/host}
mkdir -p "$OUT"
export MUJOCO_GL=${MUJOCO_GL:-egl}
for i in 1 2 3; do
  python -m mmact_ctrl.realtime.host_check --quiet --json "$OUT/empty_330us_$i.json" | tee "$OUT/empty_330us_$i.txt"
  python -m scenarios.moving_target --realtime --rt-priority 10 --source expert --mode hybrid --episodes 10 --quiet \
    --json "$OUT/stack_$i.json" | tee "$OUT/stack_$i.txt"
done
python -m mmact_ctrl.realtime.host_check --quiet --work-us 150 --json "$OUT/empty_150us.json" | tee "$OUT/empty_150us.txt"
