"""``reach`` (the default task, as it always was): the TCP within 3 cm of a ball for 0.3 s. The balls are mocap
bodies without collision (``scenarios.world.panda_scene``), the metrics are ``mmact_ctrl.metrics``' and the expert is
``scenarios.world.expert.ScriptedExpert``."""

from __future__ import annotations

from mmact_ctrl.control.force_guard import YIELD_M_S_PER_N
from scenarios.world.sim_world import SimWorld
from scenarios.world.targets import TargetSpec, target_spec


class ReachTask:
    """The reach task behind the task protocol (``scenarios.world.tasks.base.Task``)."""

    name = "reach"
    #: None: the stack's own floor (``StackConfig.tcp_floor_m``)
    tcp_floor_m: float | None = None
    #: the axes the hybrid layer retargets a chunk on (``controllers.retarget.PULL_AXES``)
    pull_axes = "xyz"
    world_class = SimWorld
    #: no contact: the stack needs no contact-force limit
    contact = False
    descent_band_m = None
    close_below_m = None
    close_below_reading_m = None
    close_stops_descent_m = None
    capture_tol_m = None
    capture_clear_m = 0.0
    mpc_z_weight = 1.0
    guard_yield_m_s_per_n = YIELD_M_S_PER_N
    empty_hand_after_s = None
    empty_hand_beside_m = None
    landing_speed_m_s = None
    empty_grip_below_m = None
    compliance_caps_pressing = False
    #: SceneConfig fields the task sets (none: reach's scene is the base scene)
    scene_overrides: dict = {}

    def add_to_scene(self, spec, config) -> None:
        """Nothing: the reach scene is the base scene."""

    def target_spec(self, kind: str, speed_m_s: float, plane_z_m: float = 0.0) -> TargetSpec:
        return target_spec(kind, speed_m_s, plane_z_m)

    def make_expert(self, bins: int, horizon: int, dt_s: float, lead: str, world=None):
        from scenarios.world.factory import make_reach_expert

        return make_reach_expert(bins=bins, horizon=horizon, dt_s=dt_s, lead=lead, world=world)
