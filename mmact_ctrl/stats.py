"""Small-sample statistics for the sweep's paired comparisons (numpy + scipy, no global state).

Every comparison in the sweep is *paired*: two execution modes run the same seeds, so episode i of
mode A and episode i of mode B share the scene and the target's path. The functions here take the
per-seed outcomes of the two modes in the same order.

- :func:`wilson_interval`  95 % Wilson score interval of one success rate;
- :func:`paired_binary`    success of A vs B: difference of rates with Newcombe's paired interval
  and the exact McNemar test;
- :func:`paired_continuous` a continuous metric of A vs B: mean paired difference with a
  t-interval and the Wilcoxon signed-rank test;
- :func:`t_interval`       mean of one sample with its t-interval (figures' error bars).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy import stats as _st

Z95 = 1.959964  # the standard normal's 97.5 % quantile


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (default 95 %).

    With p = k/n::

        centre    = (p + z^2 / (2n)) / (1 + z^2/n)
        half-width = z / (1 + z^2/n) * sqrt(p (1-p) / n + z^2 / (4 n^2))

    Returns ``(lo, hi)`` as fractions in [0, 1] (``(nan, nan)`` for n = 0). Unlike the Wald
    interval it stays inside [0, 1] and does not collapse to a point at 0/n or n/n
    (0/10 -> (0, 0.2775)).
    """
    k, n = _count(successes, "successes"), _count(n, "n")
    if k > n:
        raise ValueError(f"successes ({k}) cannot exceed n ({n})")
    if not (z > 0 and math.isfinite(z)):
        raise ValueError(f"z must be a positive finite number, got {z}")
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    lo, hi = max(0.0, centre - half), min(1.0, centre + half)
    if k == 0:  # exact ends (rounding would leave 1e-17)
        lo = 0.0
    if k == n:
        hi = 1.0
    return lo, hi


def paired_binary(a: list[bool], b: list[bool]) -> dict:
    """Paired comparison of two success sequences on the same seeds (A minus B).

    The 2x2 table of pairs: ``both`` (A and B succeed), ``a_only`` (A succeeds, B fails),
    ``b_only``, ``neither``; n pairs. Success rates p_a = (both + a_only)/n, p_b = (both + b_only)/n,
    difference ``diff = p_a - p_b = (a_only - b_only)/n``.

    Interval: Newcombe's (1998) square-and-add score interval for paired proportions (his
    method 10), from the two margins' Wilson intervals (l_a, u_a), (l_b, u_b)::

        lo = diff - sqrt((p_a - l_a)^2 - 2 phi (p_a - l_a)(u_b - p_b) + (u_b - p_b)^2)
        hi = diff + sqrt((u_a - p_a)^2 - 2 phi (u_a - p_a)(p_b - l_b) + (p_b - l_b)^2)

    with phi the continuity-corrected correlation of the pairs: A = both*neither - a_only*b_only,
    phi = (A - n/2)/sqrt(product of the four margins) if A > n/2, 0 if 0 <= A <= n/2, A/sqrt(...) if
    A < 0, and 0 when a margin is empty. It keeps good coverage for small n and rates at 0 or 1,
    where the Wald interval collapses.

    Test: exact two-sided McNemar, i.e. a binomial test of a_only successes in a_only + b_only
    trials at 1/2 (``scipy.stats.binomtest``); p = 1 when there is no discordant pair.

    Returns a dict: n, successes_a, successes_b, rate_a, rate_b, both, a_only, b_only, neither,
    diff, diff_lo, diff_hi (fractions; nan for n = 0) and p_mcnemar.
    """
    a, b = _bools(a, "a"), _bools(b, "b")
    if len(a) != len(b):
        raise ValueError(f"paired sequences must have the same length, got {len(a)} and {len(b)}")
    n = len(a)
    both = sum(x and y for x, y in zip(a, b))
    a_only = sum(x and not y for x, y in zip(a, b))
    b_only = sum(y and not x for x, y in zip(a, b))
    neither = n - both - a_only - b_only
    sa, sb = both + a_only, both + b_only
    out = dict(n=n, successes_a=sa, successes_b=sb, both=both, a_only=a_only, b_only=b_only, neither=neither)
    disc = a_only + b_only
    out["p_mcnemar"] = float(_st.binomtest(a_only, disc, 0.5).pvalue) if disc else 1.0
    if n == 0:
        nan = float("nan")
        return {**out, "rate_a": nan, "rate_b": nan, "diff": nan, "diff_lo": nan, "diff_hi": nan}
    pa, pb = sa / n, sb / n
    la, ua = wilson_interval(sa, n)
    lb, ub = wilson_interval(sb, n)
    margins = sa * (n - sa) * sb * (n - sb)
    phi = 0.0
    if margins > 0:
        cross = both * neither - a_only * b_only
        if cross > n / 2:
            phi = (cross - n / 2) / math.sqrt(margins)
        elif cross < 0:
            phi = cross / math.sqrt(margins)
    diff = pa - pb
    lo = diff - math.sqrt(max(0.0, (pa - la) ** 2 - 2 * phi * (pa - la) * (ub - pb) + (ub - pb) ** 2))
    hi = diff + math.sqrt(max(0.0, (ua - pa) ** 2 - 2 * phi * (ua - pa) * (pb - lb) + (pb - lb) ** 2))
    return {**out, "rate_a": pa, "rate_b": pb, "diff": diff, "diff_lo": max(-1.0, lo), "diff_hi": min(1.0, hi)}


