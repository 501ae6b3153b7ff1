"""The sweep's Ray backend against a real local head (``ray start --head``), on loopback only.

Ray binds to the machine's routable address when it has one, so the head runs in a network
namespace whose only interface is ``lo``. Skipped when Ray (the ``[cluster]`` extra) or
network namespaces are not available.
"""

import csv
import json
import os
import shutil
import subprocess
import sys
import uuid

import pytest

ray = pytest.importorskip("ray")

pytestmark = pytest.mark.skipif(
    shutil.which("ip") is None or os.geteuid() != 0, reason="needs iproute2 and root for a loopback-only namespace"
)


def test_sweep_on_a_local_ray_head(tmp_path):
    ns = f"mmact-{uuid.uuid4().hex[:8]}"
    if subprocess.run(["ip", "netns", "add", ns], capture_output=True).returncode != 0:
        pytest.skip("cannot create a network namespace here")
    try:
        subprocess.run(["ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up"], check=True)
        grid = [{"name": "replan", "modes": ["open_loop", "hybrid"], "replan_hz": [1.0], "latency_ms": [200.0],
                 "target": ["linear"], "speed_m_s": [0.3], "bins": [2048], "seeds": [0]}]
        bindir = os.path.dirname(sys.executable)
        script = (
            f"{bindir}/ray start --head --node-ip-address=127.0.0.1 --port=6391 --num-cpus=2 "
            f"--include-dashboard=false --disable-usage-stats >/dev/null 2>&1 && "
            f"{sys.executable} -m scenarios.sweep --backend ray --ray-address 127.0.0.1:6391 --quiet "
            f"--duration-s 2 --out {tmp_path} --grid '{json.dumps(grid)}'; rc=$?; "
            f"{bindir}/ray stop --force >/dev/null 2>&1; exit $rc"
        )
        proc = subprocess.run(["ip", "netns", "exec", ns, "bash", "-c", script], capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
    finally:
        subprocess.run(["ip", "netns", "delete", ns], capture_output=True)
    rows = list(csv.DictReader((tmp_path / "results.csv").open()))
    assert sorted(r["mode"] for r in rows) == ["hybrid", "open_loop"]
    assert (tmp_path / "report.md").is_file()
