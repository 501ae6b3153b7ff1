#!/usr/bin/env bash
# Issue 24's figures (about 35 min, most of it in real time: run it on an idle machine).
set -euo pipefail
cd "$(dirname "$0")/../.."
export MUJOCO_GL=egl PYTHONUNBUFFERED=1
OUT=docs/realtime
PRIO=${PRIO:-10}

# 1. hybrid, the scripted expert served in another process, 10 episodes of 6 s in real time (with and without FIFO)
python -m scenarios.moving_target --realtime --rt-priority $PRIO --source expert --mode hybrid --episodes 10 --quiet \
  --json $OUT/expert_hybrid_rt.json > $OUT/expert_hybrid_rt.txt
# a recording of one episode (recording is work on the loop's thread too: kept out of the figure above)
python -m scenarios.moving_target --realtime --rt-priority $PRIO --source expert --mode hybrid --episodes 1 --quiet \
  --json $OUT/expert_hybrid_rt_recorded.json --rerun $OUT/expert_hybrid_rt.rrd > $OUT/expert_hybrid_rt_recorded.txt
# one 60 s episode: no drift
python -m scenarios.moving_target --realtime --rt-priority $PRIO --source expert --mode hybrid --target random_walk \
  --duration-s 60 --episodes 1 --quiet --json $OUT/expert_hybrid_60s.json > $OUT/expert_hybrid_60s.txt
python -m scenarios.moving_target --realtime --rt-priority 0 --source expert --mode hybrid --episodes 10 --quiet \
  --json $OUT/expert_hybrid_rt_noprio.json > $OUT/expert_hybrid_rt_noprio.txt

# 2. our token policy in its own process (1 torch thread) at 1 Hz and 5 Hz, real time vs the measured latency
for hz in 1 5; do
  python -m scenarios.realtime_check --source policy --modes hybrid --targets linear --replan-hz $hz --episodes 10 \
    --rt-priority $PRIO --out $OUT/policy_${hz}hz --quiet > $OUT/policy_${hz}hz.txt
done

# 3. every mode on linear and reversal, real time vs simulated time with the measured latency (expert, 10 seeds)
python -m scenarios.realtime_check --rt-priority $PRIO --episodes 10 --out $OUT/check --quiet > $OUT/check.txt

# 4. the tick in simulated time, the MPC off the path
python -m mmact_ctrl.bench --json $OUT/bench.json > $OUT/bench.txt

# 5. the host: the same pacer around a fixed CPU work and nothing of ours, interleaved with the stack (about 10 min)
bash $OUT/host/run.sh $OUT/host
python $OUT/host/summary.py $OUT/host > $OUT/host/summary.txt
echo done
