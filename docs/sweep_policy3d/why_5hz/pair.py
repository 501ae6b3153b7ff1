"""Paired differences of two variants in a layers.py output: python pair.py OUT.jsonl A B [final_mm|mean_mm]."""
import json, sys, collections, numpy as np
from scipy.stats import wilcoxon
rows = [json.loads(l) for l in open(sys.argv[1])]
a, b = sys.argv[2], sys.argv[3]
key = sys.argv[4] if len(sys.argv) > 4 else "final_mm"
by = collections.defaultdict(dict)
for r in rows: by[(r["target"], r["variant"])][r["seed"]] = r
for t in sorted({r["target"] for r in rows}):
    A, B = by[(t, a)], by[(t, b)]
    s = sorted(set(A) & set(B))
    if not s: continue
    d = np.array([A[x][key] - B[x][key] for x in s])
    p = wilcoxon(d).pvalue if np.any(d != 0) else 1.0
    print(f"{t:12s} {a} - {b} {key}: {d.mean():+6.1f} mm (n={len(s)}, Wilcoxon p={p:.3f}); success {sum(A[x]['success'] for x in s)}/{sum(B[x]['success'] for x in s)}")
