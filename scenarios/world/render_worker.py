"""Camera frames of world snapshots, rendered in a process of its own.

In real time the 1 kHz loop must not render: MuJoCo's renderer holds the GIL for the whole frame (measured here:
a render in a thread stalled the loop's thread for milliseconds at every frame). The loop takes a snapshot of the
world at the query (``SimWorld.snapshot``: positions and mocap poses, ~10 us), and the query's worker thread has it
rendered here (``SimWorld.render_snapshot``), waiting on a pipe, which releases the GIL.
"""

from __future__ import annotations

import multiprocessing as mp

import numpy as np

from scenarios.world.panda_scene import SceneConfig


def _serve(conn, scene: SceneConfig) -> None:
    import mujoco

    from scenarios.world.panda_scene import build_panda_model

    model = build_panda_model(scene)
    data = mujoco.MjData(model)
    size = int(scene.image_size_px)
    renderer = mujoco.Renderer(model, height=size, width=size)
    conn.send(("ready",))
    while True:
        try:
            snap = conn.recv()
        except (EOFError, OSError):
            break
        if snap is None:
            break
        data.qpos[:] = snap["qpos"]
        data.mocap_pos[:] = snap["mocap_pos"]
        data.mocap_quat[:] = snap["mocap_quat"]
        data.time = snap["time"]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_camlight(model, data)
        frames = []
        for name in scene.camera_names:
            renderer.update_scene(data, camera=name)
            frames.append(renderer.render())
        conn.send(np.stack(frames))
    renderer.close()


class RenderProcess:
    """A process that renders snapshots of a scene with ``scene``'s cameras (one request at a time)."""

    def __init__(self, scene: SceneConfig) -> None:
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe(duplex=True)
        self._proc = ctx.Process(target=_serve, args=(child, scene), name="render-process", daemon=True)
        self._proc.start()
        child.close()
        if not self._conn.poll(120.0) or self._conn.recv()[0] != "ready":
            raise RuntimeError("the render process did not start (is MUJOCO_GL=egl set?)")

    def render(self, snapshot: dict) -> np.ndarray:
        """Frames ``(V, H, W, 3)`` uint8 of the snapshot."""
        self._conn.send(snapshot)
        return self._conn.recv()

    def close(self) -> None:
        try:
            self._conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        self._proc.join(timeout=2.0)
        if self._proc.is_alive():
            self._proc.kill()
