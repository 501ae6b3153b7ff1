"""The QP as tasks and limits: the compiled fast path equals the general problem of the default set, a new task is one
small class that moves the solution as its cost says, a new limit holds, the ladder relaxes the highest priority
first and never priority 0, and bad gains are refused at construction."""

from dataclasses import dataclass

import numpy as np
import pytest

from controllers.qp import (Constraint, Objective, QPConfig, QPState, TaskReference, TaskSpaceQP, TcpPositionTask,
                            build_problem, solve, solve_problem)
from controllers.qp.solve import relaxation_levels
from controllers.robot_model import PandaModel


@pytest.fixture(scope="module")
def model():
    return PandaModel()


def _instance(model, rng):
    q = model.home_q_rad + rng.normal(0, 0.2, 7)
    dq = rng.normal(0, 0.3, 7)
    terms = model.terms(q, dq)
    ref = TaskReference(terms.pos_m + rng.normal(0, 0.02, 3), rng.normal(0, 0.1, 3), rng.normal(0, 0.5, 3), terms.rot,
                        np.zeros(3), np.zeros(3), model.home_q_rad)
    return q, dq, terms, ref


def test_the_fast_path_equals_the_general_problem_of_the_default_set(model):
    rng = np.random.default_rng(0)
    fast, general = TaskSpaceQP(QPConfig()), TaskSpaceQP(QPConfig())
    for _ in range(30):
        q, dq, terms, ref = _instance(model, rng)
        for qp in (fast, general):
            qp.reset(terms.h)
        tau_fast = fast.solve(terms, q, dq, ref)
        state = general.state(terms, q, dq, ref)
        ddq = solve(general.tasks, general.limits, state, eps=1e-9, max_iter=20000)
        assert ddq is not None and fast.last_ok
        np.testing.assert_allclose(terms.M @ ddq + terms.h, tau_fast, atol=0.05)  # N*m: OSQP's tolerance


@dataclass(frozen=True)
class JointAccelTask:
    """A new task in a few lines: pull joint ``i``'s acceleration toward ``target_rad_s2`` with ``weight``."""

    i: int
    target_rad_s2: float
    weight: float

    def cost(self, state: QPState) -> Objective:
        H, c = np.zeros((7, 7)), np.zeros(7)
        H[self.i, self.i], c[self.i] = self.weight, -self.weight * self.target_rad_s2
        return Objective(H, c)


def test_a_new_task_moves_the_solution_as_its_cost_says(model):
    q, dq, terms, ref = _instance(model, np.random.default_rng(1))
    plain = TaskSpaceQP()
    plain.reset(terms.h)
    plain.solve(terms, q, dq, ref)
    base = plain.last_ddq[6]
    for weight in (1e-2, 1.0):
        qp = TaskSpaceQP(extra_tasks=(JointAccelTask(6, base + 2.0, weight),))
        qp.reset(terms.h)
        qp.solve(terms, q, dq, ref)
        assert qp.last_ok and not qp.fast_path
        moved = qp.last_ddq[6] - base
        assert 0.0 < moved <= 2.0 + 1e-6  # toward the target, never past it
        if weight == 1.0:
            assert moved > 1.0  # a heavier cost pulls harder


@dataclass(frozen=True)
class JointAccelCap:
    """A new limit: ``|ddq_i| <= cap`` at priority 1."""

    i: int
    cap_rad_s2: float
    priority: int = 1

    def rows(self, state: QPState) -> Constraint:
        A = np.zeros((1, 7))
        A[0, self.i] = 1.0
        return Constraint(A, np.array([-self.cap_rad_s2]), np.array([self.cap_rad_s2]), self.priority)


def test_a_new_limit_holds(model):
    q, dq, terms, ref = _instance(model, np.random.default_rng(2))
    ref = TaskReference(ref.pos_m + np.array([0.05, 0, 0]), *list(ref.__dict__.values())[1:])
    free = TaskSpaceQP()
    free.reset(terms.h)
    free.solve(terms, q, dq, ref)
    cap = 0.2 * abs(free.last_ddq[0])
    capped = TaskSpaceQP(extra_limits=(JointAccelCap(0, cap),))
    capped.reset(terms.h)
    capped.solve(terms, q, dq, ref)
    assert capped.last_ok and abs(capped.last_ddq[0]) <= cap + 1e-4 < abs(free.last_ddq[0])


