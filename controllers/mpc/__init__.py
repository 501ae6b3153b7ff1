"""Task-space MPC between the Ruckig smoother and the 1 kHz inverse-dynamics QP.

At 50-100 Hz the MPC previews the task-space reference (the retargeted chunk, the Kalman
filter's predicted target) over a short horizon (default 10 x 40 ms = 0.4 s), respects the
joint position / velocity / acceleration limits, and hands the QP a joint- and task-space
reference for the next interval (:meth:`MPCPlan.sample`, :meth:`MPCPlan.sample_task`).

Model
-----
Joint-space double integrator with the joint accelerations piecewise constant over each step
of ``dt_s`` (exact discretization, so :meth:`MPCPlan.sample` interpolates exactly):
``dq[k+1] = dq[k] + dt u[k]``, ``q[k+1] = q[k] + dt dq[k] + dt^2/2 u[k]``.
The task is linearized around the current state: ``p[k] = p0 + J_lin (q[k] - q0)`` and the
orientation error (a world-frame rotation vector relative to the current orientation)
``r[k] = J_ang (q[k] - q0)``, with ``J`` the 6x7 TCP Jacobian in LOCAL_WORLD_ALIGNED.
The linearization is refreshed at every solve (real-time-iteration style); only the first
interval of each plan is used before the next solve, where the model is accurate.

Decision variables ``z = [u_0, q_1, dq_1, ..., u_{N-1}, q_N, dq_N]`` (210 for N = 10; the
current state is a parameter), 14 N dynamics equality rows, 7 terminal rows, simple bounds on
every variable.  Cost, per step k = 1..N::

    w_pos |p[k] - pos_ref[k-1]|^2 + w_rot |r[k] - rotvec_ref[k-1]|^2 + w_posture |q[k] - q_nom|^2
    + w_null_posture (q[k] - q_nom)' N (q[k] - q_nom)
    + w_vel |dq[k]|^2 + w_acc |u[k-1]|^2 + w_jerk |u[k-1] - u[k-2]|^2,   plus w_terminal_vel |dq[N]|^2

with ``N`` the (damped) null-space projector of the 6x7 Jacobian at the current state (:func:`null_projector`:
the self-motion is pulled toward the nominal posture, the TCP task is not traded off) and
``u[-1]`` the acceleration the previous plan commands now (smooth hand-over between
plans).  References farther than ``max_ref_dist_m`` / ``max_ref_angle_rad`` from the current
pose are pulled in along their direction (the linear model means nothing farther away, and a
far goal makes the QP badly scaled).

Constraints at every step: ``q`` inside the limits shrunk by ``q_margin_rad`` (and by the at most
``a_max dt^2 / 8`` a constant-acceleration interval can overshoot its knots), ``|dq|`` and
``|u|`` inside ``v_limit_scale`` / ``a_limit_scale`` times the limits, and a terminal
*braking set* ``q_min <= q[N] + dq[N] * v_max / a_max <= q_max`` (per joint).  It is linear and
conservative (stopping distance v^2/(2a) <= v v_max / a, and one braking step keeps a state
inside it): from a terminal state inside it the arm can always stop within the limits after
the horizon, so the shifted problem stays feasible (recursive feasibility, nominal model).

Feasibility guard: if the current state is already outside the margins (model error, a
bump, solver tolerance), the position/velocity bounds of each step are widened per joint just
enough to contain the maximal-braking trajectory from the current state, so the QP stays
feasible and the plan brakes back toward the admissible set instead of failing.

The returned accelerations are clipped to the acceleration box and re-integrated exactly
from the measured state, so a plan is always dynamically consistent and never exceeds the
acceleration limits; positions/velocities can enter the margin band by the solver tolerance
(measured <= 2.2 mrad of the 50 mrad band), never the true limits.

Implementation and measurements
-------------------------------
The QP is built ONCE symbolically with CasADi (SX): one ``casadi.Function`` (after ``cse``)
maps the parameter vector (q0, dq0, u_prev, J, references, q_nom, N) to the nonzeros of
(triu(H), g, A, bounds) with a fixed sparsity; it is evaluated through ``Function.buffer()``
straight into numpy memory (~30 us; going through ``DM`` -> numpy cost ~300-400 us).  ``A``
is constant, only ``H`` (through J), ``g`` and the bounds change.

Whole ``solve()`` call (input checks, QP data, solve, rollout), closed loop on the Panda
(Pinocchio kinematics) tracking a point at 0.2 m/s, 300 calls, ``python -m
controllers.mpc_bench``, on the 2-core development machine while it was shared (load
average 5-6, i.e. about a third of a core for us; an idle machine should be ~2x faster)::

    back-end                                 median us   p99 us   TCP RMS error
    casadi.Opti('conic') re-built per call     ~40 000      -      (FACTS.md)
    osqp_piqp  (default, see below)              1 056     5 603   0.29 mm
    osqp_direct (OSQP 1.x, setup once, update)   1 109     5 690   0.29 mm
    piqp       (casadi.conic, via buffer)        3 238     8 256   0.27 mm
    osqp       (casadi.conic, eps 1e-4)          1 257     6 217   2.05 mm
    qrqp       (casadi.conic)                    3 908    11 175   0.27 mm
    proxqp     (casadi.conic)                    6 518    12 588   0.27 mm
    hpipm      (casadi.conic, OCP form with u_prev in the state, 581 vars, 9 IPM iters)
                                               ~2 200 (solver alone)
    fatrop (conic) asserted inside CasADi, daqp needs a strictly convex H: not usable.

OSQP (ADMM, warm-started, ~15 iterations, one KKT refactorization per call because H
changes with J) is the fastest while few constraints are active, but it stalls (2000
iterations, 30-70 ms) when many velocity / position limits are active at once (unreachable
goals).  PIQP (proximal interior point) is slower but its iteration count hardly depends on
the active set and it never failed.  The default ``osqp_piqp`` runs OSQP with at most 60
iterations and, when it has not converged, re-solves the same data with PIQP: nominal
tracking as above; with many limits active (goal out of reach / below the base) the median
was 1.8-7 ms and p99 10-17 ms under the same load (no failures).  Those saturated cases miss
the 5 ms p99 goal on a loaded machine: keep ``max_solve_ms`` at or below the MPC period, and
the fallback below handles a late solve.

Fallback: on a solver exception, a non-success status, a non-finite solution or a solve
slower than ``max_solve_ms``, :meth:`TaskSpaceMPC.solve` returns the previous plan re-timed
to start now (or, without one still covering ``t_s``, a plan that brakes to rest within the
acceleration limits) with ``ok=False`` and counts it in ``failures`` / ``late``.

This module imports numpy and casadi (and osqp for the direct OSQP backend) only.
"""

from controllers.mpc.config import N_JOINTS, SOLVERS, MPCConfig
from controllers.mpc.double_integrator import braking_accelerations
from controllers.mpc.null_space import null_projector
from controllers.mpc.plan import MPCPlan
from controllers.mpc.task_space_mpc import TaskSpaceMPC

__all__ = ["N_JOINTS", "SOLVERS", "MPCConfig", "MPCPlan", "TaskSpaceMPC", "braking_accelerations", "null_projector"]
