#!/usr/bin/env bash
# The sweep's quick grid on a local Ray head (2 workers, in a loopback-only network namespace) vs the local backend:
# every result column of the 75 cells and the report tables must be identical. Needs root (ip netns) and the cluster extra.
set -e
cd "$(dirname "$0")/../.."
. .venv/bin/activate; export MUJOCO_GL=egl
rm -rf ${OUT:-/tmp}/q_local ${OUT:-/tmp}/q_ray
python -m scenarios.sweep --quick --out ${OUT:-/tmp}/q_local --quiet --workers 2
ns=mmact-q$$; ip netns add $ns; ip netns exec $ns ip link set lo up
ip netns exec $ns bash -c "ray start --head --node-ip-address=127.0.0.1 --port=6392 --num-cpus=2 --include-dashboard=false --disable-usage-stats >/dev/null 2>&1 && python -m scenarios.sweep --quick --backend ray --ray-address 127.0.0.1:6392 --out ${OUT:-/tmp}/q_ray --quiet; rc=\$?; ray stop --force >/dev/null 2>&1; exit \$rc"
ip netns delete $ns
python - <<'PY'
import csv
T = ("tick_us", "realtime_factor", "plan_ms", "sensor_ms", "wall_s", "mpc_solve_us", "round_trip")
def rows(p):
    return {(r["study"], r["mode"], r["target"], r["seed"], r["lead"], r["replan_hz"], r["latency_ms"], r["bins"], r["speed_m_s"], r.get("d_steps"), r.get("s_steps")): {k: v for k, v in r.items() if not k.startswith(T)} for r in csv.DictReader(open(p + "/results.csv"))}
a, b = rows("${OUT:-/tmp}/q_local"), rows("${OUT:-/tmp}/q_ray")
diff = [k for k in a if a[k] != b.get(k)]
print("cells", len(a), len(b), "differing", len(diff))
PY
diff <(grep -v "this run took" ${OUT:-/tmp}/q_local/report.md) <(grep -v "this run took" ${OUT:-/tmp}/q_ray/report.md) && echo "report tables identical"
