"""The max-margin line between two sets of points in the plane: the hard-margin linear SVM, solved
exactly in 2-D as the perpendicular bisector of the closest points of the two convex hulls
(:func:`separating_line`), with a tolerance for label noise."""

from __future__ import annotations

import numpy as np


def convex_hull(p: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of 2-D points, counter-clockwise (Andrew's monotone chain)."""
    pts = np.unique(np.asarray(p, float), axis=0)  # sorted by x, then y
    if len(pts) <= 2:
        return pts

    def half(seq: np.ndarray) -> list[np.ndarray]:
        h: list[np.ndarray] = []
        for q in seq:  # a few points per boundary piece
            while len(h) >= 2 and (
                (h[-1][0] - h[-2][0]) * (q[1] - h[-2][1])
                - (h[-1][1] - h[-2][1]) * (q[0] - h[-2][0]) <= 0
            ):
                h.pop()
            h.append(q)
        return h

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _closest_to_segments(p: np.ndarray, hull: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point, the nearest point of a convex polygon's boundary (vertices or edges).

    Returns
    -------
    dist : (n,) ndarray
    foot : (n, 2) ndarray
    """
    a = hull
    b = np.roll(hull, -1, axis=0) if len(hull) > 1 else hull
    ab = b - a  # (e, 2)
    ll = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    t = np.clip(np.einsum("ned,ed->ne", p[:, None, :] - a[None], ab) / ll, 0.0, 1.0)
    foot = a[None] + t[..., None] * ab[None]  # (n, e, 2)
    d = np.hypot(*(p[:, None, :] - foot).transpose(2, 0, 1))
    k = np.argmin(d, axis=1)
    r = np.arange(len(p))
    return d[r, k], foot[r, k]


def separating_line(a: np.ndarray, b: np.ndarray, tol: float = 0.0) -> tuple[np.ndarray, bool]:
    """Max-margin line between points ``a`` (its positive side) and ``b``.

    For separable sets it is the perpendicular bisector of the closest pair of points of their
    convex hulls (the hard-margin linear SVM, solved exactly in 2-D). With a label-noise tolerance
    ``tol`` > 0 (px), sets that no line separates get a soft-margin line (logistic regression),
    which counts as separating when every point on its wrong side is within ``tol`` of it: labels
    flipped near a boundary by an arm that does not feel exactly where it touched then give one
    straight boundary, not a splinter of pieces.

    Returns
    -------
    line : (3,) ndarray
        (nx, ny, c), unit normal towards ``a``: signed distance ``n . x - c``.
    separable : bool
        Whether the line puts every point of ``a`` and ``b`` strictly on its own side.
    """
    ha, hb = convex_hull(a), convex_hull(b)
    da, fa = _closest_to_segments(ha, hb)  # a's vertices to b's hull
    db, fb = _closest_to_segments(hb, ha)
    if da.min() <= db.min():
        i = int(np.argmin(da))
        p, q = ha[i], fa[i]
    else:
        i = int(np.argmin(db))
        p, q = fb[i], hb[i]
    w = p - q
    nw = float(np.hypot(*w))
    if nw < 1e-12:  # touching or overlapping: fall back to the direction between the means
        w = a.mean(axis=0) - b.mean(axis=0)
        nw = max(float(np.hypot(*w)), 1e-12)
        p, q = a.mean(axis=0), b.mean(axis=0)
    n = w / nw
    c = float(n @ (p + q) / 2)
    separable = bool((a @ n - c > 0).all() and (b @ n - c < 0).all())
    if separable or tol <= 0:
        return np.array([n[0], n[1], c]), separable
    n, c = _soft_line(a, b)
    separable = bool((a @ n - c > -tol).all() and (b @ n - c < tol).all())
    return np.array([n[0], n[1], c]), separable


def _soft_line(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit normal (towards ``a``) and offset of a logistic-regression line between two point
    sets that overlap (deterministic: lbfgs, centred and scaled coordinates)."""
    from sklearn.linear_model import LogisticRegression

    pts = np.vstack([a, b])
    mu = pts.mean(axis=0)
    scale = max(float(pts.std()), 1e-9)
    y = np.r_[np.ones(len(a)), np.zeros(len(b))]
    clf = LogisticRegression(C=10.0).fit((pts - mu) / scale, y)
    w = clf.coef_[0] / scale
    nw = max(float(np.hypot(*w)), 1e-12)
    n = w / nw
    c = float(n @ mu - clf.intercept_[0] / nw)
    return n, c
