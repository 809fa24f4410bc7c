"""Held-out touches: the folds of a cross-validation, a fold model's predictions in the full
model's classes, and the weights that make held-out touches stand for the working area.

:func:`area_weights` weights each touch by the area it stands for (active exploration puts most
near boundaries); :func:`distance_weights` by the density ratio of its distance to its fold's
samples (a held-out touch is further from them than a point of the pad is from the full model's).
Neither uses the keyboard.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kbcli.core.model.sounds import classify_features

#: Width (px) of the bins of the distance to the nearest sample for :func:`distance_weights`.
DISTANCE_BIN_PX = 4.0


def area_weights(x: np.ndarray, k: int = 6) -> np.ndarray:
    """(n,) weights summing to one that make the samples stand for the working area evenly.

    Active exploration puts most touches near boundaries; a held-out touch there is harder than a
    random point of the pad. Weighting each sample by the area it stands for (the squared distance
    to its ``k``-th nearest neighbour, an inverse density) removes that bias from the estimates.
    """
    n = len(x)
    if n <= k:
        return np.full(n, 1.0 / max(n, 1))
    d, _ = cKDTree(x).query(x, k=k + 1)
    w = d[:, -1] ** 2
    w = np.maximum(w, 1e-12)
    return w / w.sum()


def distance_weights(x: np.ndarray, fold: np.ndarray, grid: np.ndarray,
                      bin_px: float = DISTANCE_BIN_PX) -> np.ndarray:
    """(n,) weights summing to one that give held-out touches the distance profile of the area.

    Parameters
    ----------
    x : (n, 2) ndarray
        The samples.
    fold : (n,) int ndarray
        Fold of each sample.
    grid : (m, 2) ndarray
        Points spread evenly over the working area.

    Returns
    -------
    (n,) ndarray
        For each sample, ``P_grid(d in b) / P_held(d in b)`` of the bin ``b`` of its distance to
        the nearest sample of the other folds (bins ``bin_px`` wide), normalised; ``P_grid`` is
        the share of grid points whose distance to the nearest sample (any fold) is in ``b``.
        Equal weights when there is a single fold.
    """
    n = len(x)
    d = np.full(n, np.nan)
    for f in np.unique(fold):
        test = fold == f
        if test.all():
            return np.full(n, 1.0 / max(n, 1))
        d[test] = cKDTree(x[~test]).query(x[test])[0]
    dg = cKDTree(x).query(grid)[0]
    bh, bg = (d // bin_px).astype(np.int64), (dg // bin_px).astype(np.int64)
    nb = int(max(bh.max(), bg.max())) + 1
    p_held = np.bincount(bh, minlength=nb) / n
    p_grid = np.bincount(bg, minlength=nb) / len(dg)
    w = p_grid[bh] / p_held[bh]
    total = w.sum()
    return w / total if total > 0 else np.full(n, 1.0 / n)


def fold_ids(n: int, folds: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) the fold of each sample: ``folds`` folds of (nearly) equal size, shuffled."""
    return rng.permutation(np.arange(n) % folds)


def class_map(fold_features: np.ndarray, full_features: np.ndarray, threshold: float) -> np.ndarray:
    """(C_fold,) the full model's class of each of a fold model's classes (-1: none matches)."""
    out = classify_features(fold_features, full_features, threshold)
    out[0] = 0  # silence is silence
    return out


def held_out_probs(model, x: np.ndarray, cmap: np.ndarray, n_full: int) -> np.ndarray:
    """(n, n_full) a fold model's predictions in the full model's classes."""
    p = model.predict_proba(x)
    out = np.zeros((len(x), n_full))
    ok = cmap >= 0
    np.add.at(out.T, cmap[ok], p[:, ok].T)
    return out
