"""Real time: pacing on the wall clock, late commands as missed ones, the MPC beside the loop, a served source,
the Rerun recording, and the viewer's one line. Assertions are on the counts the loop reports, with the stated
tolerances of an idle machine, not on wall-clock thresholds."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.metrics import episode_metrics
from mmact_ctrl.mpc_worker import ProcessMPC
from mmact_ctrl.realtime.pacer import PacerConfig, WallClockPacer, deadline_stats
from mmact_ctrl.realtime.session import RealtimeConfig, RealtimeSession
from scenarios.world.factory import make_expert, make_world

REPO = Path(__file__).resolve().parents[1]
#: a run whose worst window of 100 ticks missed more than twice this share of its commands met a host stall: it is
#: re-run (how many deadlines a host holds is a benchmark's figure, not a test's)
OVERRUN_TOLERANCE = 0.05
#: the loop's thread under SCHED_FIFO where allowed (root here and in CI), so that other processes on the machine
#: do not decide the test
PACED = RealtimeConfig(fifo_priority=10)


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("static", 0.0, n_objects=1)


#: the tries a wall-clock test gets: one episode, and more while the host stalled
TRIES = 3


def _robot_aborted(log) -> bool:
    """The robot aborted the episode on 20 late commands in a row (libfranka's reason)."""
    return log.abort is not None and log.abort.get("reason") == "communication_constraints_violation"


def _ended_as_the_robot_would(log) -> None:
    """What holds on any host: the episode ran to its end, or the robot aborted it on 20 late commands in a row (a
    shared 2-core VM stalls for 20 ms or more now and then, whatever the loop does: CI aborted such episodes three
    times in a row); either way no command broke a limit and none was non-finite. (With the abort switched off, a
    stall of a few hundred ms under the held torque did break limits here: the abort is the robot's protection.)"""
    assert log.abort is None or _robot_aborted(log), log.abort
    assert log.deadline["ticks"] == len(log.t_s)
    assert int(np.count_nonzero(log.safety_mask[: len(log.t_s)])) == 0
    assert np.all(np.isfinite(log.tau_cmd_nm[: len(log.t_s)]))


def _until_the_host_holds(run, tries: int = TRIES):
    """``run()`` (a wall-clock episode; it returns its log, or a tuple whose first item is the log), re-run while the
    episode aborted on 20 late commands in a row or missed more than the tolerance in a window of 100 ticks, at most
    ``tries`` runs in all: on a shared 2-core VM that is a host stall as often as our own work. The last run's counts
    decide the test's assertions."""
    for _ in range(tries):
        out = run()
        log = out[0] if isinstance(out, tuple) else out
        window_min = (log.deadline or {}).get("control_command_success_rate", 1.0)
        if not (_robot_aborted(log) or window_min < 1.0 - 2 * OVERRUN_TOLERANCE):
            break
    return out


def test_a_short_real_time_episode_is_paced_and_counts_every_late_command(world):
    """Pacing and accounting, not speed: how many deadlines a host holds is a benchmark's figure (``python -m
    scenarios.moving_target --realtime`` and ``python -m scenarios.realtime_check`` print them)."""
    def run():
        expert = make_expert(lead="velocity", world=world)
        controller = HybridController(StackConfig(mode="open_loop", duration_s=1.0))
        with RealtimeSession(world, expert, controller, PACED) as session:
            return session.episode(0)

    log = _until_the_host_holds(run)
    _ended_as_the_robot_would(log)
    d = log.deadline
    if log.abort is None:
        assert d["ticks"] == 1000
    assert d["realtime_rate"] <= 1.01, d  # paced: never ahead of the wall clock
    assert np.min(log.rt_jitter_us) >= 0.0  # no tick started before it was due
    # every late command counted as a missed one, and each is a tick the pacer saw end past its deadline
    assert d["overruns"] == log.late_commands == log.missed_ticks == len(log.rt_late_ticks)
    assert 0.0 <= d["control_command_success_rate"] <= 1.0
    assert log.chunk_active_s and sum(log.rejections.values()) == 0
    m = episode_metrics(log)
    assert m["realtime"] and m["limit_violations"] == 0 and m["overruns"] == d["overruns"]


def _stalled_episode(world, monkeypatch, stall_s: float, at_tick: int = 100):
    """A real-time episode (``RealtimeSession.episode`` itself: its priority, pinning and GC settings) whose pacer
    makes tick ``at_tick``'s work ``stall_s`` longer, so that its command is late. Returns (log, that pacer)."""
    made = []

    class StallingPacer(WallClockPacer):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.stall_s = {at_tick: stall_s}
            made.append(self)

    monkeypatch.setattr("mmact_ctrl.realtime.session.WallClockPacer", StallingPacer)
    expert = make_expert(lead="velocity", world=world)
    controller = HybridController(StackConfig(mode="open_loop", duration_s=0.4))
    with RealtimeSession(world, expert, controller, PACED) as session:
        log = session.episode(0)
    return log, made[-1]


def test_an_injected_slow_tick_is_an_overrun_and_a_missed_command(world, monkeypatch):
    log, pacer = _until_the_host_holds(lambda: _stalled_episode(world, monkeypatch, 0.003))
    stats = log.deadline
    _ended_as_the_robot_would(log)
    assert 100 in pacer.late_ticks and stats["overruns"] >= 1 and log.late_commands >= 1
    assert log.missed_ticks >= 1 and len(log.t_s) > 120  # its 3-4 late commands in a row did not abort the episode
    assert stats["cycles_missed"] >= 1  # the ticks after it started a period late
    # the robot re-applied the last torque it received at the late tick
    assert np.array_equal(log.tau_cmd_nm[100], log.tau_cmd_nm[99])
    # the episode's metrics describe each late tick: the stalled one did 3 ms of work after starting on time
    from mmact_ctrl.metrics import _realtime_episode

    late = {t["k"]: t for t in _realtime_episode(log)["late_ticks"]}
    assert set(late) == {int(k) for k in pacer.late_ticks}
    # (how late it started is the host's doing, not the stall's: a shared VM may start it late too; the metrics must
    # report what the pacer measured)
    assert late[100]["work_us"] >= 3000 and late[100]["work_us"] == float(pacer.exec_us[100])
    assert late[100]["start_late_us"] == float(pacer.jitter_us[100])
    assert late[100]["command_path_us"] == float(log.tick_us[100])
    # and the loop thread's CPU time in that work: it spun, so it ran (at most its wall time)
    assert late[100]["cpu_us"] == float(pacer.cpu_us[100])
    assert 0 < late[100]["cpu_us"] <= 1.05 * late[100]["work_us"] + 50


def test_twenty_late_commands_in_a_row_abort_as_on_the_robot(world, monkeypatch):
    log, _ = _stalled_episode(world, monkeypatch, 0.025)
    assert _robot_aborted(log) and log.late_commands >= 20
    _ended_as_the_robot_would(log)  # the log ends at the abort, and every command until it was within the limits
    assert len(log.t_s) < 400


def test_the_mpc_process_handing_late_plans_is_survived(world):
    def run():
        expert = make_expert(lead="velocity", world=world)
        controller = HybridController(StackConfig(mode="hybrid", duration_s=1.0))
        with RealtimeSession(world, expert, controller, PACED) as session:
            worker = controller.mpc_worker
            assert isinstance(worker, ProcessMPC)
            worker.max_solve_s = 1e-6  # every plan comes back too late
            return session.episode(1), worker

    log, worker = _until_the_host_holds(run)
    _ended_as_the_robot_would(log)
    m = episode_metrics(log)
    # the MPC is asked at 50 Hz, one problem in flight: every plan that came back was late, and counted
    ticks = len(log.t_s)
    assert ticks >= 100 and worker.late >= ticks // 40 and m["mpc_failures"] >= ticks // 40
    assert log.mpc_bypass_ticks > 0  # no good plan: the QP tracked the smoothed reference
    assert m["limit_violations"] == 0


def test_a_real_time_episode_with_a_served_source_runs_end_to_end():
    from mmact_ctrl.sources.remote import RemoteSource
    from scenarios.served import ServedSource, serve_argv
    from scenarios.sources import SourceSettings

    def run():
        w = make_world("linear", 0.2, n_objects=2)
        with ServedSource(serve_argv(SourceSettings(spec="expert"))) as served:
            source = RemoteSource(served.url)
            controller = HybridController(StackConfig(mode="hybrid", duration_s=2.0, mpc_phase_s=0.005))
            try:
                with RealtimeSession(w, source, controller, PACED) as session:
                    return session.episode(2, record=True)
            finally:
                source.close()
                w.close()

    log = _until_the_host_holds(run)
    _ended_as_the_robot_would(log)
    m = episode_metrics(log)
    assert len(log.chunk_active_s) >= (2 if log.abort is None else 1) and sum(log.rejections.values()) == 0
    assert log.abort is not None or log.deadline["ticks"] == 2000
    assert m["limit_violations"] == 0
    assert all(x > 0 for x in log.plan_ms) and all(d >= 0 for d in log.delay_steps)  # latency as it ran
    assert m["source_timing_ms"]["server_infer_ms"]


def test_the_recording_round_trips(tmp_path):
    pytest.importorskip("rerun") if os.environ.get("MMACT_REQUIRE_EXTRAS") != "1" else None
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.recording import METRICS, WORLD, entity_paths, write_recording

    w = make_world("linear", 0.2, n_objects=2, cameras=("front",))
    try:
        class Seeing:
            needs_image = True

            def __init__(self):
                self.e = make_expert(lead="velocity", world=w)

            def plan(self, obs):
                assert obs.image is not None
                return self.e.plan(obs)

        log = run_episode(w, Seeing(), HybridController(StackConfig(mode="hybrid", duration_s=1.5)), 0, record=True)
    finally:
        w.close()
    path = write_recording({"hybrid": log}, tmp_path / "run.rrd", camera_names=("front",))
    paths = entity_paths(path)
    for entity in (*WORLD, *METRICS, "camera/front"):
        assert f"hybrid/{entity}" in paths, (entity, sorted(paths))


def test_the_viewer_without_a_display_is_one_line():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run([sys.executable, "-m", "scenarios.moving_target", "--viewer", "--source", "expert",
                           "--episodes", "1", "--quiet"], capture_output=True, text=True, cwd=REPO, env=env, timeout=120)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--viewer needs a display" in lines[0] and "Traceback" not in proc.stderr


def test_the_pacer_keeps_the_threads_cpu_time_beside_the_wall_time():
    """A tick that waited (preempted, or another thread held the GIL) has less CPU time than work: exact with fake
    clocks (each read of the wall clock moves it 1 ns, so that the pacer's spin ends)."""
    wall, cpu = [0.0], [0.0]

    def clock():
        wall[0] += 1e-9
        return wall[0]

    def sleep(s):
        wall[0] += s

    class Runner:
        n_ticks, k, done = 3, 0, False

        def advance(self, t_s):
            wall[0] += 0.0004
            cpu[0] += 0.0001 if self.k == 1 else 0.0004  # tick 1 waited 300 us of its 400
            self.k += 1
            self.done = self.k >= self.n_ticks

    pacer = WallClockPacer(0.001, PacerConfig(spin_s=0.0, start_delay_s=0.0), clock=clock, sleep=sleep,
                           cpu_clock=lambda: cpu[0])
    pacer.run(Runner())
    assert np.allclose(pacer.exec_us, 400, atol=0.1)
    assert np.allclose(pacer.cpu_us, [400, 100, 400])


def test_deadline_statistics_from_known_ticks():
    start = np.array([0.0, 0.0002, 0.0011, 0.0, 0.0])  # the third tick started more than a period late
    end = np.array([0.0003, 0.0005, 0.0025, 0.0004, 0.0003])
    s = deadline_stats(start, end, 0.001, np.array([2]), window_ticks=2, wall_s=0.005)
    assert s["overruns"] == 1 and s["cycles_missed"] == 1 and s["overrun_rate"] == pytest.approx(0.2)
    assert s["control_command_success_rate"] == pytest.approx(0.5)  # the window holding the late one
    assert s["exec_us"]["max"] == pytest.approx(1400.0) and s["realtime_rate"] == pytest.approx(1.0)
