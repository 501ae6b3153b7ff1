"""Issue 14 figures from the eval JSONs: success (Wilson 95 %), wrong object, final error; held-out region split."""
import json, sys
from pathlib import Path
import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from mmact_ctrl.stats import wilson_interval as wilson
from scenarios.collect import in_box

HOLD = (0.5, 0.65, 0.0, 0.3)  # the --holdout-box-m of the training data
d = Path(sys.argv[1])
for f in sorted(d.glob("*.json")):
    p = json.loads(f.read_text())
    for mode, run in p["runs"].items() if "runs" in p else []:
        eps = run["episodes"]
        s = np.array([e["success"] for e in eps]); w = np.array([e["wrong_object"] for e in eps])
        fe = np.array([e["final_error_m"] for e in eps]) * 1e3
        acc = np.array([e["chunk_jump_acc_m_s2"] for e in eps]); viol = sum(e["limit_violations"] for e in eps)
        lo, hi = wilson(int(s.sum()), len(s))
        line = (f"{f.stem:22s} {mode:10s} n={len(s):3d} success {100*s.mean():5.1f} % [{100*lo:.0f}-{100*hi:.0f}] "
                f"wrong {100*w.mean():4.1f} % final {fe.mean():6.1f} mm (median {np.median(fe):5.1f}) "
                f"switch acc {np.median(acc):5.2f} m/s2 viol {viol}")
        print(line)
        if "static" in f.stem and "target_start_pos_m" in eps[0]:
            inb = np.array([in_box(e["target_start_pos_m"], HOLD) for e in eps])
            for name, m in (("held-out box", inb), ("rest", ~inb)):
                if m.any():
                    lo, hi = wilson(int(s[m].sum()), int(m.sum()))
                    print(f"{'':33s} {name:12s} n={m.sum():3d} success {100*s[m].mean():5.1f} % [{100*lo:.0f}-{100*hi:.0f}] final {fe[m].mean():6.1f} mm")
