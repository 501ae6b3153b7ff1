#!/usr/bin/env bash
# Issue 30's figures: the scripted expert natively and served in each preset (the same seeds), one piece of the
# convention wrong, and the watchdog's stops for 10 waypoints at 150 ms. Outputs beside this file; summary.py reads them.
#   bash docs/presets/run.sh            (about 10 minutes on the 2-core VM)
set -euo pipefail
cd "$(dirname "$0")/../.."
export MUJOCO_GL=egl
out=docs/presets
N=${N:-20}
common=(--episodes "$N" --replan-hz 5 --quiet)
pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true' EXIT
port=8740
for preset in libero droid; do
  port=$((port + 1))
  python -m scenarios.serve --source expert --preset "$preset" --port "$port" > "$out/serve_$preset.log" 2>&1 &
  pids+=($!)
  sleep 8
  case $preset in libero) h=10; dt=0.05 ;; droid) h=10; dt=0.06666666666666667 ;; esac
  for target in static linear; do
    python -m scenarios.moving_target --source expert --horizon "$h" --chunk-dt-s "$dt" --target "$target" \
      --mode open_loop hybrid "${common[@]}" --json "$out/${preset}_${target}_native.json" > "$out/${preset}_${target}_native.txt"
    python -m scenarios.moving_target --source "ws://127.0.0.1:$port" --preset "$preset" --target "$target" \
      --mode open_loop hybrid "${common[@]}" --json "$out/${preset}_${target}_served.json" > "$out/${preset}_${target}_served.txt"
    # one piece wrong: the rows read as deltas from the observation, not as successive steps
    python -m scenarios.moving_target --source "ws://127.0.0.1:$port" --preset "$preset" --delta-from observation \
      --target "$target" --mode open_loop "${common[@]}" --json "$out/${preset}_${target}_wrong.json" > "$out/${preset}_${target}_wrong.txt"
  done
done
# the watchdog: 10 waypoints x 0.1 s from a server that answers in 150 ms, the measured latency
port=$((port + 1))
python -m scenarios.serve --source expert --horizon 10 --infer-delay-ms 150 --port "$port" > "$out/serve_slow.log" 2>&1 &
pids+=($!)
sleep 8
slow=(--source "ws://127.0.0.1:$port" --latency-ms measured --target linear --mode open_loop hybrid --episodes 10 --quiet)
python -m scenarios.moving_target "${slow[@]}" --json "$out/watchdog_1hz.json" > "$out/watchdog_1hz.txt"
hz=$(python -c "import json; print(json.load(open('$out/watchdog_1hz.json'))['config']['connect']['coverage']['suggested_replan_hz'])")
python -m scenarios.moving_target "${slow[@]}" --replan-hz "$hz" --json "$out/watchdog_suggested.json" > "$out/watchdog_suggested.txt"
# the conformance probe against a conforming server
python -m scenarios.probe "ws://127.0.0.1:8741" --preset libero --json "$out/probe_libero.json" > "$out/probe_libero.txt" || true
python docs/presets/summary.py | tee "$out/summary.md"
