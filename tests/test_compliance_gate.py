"""``--compliance`` as a layer where contact needs it (``mmact_ctrl.control.compliance_gate``): the gate's timing, the
QP's two task sets against the QPs they stand for, and a pick in open loop whose hand, under an impedance that was
on in free space too, fell under its reference onto the belt and drove the arm past its joint limits."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controllers.qp import TaskReference, TaskSpaceQP
from controllers.qp.config import QPConfig
from controllers.qp.impedance import ImpedanceTask
from controllers.qp.tasks import TcpPositionTask
from controllers.robot_model import PandaModel
from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.compliance_gate import HOLD_S, ComplianceGate
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.factory import make_expert, make_world
from scenarios.world.tasks.registry import task_stack_settings

DT_S = 0.001
#: how far under its reference the TCP may be in the pick below (stiff tracking gives 31 mm at the chunk's turn; the
#: impedance in free space gave 86 mm, the hand on the belt)
SAG_MAX_M = 0.05


def test_the_gate_is_in_contact_from_the_first_tick_over_the_threshold_until_the_hold_has_passed():
    gate = ComplianceGate(3.0, DT_S)
    assert not gate.update(0.0) and not gate.update(3.0)  # free at the start; the threshold itself is not contact
    assert gate.update(3.1)
    hold = round(HOLD_S / DT_S)
    assert all(gate.update(0.5) for _ in range(hold))  # held through a force that falls away
    assert not gate.update(0.5) and gate.switches == 2
    for k in range(200):  # a contact that chatters at its threshold does not switch the QP's tasks tick by tick
        gate.update(5.0 if k % 2 else 1.0)
    assert gate.in_contact and gate.switches == 3
    gate.reset()
    assert not gate.in_contact and gate.switches == 0 and not gate.update(2.0)
    with pytest.raises(ValueError, match="threshold_n"):
        ComplianceGate(0.0, DT_S)


def _states(model: PandaModel, n: int, seed: int):
    rng = np.random.default_rng(seed)
    home = model.home_q_rad
    for _ in range(n):
        q = home + rng.normal(0.0, 0.2, 7)
        dq = rng.normal(0.0, 0.3, 7)
        terms = model.terms(q, dq)
        ref = TaskReference(terms.pos_m + rng.normal(0.0, 0.05, 3), rng.normal(0.0, 0.2, 3), rng.normal(0.0, 2.0, 3),
                            terms.rot, np.zeros(3), np.zeros(3), home)
        yield q, dq, terms, ref


def _torques(qp: TaskSpaceQP, model: PandaModel, seed: int, contact: bool | None = None) -> np.ndarray:
    qp.reset(model.terms(model.home_q_rad, np.zeros(7)).h)
    if contact is not None:
        qp.set_contact(contact)
    return np.array([qp.solve(terms, q, dq, ref).copy() for q, dq, terms, ref in _states(model, 40, seed)])


def test_the_gated_qp_is_the_stiff_qp_in_free_space_and_the_compliant_qp_in_contact_bit_for_bit():
    model = PandaModel()
    cfg = QPConfig(dt_s=DT_S)
    imp = ImpedanceTask(force_max_n=20.0)
    gated = TaskSpaceQP(cfg, contact_task=imp)
    assert gated.fast_path and not gated.in_contact and gated.impedance is None
    stiff = _torques(TaskSpaceQP(cfg), model, 3)
    always = TaskSpaceQP(replace(cfg, tcp=replace(cfg.tcp, w_pos=0.0)), extra_tasks=(imp,))
    compliant = _torques(always, model, 3)
    assert np.abs(stiff - compliant).max() > 0.1  # the two task sets ask for different torques on these states
    assert np.array_equal(_torques(gated, model, 3, contact=False), stiff)
    assert np.array_equal(_torques(gated, model, 3, contact=True), compliant)
    assert gated.in_contact and gated.impedance is imp and gated.tasks[-1] is imp
    assert type(gated.tasks[0]) is TcpPositionTask and gated.tasks[0].weight == 0.0
    gated.reset(np.zeros(7))  # an episode starts in free space
    assert not gated.in_contact and gated.tasks[0].weight == cfg.tcp.w_pos and imp not in gated.tasks
    with pytest.raises(ValueError, match="contact_task"):
        TaskSpaceQP(replace(cfg, tcp=replace(cfg.tcp, w_pos=0.0)), extra_tasks=(imp,), contact_task=imp)


def test_a_compliant_open_loop_pick_tracks_its_reference_in_free_space_and_keeps_the_joint_limits():
    # seed 1045, linear 0.2 m/s, open loop, --compliance (published seeds): with the impedance on in free space too,
    # the open hand fell 8 cm under its reference onto the belt at the chunk's turn, was dragged by it, and the arm
    # went past its joint position (1,023 ticks) and velocity (116) limits, with 171 N on the belt
    world = make_world("linear", 0.2, n_objects=2, task="pick")
    expert = make_expert(lead="velocity", world=world)
    cfg = StackConfig(mode="open_loop", duration_s=6.0, **task_stack_settings("pick", compliance=True))
    controller = HybridController(cfg)
    log = run_episode(world, expert, controller, seed=1045)
    world.close()
    m = episode_metrics(log)
    assert m["position_violations"] == 0 and m["velocity_violations"] == 0, m
    sag_m = float(np.max(log.ref_pos_m[:, 2] - log.ee_pos_m[:, 2]))
    assert sag_m < SAG_MAX_M, sag_m
    assert m["contact_force_violations"] == 0 and m["success"], m


def test_a_compliant_insert_hands_the_push_to_the_impedance_and_seats_within_the_limit():
    world = make_world("static", 0.0, noise_m=0.002, task="insert", clearance_mm=1.0)
    source = make_expert(lead="velocity", world=world)
    controller = HybridController(StackConfig(mode="hybrid", duration_s=6.0, **task_stack_settings("insert", True)))
    log = run_episode(world, source, controller, seed=1)
    world.close()
    m = episode_metrics(log)
    assert m["success"] and m["limit_violations"] == 0 and m["peak_contact_force_n"] < 30.0, m
    assert controller.compliance.switches >= 1  # the chamfer's contact put the impedance in the position task's place


def test_a_pressing_only_impedance_takes_the_measured_normal_and_without_one_is_the_magnitude_capped_qp():
    model = PandaModel()
    cfg = QPConfig(dt_s=DT_S)
    plain = TaskSpaceQP(cfg, contact_task=ImpedanceTask(force_max_n=20.0))
    pressing = TaskSpaceQP(cfg, contact_task=ImpedanceTask(force_max_n=20.0, pressing_only=True))
    # no normal measured: the same QP as the magnitude-capped one, bit for bit
    assert np.array_equal(_torques(pressing, model, 5, contact=True), _torques(plain, model, 5, contact=True))
    n = np.array([0.0, 0.6, 0.8])
    pressing.set_contact(True, n)
    q, dq, terms, ref = next(_states(model, 1, 9))
    assert np.array_equal(pressing.state(terms, q, dq, ref).contact_normal, n)
    plain.set_contact(True, n)  # a magnitude-capped impedance ignores the normal
    assert plain.state(terms, q, dq, ref).contact_normal is None
    pressing.set_contact(True, None)  # the force fell to zero: no normal
    assert pressing.state(terms, q, dq, ref).contact_normal is None
    pressing.set_contact(True, n)
    pressing.reset(terms.h)  # a new episode forgets it
    assert pressing.state(terms, q, dq, ref).contact_normal is None and not pressing.in_contact


def test_pick_caps_only_the_push_into_the_contact_and_insert_the_magnitude():
    assert task_stack_settings("pick", compliance=True)["compliance_caps_pressing"]
    assert "compliance_caps_pressing" not in task_stack_settings("insert", compliance=True)
    assert not StackConfig().compliance_caps_pressing


def test_a_compliant_hand_that_hit_the_belt_lifts_itself_out(monkeypatch):
    """Pick at 0.4 m/s, hybrid, ``--compliance``, seed 1041 (a published seed, read after its run found the fault):
    the open hand, sweeping sideways at 0.6 m/s near the robot's base, went under its reference into the belt
    (250 N). With the impedance's force capped in magnitude it could not lift itself out against the belt dragging
    its fingers (20 N up): 620 ticks over 30 N and 199 past the joint position limits. Capped only on the push into
    the contact, the hand lifts off. The fall no longer happens on this seed (stop 53: the MPC's preview bound, the
    held cube kept in hand by the expert and the latch; stop 54: the latch waiting for the grip), so the episode is
    replayed as the run that found it had it: the preview unbounded (``mpc_preview_governed``), the latch from the
    closing command (``latch_on_grip`` False), the latch and the expert taking a held cube off the TCP's centre for a
    miss (``empty_grip_below_m`` None, ``pick_expert.HELD_XY_M`` 0)."""
    from pick_episode import run_pick_episode
    import scenarios.world.tasks.pick_expert as pick_expert

    monkeypatch.setattr(pick_expert, "HELD_XY_M", 0.0)
    then = dict(compliance=True, mpc_preview_governed=False, latch_on_grip=False, empty_grip_below_m=None)
    log, ctl, cfg = run_pick_episode("linear", "0.4", 1041, "6", **then)
    assert cfg.compliance_caps_pressing and ctl.compliance.switches >= 1
    m = episode_metrics(log)
    assert m["limit_violations"] == 0, m
    log, _, _ = run_pick_episode("linear", "0.4", 1041, "6", compliance_caps_pressing=False, **then)
    m = episode_metrics(log)
    assert m["position_violations"] > 0 and m["contact_force_violations"] > 100, m
