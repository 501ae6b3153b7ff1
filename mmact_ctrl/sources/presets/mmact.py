"""Our own convention: the ``mmact`` observation keys (everything an ``Observation`` holds, the true target
included: only a server of ours reads them) and our task-space chunk (absolute TCP pose, rotation vector relative to
the nominal grasp, gripper opening in m, 16 waypoints 0.1 s apart). ``python -m scenarios.serve`` declares it in its
metadata, so a client of ours needs no switch; ``--preset mmact`` names it for a server that does not say."""

from __future__ import annotations

from mmact_ctrl.sources.action_space import ActionSpace
from mmact_ctrl.sources.remote.mapping import MmactMapping
from mmact_ctrl.sources.presets.convention import Convention

MMACT = Convention(
    name="mmact",
    mapping=MmactMapping(),
    action=ActionSpace(kind="tcp_pose", gripper="width_m", dt_s=0.1),
    horizon=16,
    state_rotation="rotation vector relative to the nominal grasp (mmact/ee_rotvec_rad)",
    sources=("mmact_ctrl.chunk.ActionChunk, mmact_ctrl.sources.remote.serving",),
)
