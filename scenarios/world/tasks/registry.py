"""The tasks by name (``--task``): ``reach`` (today's), ``pick``, ``insert``; one file each in this package."""

from __future__ import annotations

import importlib

from mmact_ctrl.control.force_guard import YIELD_M_S_PER_N

#: every task, by name: ``module:class``
TASK_PATHS: dict[str, str] = {
    "reach": "scenarios.world.tasks.reach:ReachTask",
    "pick": "scenarios.world.tasks.pick:PickTask",
    "insert": "scenarios.world.tasks.insert:InsertTask",
}
TASKS: tuple[str, ...] = tuple(TASK_PATHS)


def task_by_name(name: str):
    """The task ``name`` (a one-line ``ValueError`` naming the tasks otherwise)."""
    if name not in TASK_PATHS:
        raise ValueError(f"unknown task {name!r}: choose one of {', '.join(TASKS)}")
    module, _, cls = TASK_PATHS[name].partition(":")
    return getattr(importlib.import_module(module), cls)()


def task_stack_settings(name: str, compliance: bool = False, close_at_grasp: bool = False) -> dict:
    """The ``StackConfig`` settings a task needs: its TCP floor and the axes a chunk is retargeted on, and
    ``compliance`` and ``close_at_grasp`` (``task_guard_settings``); none for reach (its stack is as it always was)."""
    if name == "reach" and not compliance:
        return {}
    from controllers.retarget import RetargetConfig

    task = task_by_name(name)
    box = task_target_box(task)
    return {**({"tcp_floor_m": task.tcp_floor_m} if task.tcp_floor_m is not None else {}),
            **({"target_box_m": box} if box is not None else {}), **task_guard_settings(task, close_at_grasp),
            "retarget": RetargetConfig(pull_axes=task.pull_axes), "compliance": bool(compliance)}


def task_guard_settings(task, close_at_grasp: bool = False) -> dict:
    """The guarded descent a task asks for (``Task.descent_band_m``, ``Task.close_below_m``,
    ``Task.close_below_reading_m`` and ``Task.close_stops_descent_m`` with ``close_at_grasp`` (``--close-at-grasp``;
    README, Contact, point 14), ``Task.mpc_z_weight``,
    ``Task.guard_yield_m_s_per_n`` where it is not the default, ``Task.empty_hand_after_s``,
    ``Task.empty_hand_beside_m``, ``Task.landing_speed_m_s``, ``Task.empty_grip_below_m``, ``Task.compliance_caps_pressing``) as ``StackConfig``
    settings; none for a task without them (reach, insert: their stacks as published)."""
    out = {}
    if task.mpc_z_weight != 1.0:
        from controllers.mpc import MPCConfig

        out["mpc"] = MPCConfig(w_pos_z_scale=float(task.mpc_z_weight))
    if task.descent_band_m is not None:
        out["descent_band_m"] = tuple(float(z) for z in task.descent_band_m)
    if task.close_below_m is not None:
        out["close_below_m"] = float(task.close_below_m)
    if close_at_grasp and getattr(task, "close_below_reading_m", None) is not None:
        out["close_below_reading_m"] = float(task.close_below_reading_m)
        if getattr(task, "close_stops_descent_m", None) is not None:
            out["close_stops_descent_m"] = float(task.close_stops_descent_m)
    if task.guard_yield_m_s_per_n != YIELD_M_S_PER_N:
        out["guard_yield_m_s_per_n"] = float(task.guard_yield_m_s_per_n)
    if task.empty_hand_after_s is not None:
        out["empty_hand_after_s"] = float(task.empty_hand_after_s)
    if getattr(task, "empty_hand_beside_m", None) is not None:
        out["empty_hand_beside_m"] = float(task.empty_hand_beside_m)
    if task.landing_speed_m_s is not None:
        out["landing_speed_m_s"] = float(task.landing_speed_m_s)
    if task.empty_grip_below_m is not None:
        out["empty_grip_below_m"] = float(task.empty_grip_below_m)
    if task.compliance_caps_pressing:
        out["compliance_caps_pressing"] = True
    if getattr(task, "capture_tol_m", None) is not None:
        out["capture_tol_m"] = float(task.capture_tol_m)
        out["capture_clear_m"] = float(task.capture_clear_m)
    return out


def task_target_box(task) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """The box a contact task's carrier keeps its object in (``StackConfig.target_box_m``: the fast layer's
    predictions reflect at its walls, as the task's expert's lead does); None for reach (unbounded, as published)."""
    if not task.contact:
        return None
    spec = task.target_spec("linear", 0.1)  # the box is the task's, whatever the motion
    return tuple(float(x) for x in spec.workspace_low_m), tuple(float(x) for x in spec.workspace_high_m)
