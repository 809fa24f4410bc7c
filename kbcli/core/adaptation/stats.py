"""Statistics of repeated adaptation experiments (paper Sect. IV-A and IV-B, Figs. 6 and 7).

RMSE curves (Fig. 7), observations to thresholds (a run that never gets there within its ``T``
steps counts as ``T + 1``), tie-corrected rank tests between strategies on them, and the posterior
entropy per step (Fig. 6). ``errors`` is ``(n, T)`` (experiment, step), step ``t`` being the state
after ``t + 1`` observations.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as _sps

QUANTILES = (0.25, 0.5, 0.75)


def rmse_curve(errors: np.ndarray) -> np.ndarray:
    """(T,) root-mean-square error over the experiments ``errors`` (n, T), px, at each step."""
    e = np.asarray(errors, float)
    return np.sqrt(np.mean(e * e, axis=0))


def spread(errors: np.ndarray) -> dict[str, np.ndarray]:
    """Summary of ``errors`` (n, T) at each step: mean, std, q25, median, q75 (each (T,))."""
    e = np.asarray(errors, float)
    q = np.quantile(e, QUANTILES, axis=0)
    return {
        "mean": e.mean(axis=0),
        "std": e.std(axis=0),
        "q25": q[0],
        "median": q[1],
        "q75": q[2],
    }


def curves(errors: np.ndarray, groups: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Everything Fig. 7 draws for one category and strategy: ``rmse`` and the :func:`spread`
    entries, plus ``rmse_by_group`` (G, T) in sorted group order when ``groups`` (n,) is given."""
    out = {"rmse": rmse_curve(errors), **spread(errors)}
    if groups is not None:
        groups = np.asarray(groups)
        out["rmse_by_group"] = np.stack(
            [rmse_curve(np.asarray(errors)[groups == g]) for g in np.unique(groups)]
        )
    return out


def samples_to_threshold(errors: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """(n, k) observations each experiment needed for its error to first drop below each of
    ``thresholds`` (k,): ``t + 1`` for the first such step ``t``, ``T + 1`` when never (censored).
    """
    e = np.asarray(errors, float)
    thr = np.asarray(thresholds, float)
    below = e[:, None, :] < thr[None, :, None]  # (n, k, T)
    first = np.argmax(below, axis=-1) + 1
    return np.where(below.any(axis=-1), first, e.shape[1] + 1).astype(np.int64)


def reached(counts: np.ndarray, max_steps: int) -> np.ndarray:
    """(k,) fraction of experiments that got below each threshold within ``max_steps``, from
    :func:`samples_to_threshold` ``counts``."""
    return np.mean(np.asarray(counts) <= max_steps, axis=0)


def median_samples(counts: np.ndarray, max_steps: int) -> np.ndarray:
    """(k,) median observations to each threshold; NaN when fewer than half the runs got there.

    Censored runs count as slower than every run that got there: the median is exact.
    """
    c = np.asarray(counts)
    med = np.median(c, axis=0).astype(float)
    return np.where(med <= max_steps, med, np.nan)


def mannwhitney_pvalues(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided, tie-corrected Mann-Whitney U (Wilcoxon rank-sum) test per threshold.

    Parameters
    ----------
    a, b : (n, k) and (m, k) ndarrays
        Observations to each of ``k`` thresholds, one row per experiment of each strategy.

    Returns
    -------
    effect, pvalue : (k,) ndarrays
        ``effect = P(a > b) + P(a = b) / 2 - 1/2``, in [-0.5, 0.5]: < 0 when ``a`` needed fewer
        observations. ``pvalue`` from the normal approximation with continuity correction. No
        spread at all: effect 0, p-value 1.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        res = _sps.mannwhitneyu(a, b, axis=0, alternative="two-sided", method="asymptotic",
                                use_continuity=True)
    effect = np.asarray(res.statistic, float) / (a.shape[0] * b.shape[0]) - 0.5
    p = np.asarray(res.pvalue, float)
    tied = np.all(np.concatenate([a, b]) == np.concatenate([a, b])[:1], axis=0)
    return np.where(tied, 0.0, effect), np.where(tied | np.isnan(p), 1.0, p)


def signed_rank_pvalues(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided Wilcoxon signed-rank test of paired samples per threshold.

    Parameters
    ----------
    a, b : (n, k) ndarrays
        Row ``i`` of ``a`` and of ``b`` are a pair (same displacement and seed).

    Returns
    -------
    effect, pvalue : (k,) ndarrays
        ``effect = (R+ - R-) / (R+ + R-)``, the rank-biserial correlation of ``a - b`` (zeros
        dropped): < 0 when ``a`` needed fewer. ``pvalue`` from ``scipy.stats.wilcoxon``. No nonzero
        difference: effect 0, p-value 1.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.shape != b.shape:
        raise ValueError(f"paired samples need the same shape, got {a.shape} and {b.shape}")
    d = a - b
    k = d.shape[1]
    effect = np.zeros(k)
    p = np.ones(k)
    for j in range(k):
        dj = d[:, j][d[:, j] != 0]
        if len(dj) == 0:
            continue
        r = _sps.rankdata(np.abs(dj))
        effect[j] = (r[dj > 0].sum() - r[dj < 0].sum()) / r.sum()
        with np.errstate(divide="ignore", invalid="ignore"):
            res = _sps.wilcoxon(dj, zero_method="wilcox", alternative="two-sided")
        p[j] = 1.0 if np.isnan(res.pvalue) else float(res.pvalue)
    return effect, p


def min_pvalue_unpaired(n: int, m: int) -> float:
    """Smallest two-sided p-value a rank test of two independent samples of sizes ``n`` and ``m``
    can give, ``2 / C(n + m, n)`` (ties make it larger); 0.0 when it underflows a float."""
    if n < 1 or m < 1:
        return 1.0
    log_p = math.log(2) - (math.lgamma(n + m + 1) - math.lgamma(n + 1) - math.lgamma(m + 1))
    return min(1.0, math.exp(log_p)) if log_p > -708 else 0.0


def min_pvalue_paired(n: int) -> float:
    """Smallest two-sided p-value of the Wilcoxon signed-rank test on ``n`` pairs: ``2 / 2^n``
    (every difference of one sign). 0.0 when it underflows."""
    if n < 1:
        return 1.0
    return min(1.0, 2.0 ** (1 - n)) if n < 1000 else 0.0


def entropy_curves(entropy: np.ndarray) -> dict[str, np.ndarray]:
    """Mean and quartiles (each (T,)) of the posterior entropy (n, T) in nats (Fig. 6)."""
    e = np.asarray(entropy, float)
    q = np.quantile(e, QUANTILES, axis=0)
    return {"mean": e.mean(axis=0), "q25": q[0], "median": q[1], "q75": q[2]}
