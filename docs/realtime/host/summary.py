"""Side by side: the empty 1 kHz loop (host_check) and the stack (hybrid, served expert), per run of 10 x 6 s.

    python docs/realtime/host/summary.py [DIR]   (after docs/realtime/host/run.sh)
"""
import glob
import json
import sys
from pathlib import Path

import numpy as np

d = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/realtime/host")
print("work: the median of the episodes' medians and the largest episode p99 for the stack; pooled for the empty loop")
print("at query: the stack's late commands on the first 15 ticks of each second (the 1 Hz query, the chunk's arrival "
      "2-3 ms later and its admission)")
print(f"{'run':<16} {'work median/p99 [us]':>22} {'overruns':>9} {'cyc.missed':>10} {'rate min':>9} "
      f"{'eps >= 0.99':>11} {'aborts':>7} {'at query':>9}")
for f in sorted(glob.glob(str(d / "*.json"))):
    data = json.loads(Path(f).read_text())
    name = Path(f).stem
    if "summary" in data and "iterations_per_tick" in data["summary"]:  # the host check
        s = data["summary"]
        rates = [e["control_command_success_rate"] for e in data["episodes"]]
        row = (f"{s['work_us']['median']:.0f} / {s['work_us']['p99']:.0f}", s["overruns"], s["cycles_missed"],
               min(rates), sum(r >= 0.99 for r in rates), len(rates), s["would_abort"], "-")
    else:  # moving_target --realtime
        eps = data["episodes"]
        rates = [e["control_command_success_rate"] for e in eps]
        # (the per-tick work is pooled in the run's summary; each episode keeps its median and p99)
        row = (f"{np.median([e['exec_us_median'] for e in eps]):.0f} / {max(e['exec_us_p99'] for e in eps):.0f}",
               sum(e["overruns"] for e in eps), sum(e["cycles_missed"] for e in eps), min(rates),
               sum(r >= 0.99 for r in rates), len(rates), sum(e["aborts"] for e in eps),
               sum(t["k"] % 1000 < 15 for e in eps for t in e.get("late_ticks", [])))
    print(f"{name:<16} {row[0]:>22} {row[1]:>9} {row[2]:>10} {row[3]:>9.3f} {row[4]:>6} of {row[5]:<2} {row[6]:>7} {row[7]:>9}")
