"""A chunk source started in a process of its own (``python -m scenarios.serve``) for the real-time mode.

``--realtime`` runs the source beside the loop, as on a robot: a ``ws://`` source is used as it is; any other
(``policy``, ``expert``, ``module:factory``) is served by ``scenarios.serve`` on a free port of 127.0.0.1, and the
episode drives it through the openpi protocol. The server process is stopped when the run ends.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

_URL = re.compile(r"serving .* at (ws://[0-9.]+:[0-9]+)")
REPO = Path(__file__).resolve().parents[1]


def serve_argv(settings) -> list[str]:
    """The ``scenarios.serve`` switches of a :class:`~scenarios.sources.SourceSettings` (port 0: a free one)."""
    argv = ["--source", settings.spec, "--port", "0", "--host", "127.0.0.1"]
    kind = settings.kind
    if kind == "policy":
        if settings.checkpoint:
            argv += ["--checkpoint", str(settings.checkpoint)]
        if settings.action_steps != 1:
            argv += ["--action-steps", str(settings.action_steps)]
        if settings.refine_bins is not None:
            argv += ["--refine-bins", str(settings.refine_bins)]
    elif kind == "expert":
        argv += ["--expert-lead", settings.expert_lead, "--bins", str(settings.bins), "--horizon", str(settings.horizon)]
        if settings.chunk_dt_s:
            argv += ["--chunk-dt-s", str(settings.chunk_dt_s)]
    elif kind == "replay":
        pass  # the dataset says what its actions are
    elif kind == "plugin":
        import json

        for key, value in settings.args.items():
            argv += ["--source-arg", f"{key}={json.dumps(value) if not isinstance(value, str) else value}"]
    else:
        raise ValueError(f"--source {settings.spec} is already a server: nothing to start")
    return argv


class ServedSource:
    """``python -m scenarios.serve`` with ``argv`` in a subprocess; ``url`` once it listens.

    Args:
        argv: the serve switches (:func:`serve_argv`).
        cpus: the CPUs the server process may run on (empty: any).
        timeout_s: how long to wait for it to listen (loading a checkpoint takes a few seconds).
    """

    def __init__(self, argv: list[str], cpus: set[int] | None = None, timeout_s: float = 120.0) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self._proc = subprocess.Popen([sys.executable, "-m", "scenarios.serve", *argv], cwd=REPO, env=env,
                                      stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if cpus:
            try:
                os.sched_setaffinity(self._proc.pid, cpus)
            except OSError:
                pass
        self.lines: list[str] = []
        self.url = self._wait_for_url(timeout_s)
        # keep draining its output (a full pipe would block the server)
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()

    def _wait_for_url(self, timeout_s: float) -> str:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            line = self._proc.stdout.readline()
            if not line:
                if self._proc.poll() is not None:
                    break
                continue
            self.lines.append(line.rstrip())
            m = _URL.search(line)
            if m:
                return m.group(1)
        self.close()
        detail = self.lines[-1] if self.lines else "no output"
        raise RuntimeError(f"the source server did not start: {detail}")

    def _drain(self) -> None:
        for line in self._proc.stdout:
            self.lines.append(line.rstrip())

    def close(self) -> None:
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()

    def __enter__(self) -> "ServedSource":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
