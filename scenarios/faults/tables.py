"""The fault suite's rows summed up: per cell (source x fault x mode), the totals, what each fault cost versus the
``none`` row, and the markdown fault x mode tables of the report."""

from __future__ import annotations

import math

import numpy as np

from scenarios.faults.settings import EXPECTED_ABORTS, SAFETY_COLUMNS, VIOLATION_KINDS


def _violations(row: dict) -> int:
    return int(row["limit_violations"])


def cell_table(rows: list[dict]) -> list[dict]:
    """Per (source, fault, mode): episodes, success rate, violations, raised, aborts, median recovery."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["source"], r["fault"], r["mode"]), []).append(r)
    out = []
    for (src, fault, mode), rs in groups.items():
        rec = [r["recovery_s"] for r in rs if math.isfinite(r["recovery_s"])]
        out.append({
            "source": src, "fault": fault, "mode": mode, "episodes": len(rs),
            "applicable": all(r["applicable"] for r in rs),
            "success_rate": float(np.mean([bool(r["success"]) for r in rs])),
            "violations": int(sum(_violations(r) for r in rs)),
            **{k: int(sum(int(r[k]) for r in rs)) for k in VIOLATION_KINDS},
            "raised": int(sum(bool(r["raised"]) for r in rs)),
            "aborts": int(sum(int(r["aborts"]) for r in rs)),
            "rejected_chunks": int(sum(int(r["rejected_chunks"]) for r in rs)),
            "watchdog_stops": int(sum(int(r["watchdog_stops"]) for r in rs)),
            "gated_measurements": int(sum(int(r["gated_measurements"]) for r in rs)),
            "qp_failures": int(sum(int(r["qp_failures"]) for r in rs)),
            "mpc_failures": int(sum(int(r["mpc_failures"]) for r in rs)),
            "recovery_s_median": float(np.median(rec)) if rec else float("nan"),
            "recovered": len(rec),
            "recovered_rate": len(rec) / len(rs),
        })
    return out


def totals(rows: list[dict]) -> dict:
    """Violations of every kind over all episodes, exceptions, aborts and which faults they came from."""
    by_kind = {k: int(sum(int(r[k]) for r in rows)) for k in SAFETY_COLUMNS}
    viol_cells = sorted({(r["fault"], r["mode"], r["source"]) for r in rows if _violations(r)})
    raised = [{"fault": r["fault"], "mode": r["mode"], "source": r["source"], "seed": r["seed"], "raised": r["raised"],
               "traceback": r.get("traceback", "")} for r in rows if r["raised"]]
    aborts = [{"fault": r["fault"], "mode": r["mode"], "source": r["source"], "seed": r["seed"],
               "reason": r["abort_reason"], "t_s": r["abort_t_s"], "expected": r["fault"] in EXPECTED_ABORTS}
              for r in rows if int(r["aborts"])]
    missing_aborts = [{"fault": r["fault"], "mode": r["mode"], "source": r["source"], "seed": r["seed"]}
                      for r in rows if r["fault"] in EXPECTED_ABORTS and not int(r["aborts"]) and not r["raised"]]
    return {
        "episodes": len(rows),
        "violations": by_kind,
        "violation_cells": [{"fault": f, "mode": m, "source": s} for f, m, s in viol_cells],
        "exceptions": len(raised),
        "exception_list": raised,
        "aborts": len(aborts),
        "unexpected_aborts": sum(not a["expected"] for a in aborts),
        "abort_list": aborts,
        "missing_expected_aborts": missing_aborts,
        **{k: int(sum(int(r[k]) for r in rows)) for k in ("rejected_chunks", "watchdog_stops", "gated_measurements",
                                                           "missed_ticks", "qp_failures", "mpc_failures",
                                                           "perception_errors")},
    }


def _cell_text(c: dict) -> str:
    if not c["applicable"]:
        return "n/a"
    text = f"{c['success_rate']:.0%}"
    if c["violations"]:
        text += f" V{c['violations']}"
    if c["raised"]:
        text += f" R{c['raised']}"
    if c["aborts"]:
        text += f" A{c['aborts']}"
    return text


def _tables(cells: list[dict], faults: list[str], modes: list[str], sources: list[str], cell_text) -> dict[str, str]:
    """A markdown fault x mode table per source; ``cell_text(cell)`` formats one cell ("-" where none ran)."""
    index = {(c["source"], c["fault"], c["mode"]): c for c in cells}
    tables = {}
    for src in sources:
        lines = ["| fault | " + " | ".join(modes) + " |", "|---|" + "---|" * len(modes)]
        for f in faults:
            lines.append(f"| {f} | " + " | ".join(cell_text(index[(src, f, m)]) if (src, f, m) in index else "-"
                                                   for m in modes) + " |")
        tables[src] = "\n".join(lines)
    return tables


def _recovery_text(c: dict) -> str:
    if not c["applicable"]:
        return "n/a"
    if c["recovered"]:
        return f"{c['recovery_s_median']:.2f} ({c['recovered']}/{c['episodes']})"
    return f"never (0/{c['episodes']})"


def fault_tables(cells: list[dict], faults: list[str], modes: list[str], sources: list[str]) -> dict[str, str]:
    """Success (and violations, exceptions, aborts) per fault x mode, one table per source."""
    return _tables(cells, faults, modes, sources, _cell_text)


def recovery_tables(cells: list[dict], faults: list[str], modes: list[str], sources: list[str]) -> dict[str, str]:
    """Median recovery time (episodes recovered / episodes) per fault x mode, one table per source."""
    return _tables(cells, faults, modes, sources, _recovery_text)


def success_costs(cells: list[dict], faults: list[str], modes: list[str], sources: list[str],
                  key: str = "success_rate") -> dict:
    """Per source and fault: ``key`` (``success_rate`` or ``recovered_rate``) versus the ``none`` row in the same
    modes (applicable cells only)."""
    index = {(c["source"], c["fault"], c["mode"]): c for c in cells}
    out: dict[str, dict] = {}
    for src in sources:
        base = {m: index[(src, "none", m)][key] for m in modes if (src, "none", m) in index}
        per_fault = {}
        for f in faults:
            if f == "none":
                continue
            deltas = {m: index[(src, f, m)][key] - base[m] for m in modes
                      if m in base and (src, f, m) in index and index[(src, f, m)]["applicable"]}
            if not deltas:
                continue
            worst = min(deltas, key=deltas.get)
            rate = float(np.mean([index[(src, f, m)][key] for m in deltas]))
            ref = float(np.mean([base[m] for m in deltas]))
            per_fault[f] = {"rate": rate, "baseline": ref, "n_modes": len(deltas), "delta": rate - ref, "worst_mode": worst,
                            "worst_delta": deltas[worst], "worst_rate": index[(src, f, worst)][key],
                            "worst_baseline": base[worst]}
        out[src] = {"baseline": base, "faults": per_fault}
    return out
