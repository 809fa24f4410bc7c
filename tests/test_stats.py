"""Known answers of kbcli.core.adaptation.stats with unequal group sizes (issue 25: a Mann-Whitney effect
normalised by n*n instead of n*m survived every equal-sized test)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from kbcli.core.adaptation import stats


def test_mannwhitney_effect_unequal_groups_by_hand():
    # a = 1, 2, 3 (n = 3) against b = 2, 4, 5, 6, 7 (m = 5): pairs with a > b: (3, 2) = 1, ties:
    # (2, 2) = 1/2, so U = 1.5 of n m = 15 pairs; effect = 1.5 / 15 - 1/2 = -0.4
    # (normalised by n n = 9 it would be -1/3, by m m = 25 -0.44)
    a = np.array([1.0, 2.0, 3.0])[:, None]
    b = np.array([2.0, 4.0, 5.0, 6.0, 7.0])[:, None]
    eff, _ = stats.mannwhitney_pvalues(a, b)
    assert eff[0] == pytest.approx(-0.4, abs=1e-12)
    # the other way round: U = 15 - 1.5 = 13.5 of 15 pairs: +0.4 (n n = 25 would give +0.04)
    eff, _ = stats.mannwhitney_pvalues(b, a)
    assert eff[0] == pytest.approx(0.4, abs=1e-12)


def test_mannwhitney_pvalue_unequal_groups_by_hand():
    # the same samples: N = 8, one tie of two; mean U = n m / 2 = 7.5; tie-corrected variance
    # n m / 12 * (N + 1 - (2^3 - 2) / (N (N - 1))) = 1.25 * (9 - 6 / 56); two-sided with
    # continuity correction: z = (|1.5 - 7.5| - 0.5) / sd
    a = np.array([1.0, 2.0, 3.0])[:, None]
    b = np.array([2.0, 4.0, 5.0, 6.0, 7.0])[:, None]
    sd = math.sqrt(1.25 * (9 - 6 / 56))
    z = 5.5 / sd
    expected = math.erfc(z / math.sqrt(2))  # 2 * (1 - Phi(z))
    _, p = stats.mannwhitney_pvalues(a, b)
    assert p[0] == pytest.approx(expected, rel=1e-12)
    assert p[0] == pytest.approx(0.0990, abs=5e-4)


@pytest.mark.parametrize("n,m", [(3, 7), (10, 4), (1, 6), (12, 5)])
def test_mannwhitney_effect_is_u_over_n_times_m(n, m):
    """Several thresholds at once, unequal sizes, heavy ties: effect = U / (n m) - 1/2 with U
    from scipy.stats.mannwhitneyu, and the same p-value."""
    rng = np.random.default_rng(n * 100 + m)
    a = rng.integers(1, 6, size=(n, 3)).astype(float)
    b = rng.integers(2, 8, size=(m, 3)).astype(float)
    eff, p = stats.mannwhitney_pvalues(a, b)
    for j in range(3):
        res = sps.mannwhitneyu(a[:, j], b[:, j], alternative="two-sided", method="asymptotic")
        assert eff[j] == pytest.approx(res.statistic / (n * m) - 0.5, abs=1e-12)
        assert p[j] == pytest.approx(res.pvalue, rel=1e-12)
        # the direct count: P(a > b) + P(a = b) / 2 - 1/2
        diff = a[:, j][:, None] - b[:, j][None, :]
        direct = (np.sum(diff > 0) + 0.5 * np.sum(diff == 0)) / (n * m) - 0.5
        assert eff[j] == pytest.approx(direct, abs=1e-12)


def test_mannwhitney_extremes_unequal_groups():
    a = np.arange(1.0, 4.0)[:, None]  # 3 runs, all faster than
    b = np.arange(10.0, 17.0)[:, None]  # 7 runs
    eff, _ = stats.mannwhitney_pvalues(a, b)
    assert eff[0] == -0.5
    eff, _ = stats.mannwhitney_pvalues(b, a)
    assert eff[0] == 0.5


def test_smallest_attainable_pvalue_unequal_groups():
    assert stats.min_pvalue_unpaired(3, 5) == pytest.approx(2 / math.comb(8, 3))
    assert stats.min_pvalue_unpaired(5, 3) == pytest.approx(stats.min_pvalue_unpaired(3, 5))
    assert stats.min_pvalue_unpaired(0, 5) == 1.0
    exact = sps.mannwhitneyu([1, 2, 3], [4, 5, 6, 7, 8], method="exact").pvalue
    assert exact == pytest.approx(stats.min_pvalue_unpaired(3, 5))
