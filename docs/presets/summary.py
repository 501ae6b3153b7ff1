"""The table of issue 30's figures from docs/presets/*.json (run.sh writes them)."""

import json
from pathlib import Path

HERE = Path(__file__).parent


def load(name: str) -> dict:
    return json.loads((HERE / f"{name}.json").read_text())


def successes(run: dict, mode: str) -> str:
    eps = run["runs"][mode]["episodes"]
    return f"{sum(e['success'] for e in eps)}/{len(eps)}"


def main() -> None:
    print("| preset | target | mode | native | served | final error, native / served [mm] | difference per episode, mean / largest [mm] | violations (served) | one piece wrong: --delta-from observation (open_loop) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for preset in ("libero", "droid"):
        for target in ("static", "linear"):
            nat, srv, wrong = (load(f"{preset}_{target}_{k}") for k in ("native", "served", "wrong"))
            for mode in ("open_loop", "hybrid"):
                a, b = nat["runs"][mode]["episodes"], srv["runs"][mode]["episodes"]
                diffs = [abs(x["final_error_m"] - y["final_error_m"]) * 1e3 for x, y in zip(a, b)]
                same = [x["success"] for x in a] == [y["success"] for y in b]
                viol = sum(e["limit_violations"] for e in b)
                w = ""
                if mode == "open_loop":
                    ws = wrong["runs"]["open_loop"]
                    w = f"{successes(wrong, 'open_loop')}, {ws['summary']['final_error_m'] * 1e3:.1f} mm"
                print(f"| {preset} | {target} | {mode} | {successes(nat, mode)} | {successes(srv, mode)}"
                      f"{'' if same else ' (differs)'} | {nat['runs'][mode]['summary'].get('final_error_m', float('nan')) * 1e3:.1f} / "
                      f"{srv['runs'][mode]['summary'].get('final_error_m', float('nan')) * 1e3:.1f} | {sum(diffs) / len(diffs):.3f} / {max(diffs):.3f} | {viol} | {w} |")
    print()
    for name in ("watchdog_1hz", "watchdog_suggested"):
        run = load(name)
        cov = run["config"]["connect"]["coverage"]
        stops = {m: sum(e["watchdog_stops"] for e in r["episodes"]) for m, r in run["runs"].items()}
        rt = run["config"]["connect"]["first"]["round_trip_ms"]
        print(f"- {name}: replan {run['config']['replan_hz']:g} Hz, first round trip {rt:.0f} ms, covers {cov['covers']}, "
              f"suggested {cov['suggested_replan_hz']}, watchdog stops {stops}, success "
              + ", ".join(f"{m} {successes(run, m)}" for m in run["runs"]))


if __name__ == "__main__":
    main()
