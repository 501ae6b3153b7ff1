"""Pair two main-job runs by seed (in-process vs served): success with Wilson intervals, final error, and the
per-episode differences. Usage: python docs/byo/compare.py A.json B.json [C.json D.json ...] (pairs)."""

import json
import sys

import numpy as np

from mmact_ctrl.stats import wilson_interval


def main(paths: list[str]) -> None:
    print("| target | mode | in-process success [95 %] | served success [95 %] | final error in / served [mm] | "
          "episodes identical (success, final error) | round trip median / p95 [ms] | server infer [ms] |")
    print("|---|---|---|---|---|---|---|---|")
    for a_path, b_path in zip(paths[::2], paths[1::2]):
        a, b = json.load(open(a_path)), json.load(open(b_path))
        target = a["config"]["target"]
        for mode in a["runs"]:
            ea, eb = a["runs"][mode]["episodes"], b["runs"][mode]["episodes"]
            sa, sb = sum(e["success"] for e in ea), sum(e["success"] for e in eb)
            ca, cb = wilson_interval(sa, len(ea)), wilson_interval(sb, len(eb))
            fa = np.mean([e["final_error_m"] for e in ea]) * 1e3
            fb = np.mean([e["final_error_m"] for e in eb]) * 1e3
            same = sum(x["seed"] == y["seed"] and x["success"] == y["success"]
                       and abs(x["final_error_m"] - y["final_error_m"]) < 1e-9 for x, y in zip(ea, eb))
            rt = b["runs"][mode]["summary"]["round_trip_ms"]
            srv = b["runs"][mode]["summary"].get("server_infer_ms", {}).get("median", float("nan"))
            print(f"| {target} | {mode} | {sa}/{len(ea)} [{100 * ca[0]:.0f}-{100 * ca[1]:.0f} %] | {sb}/{len(eb)} "
                  f"[{100 * cb[0]:.0f}-{100 * cb[1]:.0f} %] | {fa:.1f} / {fb:.1f} | {same}/{len(ea)} | "
                  f"{rt['median']:.1f} / {rt['p95']:.1f} | {srv:.1f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
