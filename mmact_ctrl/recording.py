"""A Rerun recording of episodes (``--rerun PATH.rrd``), viewable later with ``rerun PATH.rrd``.

rerun-sdk is an optional extra (``pip install -e ".[viz]"``). Each episode is logged under ``<name>/`` on the
``sim_time`` timeline (s):

3-D (``<name>/world/...``)
    ``tcp`` the TCP's path, ``target`` the instructed ball, ``target_estimate`` the filter's estimate (100 Hz),
    ``reference`` the reference the QP tracked, ``chunk`` the active chunk's waypoints (one line per activation),
    ``mpc_preview`` each MPC plan's predicted TCP path;
time series (``<name>/metrics/...``)
    ``error_m`` TCP-target distance, ``torque_rate_nm_s`` the largest joint torque rate sent, ``tick_us`` the 1 kHz
    path's time, ``overrun`` (1 where a real-time command was late; 0 elsewhere), ``exec_us`` (real time: a tick's
    work);
images (``<name>/camera/<view>``)
    the frames each query of the source was answered from.

The episode must have been run with ``record=True`` (``EpisodeRunner``) for the estimate, chunks, previews and
frames; the rest comes from every log.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mmact_ctrl.episode_log import EpisodeLog

#: the entity paths under each episode's name (the test reads them back)
WORLD = ("world/tcp", "world/target", "world/target_estimate", "world/reference", "world/chunk", "world/mpc_preview")
METRICS = ("metrics/error_m", "metrics/torque_rate_nm_s", "metrics/tick_us", "metrics/overrun")
#: every how many ticks the 3-D paths are logged (100 Hz at a 1 ms tick)
PATH_STRIDE = 10


def _rerun():
    try:
        import rerun as rr
    except ImportError:
        raise RuntimeError("--rerun needs rerun-sdk: pip install -e '.[viz]'") from None
    return rr


def write_recording(logs: dict[str, EpisodeLog], path: str | Path, app_id: str = "mmact_ctrl",
                    camera_names: tuple[str, ...] = ()) -> Path:
    """Write ``logs`` (name -> episode log, e.g. one per mode) to the Rerun file ``path``."""
    rr = _rerun()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(app_id)
    rec.save(str(path))
    for name, log in logs.items():
        _log_episode(rr, rec, name, log, camera_names)
    rec.flush()
    rec.disconnect()
    return path


def _log_episode(rr, rec, name: str, log: EpisodeLog, camera_names: tuple[str, ...]) -> None:
    t = np.asarray(log.t_s, dtype=float)
    if len(t) < 2:
        return
    dt = float(t[1] - t[0])
    times = rr.TimeColumn("sim_time", duration=t)
    err = np.linalg.norm(log.ee_pos_m - log.target_pos_m, axis=1)
    tau = np.asarray(log.tau_cmd_nm, dtype=float)
    rate = np.zeros(len(t))
    rate[1:] = np.max(np.abs(np.diff(tau, axis=0)), axis=1) / dt
    overrun = np.zeros(len(t))
    if log.rt_late_ticks is not None and len(log.rt_late_ticks):
        late = np.asarray(log.rt_late_ticks, dtype=int)
        overrun[late[(late >= 0) & (late < len(t))]] = 1.0
    series = {"metrics/error_m": err, "metrics/torque_rate_nm_s": rate, "metrics/tick_us": np.asarray(log.tick_us),
              "metrics/overrun": overrun}
    if log.rt_exec_us is not None and len(log.rt_exec_us) == len(t):
        series["metrics/exec_us"] = np.asarray(log.rt_exec_us, dtype=float)
    for entity, values in series.items():
        rec.send_columns(f"{name}/{entity}", indexes=[times], columns=rr.Scalars.columns(scalars=values))
    # 3-D: the paths at 100 Hz, each point on its time
    for i in range(0, len(t), PATH_STRIDE):
        rec.set_time("sim_time", duration=float(t[i]))
        rec.log(f"{name}/world/tcp", rr.Points3D([log.ee_pos_m[i]], radii=0.006, colors=[(40, 120, 255)]))
        rec.log(f"{name}/world/target", rr.Points3D([log.target_pos_m[i]], radii=0.02, colors=[(230, 50, 50)]))
        if np.all(np.isfinite(log.ref_pos_m[i])):
            rec.log(f"{name}/world/reference", rr.Points3D([log.ref_pos_m[i]], radii=0.004, colors=[(60, 200, 90)]))
    rec.set_time("sim_time", duration=0.0)
    rec.log(f"{name}/world/tcp_path", rr.LineStrips3D([log.ee_pos_m[::PATH_STRIDE]], colors=[(40, 120, 255)]))
    recd = log.recording or {}
    for t_est, est in recd.get("estimate", []):
        rec.set_time("sim_time", duration=float(t_est))
        rec.log(f"{name}/world/target_estimate", rr.Points3D([est], radii=0.012, colors=[(250, 170, 40)]))
    for t_act, _times, waypoints in recd.get("chunks", []):
        rec.set_time("sim_time", duration=float(t_act))
        rec.log(f"{name}/world/chunk", rr.LineStrips3D([waypoints[:, :3]], colors=[(170, 80, 220)]))
    for t_asked, _t0, _dt, preview in recd.get("mpc", []):
        rec.set_time("sim_time", duration=float(t_asked))
        rec.log(f"{name}/world/mpc_preview", rr.LineStrips3D([preview], colors=[(20, 200, 200)]))
    for t_q, frames in recd.get("frames", []):
        rec.set_time("sim_time", duration=float(t_q))
        for v, img in enumerate(np.asarray(frames)):
            view = camera_names[v] if v < len(camera_names) else f"view{v}"
            rec.log(f"{name}/camera/{view}", rr.Image(img))


def entity_paths(path: str | Path) -> set[str]:
    """The entity paths a Rerun file holds (read back with rerun-sdk)."""
    _rerun()  # the one-line error when rerun-sdk is missing
    from rerun.chunk import RrdReader

    paths = set()
    for chunk in RrdReader(str(path)).stream().to_chunks():
        paths.add(str(chunk.entity_path).lstrip("/"))
    return paths
