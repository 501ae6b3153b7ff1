"""The tick's work by its place after the 1 Hz query, in real time: medians over every query of a run.

    python docs/realtime/host/query_ticks.py OUT.json [--no-defer] -- [moving_target arguments]
    (default arguments: --realtime --rt-priority 10 --source expert --mode hybrid --episodes 10 --quiet)

Per tick it keeps the whole work, the loop thread's CPU time and the after-command work (``EpisodeLog.rt_exec_us``,
``rt_cpu_us``, ``after_us``) and prints, for the ticks 0-5 after each query (the query at 0, the chunk's arrival
2-3 ms later), their medians. ``--no-defer`` puts back the order before 2026-12-03: the measurements that arrived on
the query's tick fused on that tick, not the next.
"""
import json
import sys
import time

import numpy as np

QUERY_PERIOD_TICKS = 1000  # 1 Hz at 1 kHz


def main() -> None:
    out = sys.argv[1]
    rest = sys.argv[2:]
    no_defer = "--no-defer" in rest
    rest = [a for a in rest if a != "--no-defer"]
    if rest and rest[0] == "--":
        rest = rest[1:]
    argv = rest or ["--realtime", "--rt-priority", "10", "--source", "expert", "--mode", "hybrid", "--episodes", "10",
                    "--quiet"]
    import mmact_ctrl.realtime.session as session
    from mmact_ctrl.runner import EpisodeRunner
    from scenarios import moving_target

    if no_defer:
        after = EpisodeRunner._after_command

        def _after_command(self, t):  # the old order: what arrived is fused on its own tick, query or not
            if self.deadline is None or not self._deferred_measurements:
                return after(self, t)
            a0 = time.perf_counter()
            arrived, self._deferred_measurements = self._deferred_measurements, []
            self._fuse(arrived)
            return (time.perf_counter() - a0) * 1e6 + after(self, t)

        EpisodeRunner._after_command = _after_command
    logs = []
    episode = session.RealtimeSession.episode

    def kept(self, *args, **kwargs):
        log = episode(self, *args, **kwargs)
        logs.append({"exec_us": np.asarray(log.rt_exec_us).tolist(), "cpu_us": np.asarray(log.rt_cpu_us).tolist(),
                     "after_us": np.asarray(log.after_us).tolist()})
        return log

    session.RealtimeSession.episode = kept
    moving_target.main(argv)
    with open(out, "w") as f:
        json.dump(logs, f)
    n = max(len(x["exec_us"]) for x in logs)
    full = [x for x in logs if len(x["exec_us"]) == n]  # an episode the robot aborted is left out
    work, cpu, after = (np.array([x[key] for x in full]) for key in ("exec_us", "cpu_us", "after_us"))
    queries = range(QUERY_PERIOD_TICKS, n - 10, QUERY_PERIOD_TICKS)  # the first (tick 0) starts the episode cold
    print(f"{'defer' if not no_defer else 'no defer'}: medians over {len(queries) * len(full)} queries of "
          f"{len(full)} whole episodes ({len(logs) - len(full)} aborted left out) "
          "(tick after the query: work / CPU / after-command work, us)")
    for off in range(6):
        idx = [q + off for q in queries]
        print(f"  +{off}: {np.median(work[:, idx]):6.0f} / {np.median(cpu[:, idx]):6.0f} / {np.median(after[:, idx]):6.0f}")
    print(f"  all ticks: {np.median(work):6.0f} / {np.median(cpu):6.0f} / {np.median(after):6.0f}")


if __name__ == "__main__":
    main()
