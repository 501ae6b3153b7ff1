"""The sweep's Ray backend against a real local head (``ray start --head``, 2 workers), on loopback only: the same
grid and seeds give exactly the local backend's results.

Ray binds to the machine's routable address when it has one, so the head runs in a network namespace whose only
interface is ``lo``. Outside CI the test is skipped when Ray (the ``[cluster]`` extra) or network namespaces are
missing; CI sets ``MMACT_REQUIRE_RAY=1`` (``.ci/run``), and then a missing piece fails the test instead.
"""

import csv
import json
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

REQUIRED = os.environ.get("MMACT_REQUIRE_RAY") == "1"
REPO = Path(__file__).resolve().parents[1]
#: columns that are wall-clock measurements, not results
TIMING = ("tick_us", "realtime_factor", "plan_ms", "sensor_ms", "wall_s", "mpc_solve_us", "round_trip")


def _missing(reason: str):
    if REQUIRED:
        pytest.fail(f"MMACT_REQUIRE_RAY=1 but {reason}")
    pytest.skip(reason)


def _rows(path: Path) -> dict:
    rows = list(csv.DictReader((path / "results.csv").open()))
    return {(r["mode"], r["target"], r["seed"]): {k: v for k, v in r.items() if not k.startswith(TIMING)} for r in rows}


def test_ray_backend_gives_the_local_results_on_a_local_head(tmp_path):
    try:
        import ray  # noqa: F401
    except ImportError:
        _missing("Ray is not installed (pip install -e '.[cluster]')")
    if shutil.which("ip") is None or os.geteuid() != 0:
        _missing("a loopback-only network namespace needs iproute2 and root")
    grid = [{"name": "families", "modes": ["open_loop", "hybrid"], "replan_hz": [1.0], "latency_ms": [200.0],
             "target": ["reversal", "jump"], "speed_m_s": [0.3], "bins": [2048], "seeds": [0, 1]}]
    local, remote = tmp_path / "local", tmp_path / "ray"
    common = ["--quiet", "--duration-s", "2", "--grid", json.dumps(grid)]
    subprocess.run([sys.executable, "-m", "scenarios.sweep", "--workers", "2", "--out", str(local), *common],
                   check=True, cwd=REPO, capture_output=True, timeout=600)
    ns = f"mmact-{uuid.uuid4().hex[:8]}"
    if subprocess.run(["ip", "netns", "add", ns], capture_output=True).returncode != 0:
        _missing("cannot create a network namespace here")
    try:
        subprocess.run(["ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up"], check=True)
        bindir = os.path.dirname(sys.executable)
        script = (
            f"{bindir}/ray start --head --node-ip-address=127.0.0.1 --port=6391 --num-cpus=2 "
            f"--include-dashboard=false --disable-usage-stats >/dev/null 2>&1 && "
            f"{sys.executable} -m scenarios.sweep --backend ray --ray-address 127.0.0.1:6391 --out {remote} "
            f"{' '.join(common[:3])} --grid '{json.dumps(grid)}'; rc=$?; "
            f"{bindir}/ray stop --force >/dev/null 2>&1; exit $rc"
        )
        proc = subprocess.run(["ip", "netns", "exec", ns, "bash", "-c", script], capture_output=True, text=True,
                              timeout=600, cwd=REPO)
        assert proc.returncode == 0, proc.stderr[-2000:]
    finally:
        subprocess.run(["ip", "netns", "delete", ns], capture_output=True)
    a, b = _rows(local), _rows(remote)
    assert len(a) == 8 and set(a) == set(b)
    for key in a:
        assert a[key] == b[key], key  # every result column identical, cell by cell
    assert (remote / "report.md").is_file()
