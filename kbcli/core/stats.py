"""Statistics of repeated adaptation experiments (paper Sect. IV-A and IV-B, Figs. 6 and 7).

The paper runs 50 experiments per displacement parametrization, groups the parametrizations into
small, medium and large displacements, and reports

- the estimation error against the number of observations (Fig. 7): here the root-mean-square of
  the per-experiment error over the experiments of a group, ``RMSE(t) = sqrt(mean_i e_i(t)^2)``,
  with its spread (quartiles and standard deviation of ``e_i(t)``, and the RMSE of each
  parametrization);
- how many observations each experiment needed to bring its error below a threshold, and the
  Wilcoxon rank-sum test between two strategies on those counts (``scipy.stats.ranksums``); an
  experiment that never gets below a threshold within its ``T`` steps counts as ``T + 1`` (it ranks
  after every experiment that did, and ties with the others that did not);
- the entropy of the posterior per step (Fig. 6).

Pure numpy/scipy: no I/O, no plotting. Shapes: ``errors`` is ``(n, T)`` (experiment, step), step
``t`` (0-based) being the state after ``t + 1`` observations.
"""

from __future__ import annotations

import numpy as np
from scipy import stats as _sps

QUANTILES = (0.25, 0.5, 0.75)


def rmse_curve(errors: np.ndarray) -> np.ndarray:
    """Root-mean-square error over experiments at each step.

    Parameters
    ----------
    errors : (n, T) ndarray
        Error of each experiment at each step (px); ``n >= 1``.

    Returns
    -------
    (T,) ndarray
    """
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
    """Everything Fig. 7 draws for one category and strategy.

    Parameters
    ----------
    errors : (n, T) ndarray
    groups : (n,) int ndarray, optional
        Parametrization of each experiment; adds ``rmse_by_group`` (G, T) in sorted group order.

    Returns
    -------
    dict of (T,) ndarrays
        ``rmse`` and the :func:`spread` entries, plus ``rmse_by_group`` when ``groups`` is given.
    """
    out = {"rmse": rmse_curve(errors), **spread(errors)}
    if groups is not None:
        groups = np.asarray(groups)
        out["rmse_by_group"] = np.stack(
            [rmse_curve(np.asarray(errors)[groups == g]) for g in np.unique(groups)]
        )
    return out


def samples_to_threshold(errors: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """Observations each experiment needed for its error to first drop below each threshold.

    Parameters
    ----------
    errors : (n, T) ndarray
    thresholds : (k,) ndarray
        Error thresholds (px).

    Returns
    -------
    (n, k) int ndarray
        ``t + 1`` for the first step ``t`` with ``errors[i, t] < thresholds[j]``; ``T + 1`` when the
        error never gets below it (censored).
    """
    e = np.asarray(errors, float)
    thr = np.asarray(thresholds, float)
    below = e[:, None, :] < thr[None, :, None]  # (n, k, T)
    first = np.argmax(below, axis=-1) + 1
    return np.where(below.any(axis=-1), first, e.shape[1] + 1).astype(np.int64)


def reached(counts: np.ndarray, max_steps: int) -> np.ndarray:
    """(k,) fraction of experiments that got below each threshold within ``max_steps``.

    Parameters
    ----------
    counts : (n, k) int ndarray
        From :func:`samples_to_threshold`.
    """
    return np.mean(np.asarray(counts) <= max_steps, axis=0)


def median_samples(counts: np.ndarray, max_steps: int) -> np.ndarray:
    """(k,) median observations to each threshold; NaN when fewer than half the runs got there.

    Censored runs (``T + 1``) count as slower than every run that got there, so the median is exact
    whenever at least half the runs reached the threshold.
    """
    c = np.asarray(counts)
    med = np.median(c, axis=0).astype(float)
    return np.where(med <= max_steps, med, np.nan)


def ranksum_pvalues(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided Wilcoxon rank-sum test between two strategies, per threshold.

    Parameters
    ----------
    a, b : (n, k) and (m, k) int ndarrays
        Observations to each of ``k`` thresholds (:func:`samples_to_threshold`), one row per
        experiment of each strategy.

    Returns
    -------
    statistic, pvalue : (k,) ndarrays
        ``statistic < 0`` when ``a`` needed fewer observations than ``b``. Identical samples give
        statistic 0 and p-value 1.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    res = _sps.ranksums(a, b, axis=0)
    stat = np.nan_to_num(np.asarray(res.statistic, float), nan=0.0)
    p = np.nan_to_num(np.asarray(res.pvalue, float), nan=1.0)
    return stat, p


def entropy_curves(entropy: np.ndarray) -> dict[str, np.ndarray]:
    """Mean and quartiles (each (T,)) of the posterior entropy (n, T) in nats (Fig. 6)."""
    e = np.asarray(entropy, float)
    q = np.quantile(e, QUANTILES, axis=0)
    return {"mean": e.mean(axis=0), "q25": q[0], "median": q[1], "q75": q[2]}