def paired_continuous(a: list[float], b: list[float]) -> dict:
    """Paired comparison of a continuous metric on the same seeds (A minus B, in the metric's units).

    Pairs where either value is NaN or None are dropped (``n_dropped``). On the differences
    d_i = a_i - b_i (n pairs): ``mean_diff`` = mean(d), ``median_diff`` = median(d), and the t-interval
    ``mean(d) +- t_{0.975, n-1} * sd(d)/sqrt(n)`` (sd with n-1; nan for n < 2; a point for
    constant d). ``p_wilcoxon`` is the two-sided Wilcoxon signed-rank test of d (scipy,
    zero_method 'wilcox': zero differences are discarded; exact distribution for small n without
    ties), nan when n < 2 or every difference is zero. Note that with n pairs the smallest possible
    two-sided p is 2/2^n: n >= 6 is needed to reach p < 0.05. ``rank_balance`` = (W+ - W-)/(W+ + W-)
    in [-1, 1], the signed-rank statistic's direction (W+: sum of the ranks of |d_i| over d_i > 0,
    zeros discarded; nan without a non-zero difference): negative means A tends to be lower.
    """
    fa, fb = _floats(a, "a"), _floats(b, "b")
    if len(fa) != len(fb):
        raise ValueError(f"paired sequences must have the same length, got {len(fa)} and {len(fb)}")
    keep = ~(np.isnan(fa) | np.isnan(fb))
    d = fa[keep] - fb[keep]
    n = int(d.size)
    nan = float("nan")
    out = dict(n=n, n_dropped=int(len(fa) - n), mean_a=_mean(fa[keep]), mean_b=_mean(fb[keep]),
               mean_diff=_mean(d), median_diff=float(np.median(d)) if n else nan)
    lo, hi = _t_bounds(d)
    out.update(diff_lo=lo, diff_hi=hi, p_wilcoxon=nan, rank_balance=nan)
    nz = d[d != 0]
    if nz.size:
        ranks = _st.rankdata(np.abs(nz))
        out["rank_balance"] = float((ranks[nz > 0].sum() - ranks[nz < 0].sum()) / ranks.sum())
    if n >= 2 and np.any(d != 0):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                out["p_wilcoxon"] = float(_st.wilcoxon(d, zero_method="wilcox").pvalue)
            except ValueError:  # too few non-zero differences for scipy
                pass
    return out


def t_interval(values: list[float]) -> tuple[float, float, float]:
    """``(mean, lo, hi)`` of one sample with its 95 % t-interval, NaNs dropped (nan where undefined)."""
    x = _floats(values, "values")
    x = x[~np.isnan(x)]
    return (_mean(x), *_t_bounds(x))


# ---- helpers -------------------------------------------------------------------------------


def _t_bounds(x: np.ndarray) -> tuple[float, float]:
    if x.size < 2:
        return float("nan"), float("nan")
    m = float(np.mean(x))
    half = float(_st.t.ppf(0.975, x.size - 1) * np.std(x, ddof=1) / math.sqrt(x.size))
    return m - half, m + half


def _mean(x: np.ndarray) -> float:
    return float(np.mean(x)) if x.size else float("nan")


def _count(v, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) and not (isinstance(v, float) and v.is_integer()):
        raise ValueError(f"{name} must be a non-negative integer, got {v!r}")
    if v < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {v!r}")
    return int(v)


def _bools(seq, name: str) -> list[bool]:
    out = []
    for v in seq:
        if isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1)):
            out.append(bool(v))
        else:
            raise ValueError(f"{name} must hold booleans (or 0/1), got {v!r}")
    return out


def _floats(seq, name: str) -> np.ndarray:
    try:
        return np.array([np.nan if v is None else float(v) for v in seq], dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must hold numbers (NaN or None for missing)") from None
