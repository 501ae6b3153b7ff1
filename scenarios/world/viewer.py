"""MuJoCo's passive viewer for ``--viewer``: where there is a display, the episodes play in it as they run."""

from __future__ import annotations

import os

from mmact_ctrl.runner import EpisodeRunner

#: how often the viewer is synced, s of simulated time (about 60 frames per simulated second)
SYNC_EVERY_S = 1.0 / 60.0


def require_display() -> None:
    """Raise ``RuntimeError`` (one line) when there is no display to open the viewer on."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise RuntimeError("--viewer needs a display (DISPLAY is not set): MuJoCo's passive viewer cannot open here; "
                           "use --rerun PATH.rrd to look at the run later")


def run_with_viewer(world, source, controller, seed: int, sensor=None, record: bool = False):
    """One episode of the main job, the viewer synced every :data:`SYNC_EVERY_S`; returns its log."""
    import mujoco.viewer

    runner = EpisodeRunner(world, source, controller, seed, sensor=sensor, record=record)
    with mujoco.viewer.launch_passive(world.model, world.data) as viewer:
        while not runner.done and viewer.is_running():
            runner.advance(runner.t_s + SYNC_EVERY_S)
            viewer.sync()
    runner.advance()
    return runner.finish()
