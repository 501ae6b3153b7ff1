"""Per target and variant: episodes, successes, mean final / mean error, rejected chunks, violations: python sum.py OUT.jsonl."""
import json, sys, collections, numpy as np
rows = [json.loads(l) for l in open(sys.argv[1])]
g = collections.defaultdict(list)
for r in rows: g[(r["target"], r["variant"])].append(r)
for (t, v), rs in sorted(g.items()):
    print(f"{t:12s} {v:14s} n={len(rs):2d} succ {sum(r['success'] for r in rs):2d} final {np.mean([r['final_mm'] for r in rs]):6.1f} mean {np.mean([r['mean_mm'] for r in rs]):6.1f} rej {np.mean([r['rejected'] for r in rs]):4.1f} viol {sum(r['viol'] for r in rs)}")
