"""Sound discovery: which sounds the exploration heard, and which of them are neighbours.

From the perceived features alone, the sound classes by leader clustering with the matching
threshold of Eq. 2 (:func:`discover_classes`; class 0 is silence, the others sorted by their
features); two sounds are neighbours where a Delaunay edge of the samples joins them
(:func:`straddling_edges`): the start of every learned model class.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree

from kbcli.core.instrument.keyboard import match
from kbcli.errors import ConfigError

#: Class id of silence.
SILENCE = 0
#: Class id of a sound that matches no class.
UNKNOWN = -1


def classify_features(
    perceived: np.ndarray, class_features: np.ndarray, threshold: float
) -> np.ndarray:
    """Class of each perceived sound: 0 for silence (NaN), -1 when no class is within ``threshold``.

    Parameters
    ----------
    perceived : (n, D) ndarray
    class_features : (C, D) ndarray, row 0 (silence) is ignored
    """
    perceived = np.atleast_2d(np.asarray(perceived, float))
    silent = np.isnan(perceived).all(axis=1)
    m = match(perceived, class_features[1:], threshold)
    out = np.where(m >= 0, m + 1, UNKNOWN)
    out[silent] = SILENCE
    return out


def discover_classes(perceived: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Sound classes from perceived features by leader clustering (Eq. 2 threshold): a sound
    further than the threshold from every class so far opens a new one; classes whose mean sounds
    end up within the threshold are merged.

    Parameters
    ----------
    perceived : (n, D) ndarray
        Perceived features; an all-NaN row is silence.
    threshold : float
        Manhattan distance within which a sound joins a class's leader.

    Returns
    -------
    class_features : (C, D) ndarray
        Row 0 is silence (NaN); rows 1.. the mean features of each class, sorted.
    labels : (n,) int ndarray
        Class of each sample.
    """
    s = np.atleast_2d(np.asarray(perceived, float))
    n, dim = s.shape
    silent = np.isnan(s).any(axis=1)
    lead = np.full(n, -1, dtype=np.int64)
    means: list[np.ndarray] = []
    todo = ~silent
    while todo.any():  # one pass per class, vectorized over the samples
        first = int(np.flatnonzero(todo)[0])
        near = todo & (np.abs(s - s[first]).sum(axis=1) < threshold)
        lead[near] = len(means)
        means.append(s[near].mean(axis=0))
        todo &= ~near
    if not means:
        return np.full((1, dim), np.nan), np.zeros(n, dtype=np.int64)
    centres, counts = np.array(means), np.bincount(lead[~silent])
    while len(centres) > 1:  # merge classes whose mean sounds are within the threshold
        d = np.abs(centres[:, None, :] - centres[None, :, :]).sum(axis=-1)
        d[np.diag_indices(len(d))] = np.inf
        i, j = np.unravel_index(np.argmin(d), d.shape)
        if d[i, j] >= threshold:
            break
        i, j = min(i, j), max(i, j)
        centres[i] = (counts[i] * centres[i] + counts[j] * centres[j]) / (counts[i] + counts[j])
        counts[i] += counts[j]
        centres, counts = np.delete(centres, j, axis=0), np.delete(counts, j)
        lead[lead == j] = i
        lead[lead > j] -= 1
    order = np.lexsort(centres.T[::-1])
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    features = np.vstack([np.full((1, dim), np.nan), centres[order]])
    labels = np.zeros(n, dtype=np.int64)
    labels[~silent] = rank[lead[~silent]] + 1
    # settle each sample on its nearest class centre (a leader may sit at its class's edge)
    again = classify_features(s[~silent], features, threshold)
    labels[~silent] = np.where(again > 0, again, labels[~silent])
    return features, labels


def prepare_samples(
    actions: np.ndarray, perceived: np.ndarray, targets: np.ndarray | None, threshold: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Check exploration samples and find their sound classes (the start of every model's fit).

    Parameters
    ----------
    actions : (n, 2) array_like
        Where the finger landed (proprioception); finite, at least one.
    perceived : (n, D) array_like
        What was heard there (NaN rows: silence).
    targets : (n, 2) array_like or None
        Where the reaches aimed.
    threshold : float
        Eq. 2's matching threshold (:func:`discover_classes`).

    Returns
    -------
    x : (n, 2) ndarray
    features : (C, D) ndarray
    labels : (n,) ndarray
        As :func:`discover_classes`.
    reach_sd : float
        Per-axis rms of landed minus aimed (~0 for an ideal arm; 0 without ``targets``).

    Raises
    ------
    ConfigError
        No sample, or a non-finite action.
    """
    x = np.asarray(actions, float).reshape(-1, 2)
    if len(x) < 1:
        raise ConfigError("fit needs at least one sample")
    if not np.isfinite(x).all():
        raise ConfigError("actions must be finite")
    s = np.asarray(perceived, float).reshape(len(x), -1)
    features, labels = discover_classes(s, threshold)
    reach_sd = 0.0
    if targets is not None:
        d = x - np.asarray(targets, float).reshape(-1, 2)
        reach_sd = float(np.sqrt(np.mean(d * d)))
    return x, features, labels, reach_sd


def straddling_edges(points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(m, 2) Delaunay edges joining samples of two different sounds, lower class's end first.

    An edge is dropped when a sample of a third sound lies inside the circle on the edge as
    diameter (the segment may then pass through that sound's region, so its two ends need not
    be neighbours across one boundary).
    """
    n = len(points)
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    try:
        tri = Delaunay(points)
        s = tri.simplices
        e = np.vstack([s[:, [0, 1]], s[:, [1, 2]], s[:, [0, 2]]])
    except (QhullError, ValueError):  # fewer than 3 points, or all on a line
        i, j = np.triu_indices(n, 1)
        e = np.column_stack([i, j])
    e = np.unique(np.sort(e, axis=1), axis=0)
    e = e[labels[e[:, 0]] != labels[e[:, 1]]]
    if len(e) == 0:
        return np.empty((0, 2), dtype=np.int64)
    mid = (points[e[:, 0]] + points[e[:, 1]]) / 2
    r = np.hypot(*(points[e[:, 0]] - points[e[:, 1]]).T) / 2
    k = min(12, n)
    d, idx = cKDTree(points).query(mid, k=k)
    d, idx = d.reshape(len(e), k), idx.reshape(len(e), k)
    third = (labels[idx] != labels[e[:, :1]]) & (labels[idx] != labels[e[:, 1:]])
    e = e[~(third & (d < r[:, None] * (1 - 1e-9))).any(axis=1)]
    flip = labels[e[:, 0]] > labels[e[:, 1]]
    e[flip] = e[flip][:, ::-1]
    return e
