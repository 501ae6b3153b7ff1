"""Can this host hold a 1 kHz loop? The real-time loop's pacing and statistics with a fixed CPU work per tick and
nothing of ours in it (no physics, no solver, no other thread or process): what is late here is the host's.

    python -m mmact_ctrl.realtime.host_check                       # 10 x 6 s at 1 kHz, 330 us of work a tick
    python -m mmact_ctrl.realtime.host_check --work-us 150 --episodes 3 --json host.json

Each tick runs a fixed amount of pure-Python arithmetic, calibrated before the run to take ``--work-us`` (default:
the median whole work of a hybrid real-time tick on our 2-core test machine), on the loop's CPU under the same
settings as ``--realtime`` (SCHED_FIFO when allowed, a CPU of its own, no cyclic GC), paced by the same
:class:`~mmact_ctrl.realtime.pacer.WallClockPacer` and summarized by the same :func:`deadline_stats`. A fixed
computation that takes 2-3x its median now and then, with the thread's CPU time equal to its wall time, means that
the CPU itself ran slowly (a contended host core); CPU time well under the wall time means the thread was not
running (preempted). Compare its ``control_command_success_rate`` with that of ``moving_target --realtime``: where
the empty loop misses too, the host, not the stack, sets the figure.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass

import numpy as np

from mmact_ctrl.config import StackConfig
from mmact_ctrl.realtime.loop_thread import cpu_split, loop_thread
from mmact_ctrl.realtime.pacer import PacerConfig, WallClockPacer

PROG = "python -m mmact_ctrl.realtime.host_check"

#: the robot aborts after this many late commands in a row (libfranka), as the episode runner does
ABORT_AFTER = StackConfig().abort_after_missed_ticks


@dataclass(frozen=True)
class HostCheckConfig:
    """Attributes:
    work_us: CPU work per tick, us (a fixed computation calibrated to take this long).
    episodes: how many episodes.
    duration_s: each episode's length, s.
    dt_s: the control period, s.
    fifo_priority: SCHED_FIFO priority of the loop's thread (0: normal scheduling).
    loop_cpu: the loop's CPU (None: not pinned).
    slow_factor: a tick whose work took more than this times the median is "slow" in the summary.
    """

    work_us: float = 330.0
    episodes: int = 10
    duration_s: float = 6.0
    dt_s: float = 0.001
    fifo_priority: int = 10
    loop_cpu: int | None = 0
    slow_factor: float = 2.0

    def __post_init__(self) -> None:
        if not 0 < self.work_us <= 1e5:
            raise ValueError(f"work_us must be in (0, 100000] us, got {self.work_us!r}")
        if int(self.episodes) != self.episodes or self.episodes < 1:
            raise ValueError(f"episodes must be an integer >= 1, got {self.episodes!r}")
        if not 0 < self.duration_s <= 600:
            raise ValueError(f"duration_s must be in (0, 600] s, got {self.duration_s!r}")
        if not 0 < self.dt_s <= 0.1:
            raise ValueError(f"dt_s must be in (0, 0.1] s, got {self.dt_s!r}")
        if not 0 <= self.fifo_priority <= 99:
            raise ValueError(f"fifo_priority must be in [0, 99], got {self.fifo_priority!r}")
        if not self.slow_factor > 1:
            raise ValueError(f"slow_factor must be > 1, got {self.slow_factor!r}")


def _spin(n: int) -> int:
    """A fixed computation: ``n`` iterations of integer arithmetic in the interpreter (as our tick is Python-bound)."""
    s = 0
    for i in range(n):
        s += i * i
    return s


def calibrate(work_us: float, trials: int = 200) -> int:
    """The iterations of :func:`_spin` whose median time is ``work_us`` on this thread now."""
    probe = 2000
    samples = np.empty(trials)
    _spin(probe)
    for i in range(trials):
        t0 = time.perf_counter()
        _spin(probe)
        samples[i] = time.perf_counter() - t0
    per_iter_s = float(np.median(samples)) / probe
    return max(1, int(round(work_us * 1e-6 / per_iter_s)))


class SpinRunner:
    """A runner for :class:`WallClockPacer` whose every tick is ``iterations`` of :func:`_spin`; it counts, as the
    episode runner does, the late commands the pacer reports and the aborts (``ABORT_AFTER`` in a row) that a robot
    would have made, but runs to the end so that the whole host is measured."""

    def __init__(self, iterations: int, n_ticks: int, dt_s: float, deadline: WallClockPacer) -> None:
        self.iterations, self.n_ticks, self.dt_s, self.deadline = iterations, n_ticks, dt_s, deadline
        self.k = 0
        self.in_row = 0
        self.would_abort = 0

    @property
    def done(self) -> bool:
        return self.k >= self.n_ticks

    def advance(self, t_s: float) -> None:
        while self.k * self.dt_s < t_s - 1e-9 and not self.done:
            _spin(self.iterations)
            if self.deadline.missed(self.k):
                self.in_row += 1
                if self.in_row == ABORT_AFTER:
                    self.would_abort += 1
            else:
                self.in_row = 0
            self.k += 1


def run(config: HostCheckConfig, progress=None) -> dict:
    """The host check; returns its summary and per-episode statistics (see the module docstring)."""
    loop_cpus, _ = cpu_split(config.loop_cpu)
    n_ticks = max(1, int(round(config.duration_s / config.dt_s)))
    episodes, works, cpus = [], [], []
    with loop_thread(config.fifo_priority, loop_cpus) as thread:
        iterations = calibrate(config.work_us)
        for e in range(int(config.episodes)):
            pacer = WallClockPacer(config.dt_s, PacerConfig())
            runner = SpinRunner(iterations, n_ticks, config.dt_s, pacer)
            stats = pacer.run(runner)
            stats["would_abort"] = runner.would_abort
            episodes.append(stats)
            works.append(pacer.exec_us)
            cpus.append(pacer.cpu_us)
            if progress is not None:
                progress(e + 1)
    work, cpu = np.concatenate(works), np.concatenate(cpus)
    med = float(np.median(work))
    slow = work > config.slow_factor * med
    rates = np.array([e["control_command_success_rate"] for e in episodes])
    ticks = int(sum(e["ticks"] for e in episodes))
    overruns = int(sum(e["overruns"] for e in episodes))
    summary = {
        "ticks": ticks,
        "iterations_per_tick": iterations,
        "work_us": {"median": med, "p99": float(np.percentile(work, 99)), "p999": float(np.percentile(work, 99.9)),
                    "max": float(np.max(work))},
        "slow_ticks": int(np.count_nonzero(slow)),
        "slow_tick_rate": float(np.mean(slow)),
        "slow_cpu_over_wall": float(np.median(cpu[slow] / work[slow])) if slow.any() else None,
        "overruns": overruns,
        "overrun_rate": float(overruns / ticks),
        "cycles_missed": int(sum(e["cycles_missed"] for e in episodes)),
        "would_abort": int(sum(e["would_abort"] for e in episodes)),
        "control_command_success_rate_min": float(rates.min()),
        "episodes_at_or_above_0_99": int(np.count_nonzero(rates >= 0.99)),
        "priority_refused": thread.priority_refused,
        "loop_cpu": sorted(loop_cpus),
    }
    return {"config": asdict(config), "summary": summary, "episodes": episodes}


def format_summary(result: dict) -> str:
    c, s = result["config"], result["summary"]
    ratio = s["slow_cpu_over_wall"]
    cause = ("" if ratio is None else
             " (the CPU ran slowly: a contended host)" if ratio > 0.9 else " (the thread was not running: preempted)")
    lines = [
        f"host check: {c['episodes']} x {c['duration_s']:g} s at {1 / c['dt_s']:g} Hz, {c['work_us']:g} us of fixed "
        f"CPU work a tick, nothing else in the loop",
        f"  tick work median / p99 / p99.9 / max [us]   {s['work_us']['median']:.0f} / {s['work_us']['p99']:.0f} / "
        f"{s['work_us']['p999']:.0f} / {s['work_us']['max']:.0f}",
        f"  ticks over {c['slow_factor']:g}x the median                  {s['slow_ticks']} "
        f"({100 * s['slow_tick_rate']:.2f} %)"
        + (f", CPU time / wall time {ratio:.2f}{cause}" if ratio is not None else ""),
        f"  overruns                                    {s['overruns']} ({100 * s['overrun_rate']:.3f} %), cycles "
        f"missed {s['cycles_missed']}",
        f"  command success rate (min)                  {s['control_command_success_rate_min']:.3f}; >= 0.99 in "
        f"{s['episodes_at_or_above_0_99']} of {c['episodes']} episodes",
        f"  aborts a robot would have made              {s['would_abort']}",
    ]
    if s["priority_refused"]:
        lines.append(f"  note: {s['priority_refused']}; the loop ran at normal priority")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = HostCheckConfig()
    p.add_argument("--work-us", type=float, default=d.work_us, help=f"CPU work per tick, us (default {d.work_us:g})")
    p.add_argument("--episodes", type=int, default=d.episodes, help=f"episodes (default {d.episodes})")
    p.add_argument("--duration-s", type=float, default=d.duration_s,
                   help=f"episode length, s (default {d.duration_s:g})")
    p.add_argument("--rt-priority", type=int, default=d.fifo_priority,
                   help=f"SCHED_FIFO priority of the loop's thread, 0: normal scheduling (default {d.fifo_priority})")
    p.add_argument("--json", metavar="PATH", help="write the summary and per-episode statistics here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        config = HostCheckConfig(work_us=args.work_us, episodes=args.episodes, duration_s=args.duration_s,
                                 fifo_priority=args.rt_priority)
    except ValueError as exc:  # named as the user typed it
        message = str(exc)
        for field, flag in (("work_us", "--work-us"), ("episodes", "--episodes"), ("duration_s", "--duration-s"),
                            ("fifo_priority", "--rt-priority")):
            message = message.replace(field, flag)
        parser.error(message)
    from tqdm import tqdm

    with tqdm(total=config.episodes, desc="host check", unit="ep", disable=args.quiet, file=sys.stderr) as bar:
        result = run(config, progress=lambda i: bar.update(1))
    print(format_summary(result))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
