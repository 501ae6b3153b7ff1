"""The task protocol (``--task``): what a task is to the rest of the project. One file per task in this package
implements it, ``registry.TASK_PATHS`` names them; the loop and the executors know no task: the world a task builds
reports its figures (``task_report``) and the contact wrench (``RobotState.wrench_ext``), and the metrics read them."""

from __future__ import annotations

from typing import Protocol

from scenarios.world.targets import TargetSpec


class Task(Protocol):
    """A task: its scene, its world (reset from a seed, the 100 Hz measurement channel, the success predicate and
    figures in ``task_report()``), its target course and its scripted expert.

    Attributes:
        name: the ``--task`` name.
        tcp_floor_m: the lowest TCP reference the task needs, m (None: the stack's default).
        world_class: the ``SimWorld`` subclass of its scene (constructed as ``SimWorld`` is).
        contact: whether the robot touches things (the stack then checks the contact force).
        pull_axes: the axes the hybrid layer retargets a chunk on (``controllers.retarget.PULL_AXES``).
        descent_band_m: (low, high) TCP heights the hand passes at a guarded move's speed, where the fingertips pass
            the top of the task's objects (``StackConfig.descent_band_m``); None: no band.
        close_below_m: the gripper starts closing only with the TCP below this height (``StackConfig.close_below_m``);
            None: the chunk's clock decides.
        close_below_reading_m: in a mode that reads the object, the gripper starts closing only with the TCP below
            this height instead (``StackConfig.close_below_reading_m``); None: ``close_below_m``.
        close_stops_descent_m: with ``close_below_reading_m``, the hand stops coming down once the gripper starts
            closing, at most this under the TCP's height then (``StackConfig.close_stops_descent_m``), m; None: it
            goes on.
        capture_tol_m: with a descent band, the hand stays over it while the object is off the fingers' axis by more
            than this, in a mode that reads the object (``StackConfig.capture_tol_m``); None: no such gate.
        capture_clear_m: across the fingers' axis, an object off the TCP by more than this clears the fingers
            (``StackConfig.capture_clear_m``; read only with ``capture_tol_m``).
        mpc_z_weight: the MPC's weight on the vertical position error relative to the horizontal
            (``controllers.mpc.MPCConfig.w_pos_z_scale``; 1: alike).
        guard_yield_m_s_per_n: how fast the contact-force guard yields per newton over its threshold
            (``StackConfig.guard_yield_m_s_per_n``), m/s/N.
        empty_hand_after_s: a closing that has gone on this long with the object not between the fingers found
            nothing: the closed hand rises before it goes on, in a mode that reads the object
            (``StackConfig.empty_hand_after_s``), s; None: no such gate.
        empty_hand_beside_m: with ``empty_hand_after_s`` and ``capture_tol_m``: a closing whose measured opening can
            no longer take in the object, with the object off the TCP across the fingers' axis by more than this
            (beside the fingers), found nothing at once (``StackConfig.empty_hand_beside_m``), m; None: only after
            ``empty_hand_after_s``.
        landing_speed_m_s: with a descent band, the speed at which a mode that does not read the object passes the
            band (``StackConfig.landing_speed_m_s``), m/s; None: no band in those modes.
        empty_grip_below_m: fingers closed closer than this found nothing: the hand rises at once, in a mode that
            does not read the object (``StackConfig.empty_grip_below_m``), m; None: no such gate.
        compliance_caps_pressing: with ``--compliance``, the impedance's force cap acts only on the push into the
            measured contact (``StackConfig.compliance_caps_pressing``); False: on the force's magnitude.
    """

    name: str
    tcp_floor_m: float | None
    world_class: type
    contact: bool
    pull_axes: str
    descent_band_m: tuple[float, float] | None
    close_below_m: float | None
    close_below_reading_m: float | None
    close_stops_descent_m: float | None
    capture_tol_m: float | None
    capture_clear_m: float
    mpc_z_weight: float
    guard_yield_m_s_per_n: float
    empty_hand_after_s: float | None
    empty_hand_beside_m: float | None
    landing_speed_m_s: float | None
    empty_grip_below_m: float | None
    compliance_caps_pressing: bool

    def add_to_scene(self, spec, config) -> None:
        """Add the task's bodies, pads and contact settings to the MjSpec of the Panda scene."""

    def target_spec(self, kind: str, speed_m_s: float, plane_z_m: float = 0.0) -> TargetSpec:
        """The course of the task's moving thing (the ball, the carrier, the fixture) for a motion family."""

    def make_expert(self, bins: int, horizon: int, dt_s: float, lead: str, world=None):
        """The task's scripted expert (a ``ChunkSource``)."""
