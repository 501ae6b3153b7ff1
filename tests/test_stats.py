"""scenarios.stats against published values and constructed data."""

import math

import numpy as np
import pytest

from mmact_ctrl.stats import paired_binary, paired_continuous, t_interval, wilson_interval


@pytest.mark.parametrize("k,n,lo,hi", [
    (0, 10, 0.0, 0.2775), (10, 10, 0.7225, 1.0), (5, 10, 0.2366, 0.7634),
    (81, 263, 0.2553, 0.3662),  # Newcombe (1998), single proportion, example (a)
    (15, 148, 0.0624, 0.1605),  # Newcombe (1998), example (b)
    (1, 29, 0.0061, 0.1718),  # Newcombe (1998), example (d)
])
def test_wilson_matches_published_values(k, n, lo, hi):
    got = wilson_interval(k, n)
    assert got == pytest.approx((lo, hi), abs=1e-4)


def test_wilson_edge_cases_and_bad_input():
    assert all(math.isnan(x) for x in wilson_interval(0, 0))
    lo, hi = wilson_interval(3, 10, z=1.0)
    assert lo < 0.3 < hi and (hi - lo) < (wilson_interval(3, 10)[1] - wilson_interval(3, 10)[0])
    for args in [(11, 10), (-1, 10), (1, -2), (1.5, 10), (True, 10), ("3", 10)]:
        with pytest.raises(ValueError):
            wilson_interval(*args)
    with pytest.raises(ValueError):
        wilson_interval(1, 10, z=0.0)


def test_mcnemar_exact_p_on_a_known_table():
    # 1 pair where only A succeeds, 9 where only B does: p = 2 * P(X <= 1 | Bin(10, 1/2)) = 22/1024
    a = [True] + [False] * 9 + [True] * 5 + [False] * 3
    b = [False] + [True] * 9 + [True] * 5 + [False] * 3
    r = paired_binary(a, b)
    assert (r["a_only"], r["b_only"], r["both"], r["neither"], r["n"]) == (1, 9, 5, 3, 18)
    assert r["p_mcnemar"] == pytest.approx(0.02148, abs=1e-5)
    assert r["diff"] == pytest.approx(-8 / 18)
    assert r["diff_lo"] < r["diff"] < r["diff_hi"] < 0  # significant: the interval excludes 0


def test_paired_binary_newcombe_interval():
    # 10/10 vs 0/10: the margins' Wilson intervals square-and-added (phi = 0, one margin empty)
    r = paired_binary([True] * 10, [False] * 10)
    w = wilson_interval(10, 10)[0]
    assert r["diff"] == 1.0 and r["diff_hi"] == 1.0
    assert r["diff_lo"] == pytest.approx(1.0 - math.hypot(1 - w, 1 - w), abs=1e-12)  # 0.6075
    assert r["p_mcnemar"] == pytest.approx(2 / 1024)
    # no discordant pair: p = 1, the interval is symmetric about 0
    r = paired_binary([True] * 5 + [False] * 5, [True] * 5 + [False] * 5)
    assert r["diff"] == 0 and r["p_mcnemar"] == 1.0 and r["diff_lo"] == pytest.approx(-r["diff_hi"])
    # a positive correlation between the pairs narrows the interval against phi = 0
    a = [True] * 6 + [False] * 6 + [True] * 3 + [False]
    b = [True] * 6 + [False] * 6 + [False] * 3 + [True]
    r = paired_binary(a, b)
    la, ua = wilson_interval(9, 16)
    lb, ub = wilson_interval(7, 16)
    pa, pb = 9 / 16, 7 / 16
    assert r["diff_lo"] > (pa - pb) - math.hypot(pa - la, ub - pb)
    assert r["diff_hi"] < (pa - pb) + math.hypot(ua - pa, pb - lb)
    assert paired_binary([], [])["n"] == 0 and math.isnan(paired_binary([], [])["diff"])


def test_paired_binary_bad_input():
    with pytest.raises(ValueError):
        paired_binary([True], [True, False])
    with pytest.raises(ValueError):
        paired_binary([True, 2], [True, False])


def test_paired_continuous_on_constructed_data():
    rng = np.random.default_rng(1)
    b = rng.normal(0.1, 0.02, 12)
    a = b - 0.03 + rng.normal(0, 0.001, 12)  # A 30 mm lower on every seed
    a[3], b[7] = np.nan, np.nan
    r = paired_continuous(list(a), list(b))
    d = (a - b)[~(np.isnan(a) | np.isnan(b))]
    assert r["n"] == 10 and r["n_dropped"] == 2
    assert r["mean_diff"] == pytest.approx(d.mean())
    half = 2.262157 * d.std(ddof=1) / math.sqrt(10)  # t_{0.975, 9}
    assert (r["diff_lo"], r["diff_hi"]) == pytest.approx((d.mean() - half, d.mean() + half), rel=1e-5)
    assert r["p_wilcoxon"] == pytest.approx(2 / 2**10)  # every difference negative: the exact minimum
    assert r["rank_balance"] == -1.0


def test_paired_continuous_degenerate_cases():
    r = paired_continuous([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])  # all-zero differences
    assert r["mean_diff"] == 0 and math.isnan(r["p_wilcoxon"]) and (r["diff_lo"], r["diff_hi"]) == (0, 0)
    r = paired_continuous([1.0], [0.0])  # n < 2
    assert r["mean_diff"] == 1.0 and math.isnan(r["p_wilcoxon"]) and math.isnan(r["diff_lo"])
    r = paired_continuous([float("nan"), None], [1.0, 2.0])
    assert r["n"] == 0 and math.isnan(r["mean_diff"]) and math.isnan(r["p_wilcoxon"])
    with pytest.raises(ValueError):
        paired_continuous([1.0, 2.0], [1.0])
    with pytest.raises(ValueError):
        paired_continuous(["x"], [1.0])


def test_t_interval():
    m, lo, hi = t_interval([1.0, 2.0, 3.0, float("nan")])
    assert m == 2.0 and (lo, hi) == pytest.approx((2 - 4.302653 / math.sqrt(3), 2 + 4.302653 / math.sqrt(3)), rel=1e-6)
    assert all(math.isnan(x) for x in t_interval([]))
