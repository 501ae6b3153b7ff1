#!/usr/bin/env bash
# Issue 22's figures: a foreign source in the study and the fault suite, our token policy served vs in-process,
# the protocol's overhead, and sources in other action spaces. Outputs land in docs/byo/. ~15 min on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
export MUJOCO_GL=egl PYTHONUNBUFFERED=1
OUT=docs/byo
PORT=${PORT:-8765}

# 1. the study and the fault suite on the README's example source
python -m scenarios.sweep --quick --source examples/byo_source.py:make_source --out $OUT/sweep_quick --quiet
python -m scenarios.faults --quick --source examples.byo_source:make_source --out $OUT/faults_quick --quiet --workers 2

# 2. our token policy in this process vs served by scenarios.serve (another process), same seeds
for t in static linear; do
  python -m scenarios.moving_target --source policy --target $t --mode open_loop hybrid --episodes 20 --quiet \
    --json $OUT/policy_inproc_$t.json > $OUT/policy_inproc_$t.txt
done
python -m scenarios.serve --source policy --port $PORT > $OUT/serve.log 2>&1 &
SERVER=$!
trap 'kill $SERVER 2>/dev/null || true' EXIT
for i in $(seq 50); do curl -sf http://127.0.0.1:$PORT/healthz > /dev/null && break; sleep 0.2; done
for t in static linear; do
  python -m scenarios.moving_target --source ws://127.0.0.1:$PORT --target $t --mode open_loop hybrid --episodes 20 \
    --quiet --json $OUT/policy_ws_$t.json > $OUT/policy_ws_$t.txt
done
# the same with the latency as it ran (each chunk active after its measured round trip)
python -m scenarios.moving_target --source ws://127.0.0.1:$PORT --target linear --mode hybrid --episodes 20 \
  --latency-ms measured --quiet --json $OUT/policy_ws_linear_measured.json > $OUT/policy_ws_linear_measured.txt
kill $SERVER; trap - EXIT
python docs/byo/compare.py $OUT/policy_inproc_static.json $OUT/policy_ws_static.json \
  $OUT/policy_inproc_linear.json $OUT/policy_ws_linear.json > $OUT/served_vs_inprocess.md

# 3. the protocol's overhead on loopback: two 224 x 224 images + state
python -m mmact_ctrl.sources.openpi.bench --calls 500 --json $OUT/wire_bench.json > $OUT/wire_bench.txt

# 4. sources that speak joint positions and TCP deltas, static target, hybrid
for f in make_joint_source make_delta_source; do
  python -m scenarios.moving_target --source examples.action_spaces:$f --target static --mode hybrid --episodes 20 \
    --quiet --json $OUT/$f.json > $OUT/$f.txt
done
echo done
