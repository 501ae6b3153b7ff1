"""Two checkpoints on the same seeds, paired: ``python docs/policy3d/compare_checkpoints.py NEW_DIR OLD_DIR``.

Each directory holds the JSONs of ``evalA.sh`` / ``evalB.sh`` (``scenarios.moving_target --json``). For every file and
mode both have, the episodes are paired by seed: success difference (new minus old) with Newcombe's paired interval
and the exact McNemar p, final-error difference (mm) with its t-interval and the Wilcoxon p
(``mmact_ctrl.stats``), and the limit violations of each.
"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from mmact_ctrl.stats import paired_binary, paired_continuous  # noqa: E402


def runs(d: Path) -> dict[tuple[str, str], dict[int, dict]]:
    out = {}
    for f in sorted(d.glob("*.json")):
        p = json.loads(f.read_text())
        for mode, run in p.get("runs", {}).items():
            out[(f.stem, mode)] = {int(e["seed"]): e for e in run["episodes"]}
    return out


def main() -> None:
    new, old = runs(Path(sys.argv[1])), runs(Path(sys.argv[2]))
    print(f"new = {sys.argv[1]}, old = {sys.argv[2]}; paired by seed; differences are new minus old")
    for key in sorted(set(new) & set(old)):
        seeds = sorted(set(new[key]) & set(old[key]))
        a = [new[key][s] for s in seeds]
        b = [old[key][s] for s in seeds]
        pb = paired_binary([e["success"] for e in a], [e["success"] for e in b])
        pc = paired_continuous([1e3 * e["final_error_m"] for e in a], [1e3 * e["final_error_m"] for e in b])
        va, vb = sum(e["limit_violations"] for e in a), sum(e["limit_violations"] for e in b)
        print(f"{key[0]:20s} {key[1]:9s} n={len(seeds):3d} success {100 * pb['rate_a']:5.1f} vs {100 * pb['rate_b']:5.1f} % "
              f"(diff {100 * pb['diff']:+5.1f} [{100 * pb['diff_lo']:+.0f}, {100 * pb['diff_hi']:+.0f}], McNemar p={pb['p_mcnemar']:.3f}) "
              f"final error {pc['mean_diff']:+6.1f} mm (Wilcoxon p={pc['p_wilcoxon']:.3f}) violations {va} / {vb}")


if __name__ == "__main__":
    main()