def test_the_ladder_relaxes_the_highest_priority_first_and_never_priority_0(model):
    q, dq, terms, ref = _instance(model, np.random.default_rng(3))
    qp = TaskSpaceQP()
    qp.reset(terms.h)
    state = qp.state(terms, q, dq, ref)
    # two contradictory limits on joint 0 (priority 2 says >= 0.01, priority 1 says <= -0.01): the level that relaxes
    # priority 2 solves it, so the priority-1 row holds
    hi = Constraint(np.eye(7)[:1], np.array([0.01]), np.array([np.inf]), 2)
    lo = Constraint(np.eye(7)[:1], np.array([-np.inf]), np.array([-0.01]), 1)
    problem = build_problem(qp.tasks, qp.limits + (_Fixed(hi), _Fixed(lo)), state)
    assert list(relaxation_levels(problem.priority)) == [None, 2, 1]
    ddq = solve_problem(problem)
    assert ddq is not None and ddq[0] <= -0.01 + 1e-6
    tau = terms.M @ ddq + terms.h  # the torque rows (priority 0) held
    assert np.all(np.abs(tau - qp.tau_last) <= qp.dtau_step_nm + 1e-6)


@dataclass(frozen=True)
class _Fixed:
    row: Constraint

    @property
    def priority(self) -> int:
        return self.row.priority

    def rows(self, state: QPState) -> Constraint:
        return self.row


def test_bad_gains_are_refused_at_construction():
    with pytest.raises(ValueError, match="TcpPositionTask.kp"):
        TcpPositionTask(kp=-1.0)
    with pytest.raises(ValueError, match="tcp_vel_cap_m_s"):
        TcpPositionTask(tcp_vel_cap_m_s=0.0)


def test_the_warm_general_solver_agrees_with_the_cold_one_and_takes_the_ladder(model):
    from controllers.qp.warm import WarmProblemSolver

    rng = np.random.default_rng(4)
    qp = TaskSpaceQP(extra_tasks=(JointAccelTask(0, 1.0, 1e-3),))  # the general path
    warm = WarmProblemSolver(eps=1e-9, max_iter=20000)
    for _ in range(20):  # a run of ticks on one shape: the warm start carries over
        q, dq, terms, ref = _instance(model, rng)
        qp.reset(terms.h)
        problem = build_problem(qp.tasks, qp.limits, qp.state(terms, q, dq, ref))
        x_warm, x_cold = warm.solve(problem), solve_problem(problem, eps=1e-9, max_iter=20000)
        assert x_warm is not None and x_cold is not None
        np.testing.assert_allclose(terms.M @ x_warm, terms.M @ x_cold, atol=1e-3)  # N*m
        assert np.all(problem.A @ x_warm >= problem.lower - 1e-6) and np.all(problem.A @ x_warm <= problem.upper + 1e-6)
    # another shape (one more row) is set up anew; contradictory rows go down DAQP's ladder as the cold path does
    hi = Constraint(np.eye(7)[:1], np.array([0.01]), np.array([np.inf]), 2)
    lo = Constraint(np.eye(7)[:1], np.array([-np.inf]), np.array([-0.01]), 1)
    problem = build_problem(qp.tasks, qp.limits + (_Fixed(hi), _Fixed(lo)), qp.state(terms, q, dq, ref))
    x = warm.solve(problem)
    assert x is not None and x[0] <= -0.01 + 1e-6


def test_the_impedance_force_is_capped_with_the_references_acceleration_in_it(model):
    from controllers.qp.impedance import ImpedanceTask

    q, dq, terms, ref = _instance(model, np.random.default_rng(5))
    task = ImpedanceTask(force_max_n=20.0)
    jp = terms.J[:3]
    lam = np.linalg.inv(jp @ np.linalg.solve(terms.M, jp.T))
    # small: a_des = a_ref + Lambda^-1 f exactly (the cap does not bind)
    at = TaskReference(terms.pos_m + np.array([0.0, 0.0, -0.002]), terms.vel[:3].copy(), np.array([0.0, 0.0, -0.5]),
                       terms.rot, np.zeros(3), np.zeros(3), model.home_q_rad)
    state = QPState(terms, q, dq, at, terms.h, np.zeros(7))
    f_sd = task.spring_damper_n(state)
    assert np.linalg.norm(lam @ at.acc_m_s2 + f_sd) < 20.0
    np.testing.assert_allclose(task.desired_acc(state), at.acc_m_s2 + np.linalg.solve(lam, f_sd), atol=1e-9)
    # a reference accelerating down at 20 m/s^2 with the TCP on it: the feed-forward alone is over the cap, and the
    # force asked of the TCP is the cap, along the feed-forward (a held peg is not pushed with Lambda a_ref)
    fast = TaskReference(terms.pos_m.copy(), terms.vel[:3].copy(), np.array([0.0, 0.0, -20.0]), terms.rot,
                         np.zeros(3), np.zeros(3), model.home_q_rad)
    state = QPState(terms, q, dq, fast, terms.h, np.zeros(7))
    f = task.force_n(state)
    ff = lam @ fast.acc_m_s2
    assert np.linalg.norm(ff) > 20.0
    assert np.linalg.norm(f) == pytest.approx(20.0)
    np.testing.assert_allclose(f / 20.0, ff / np.linalg.norm(ff), atol=1e-9)
    np.testing.assert_allclose(task.desired_acc(state), np.linalg.solve(lam, f), atol=1e-9)
