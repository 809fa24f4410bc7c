"""Credible regions of the posterior over the translation.

The region reported is the disc around the estimate holding ``level`` of the posterior mass: its
radius ``r_level`` is the smallest distance (px) from the estimate within which the translation
marginal holds at least ``level``. It *covers* the truth when the true translation lies within
``r_level`` of the estimate.
"""

from __future__ import annotations

import numpy as np

#: The credible level reported by default.
LEVEL = 0.9


def radius_of(dx: np.ndarray, dy: np.ndarray, probs: np.ndarray, centre: np.ndarray,
              level: float = LEVEL) -> float:
    """The radius (px) of the disc around ``centre`` holding ``level`` of the mass.

    Parameters
    ----------
    dx, dy : (n,), (m,) ndarrays
        The grid's translation axes.
    probs : (m, n) ndarray
        The translation marginal (rows dy, columns dx), summing to one.
    centre : (2,) ndarray
        ``(dx, dy)`` (a longer vector's last two entries).
    level : float
        In (0, 1].

    Returns
    -------
    float
        0 when the centre's own cell holds ``level``.
    """
    if not 0.0 < level <= 1.0:
        raise ValueError(f"level must lie in (0, 1], got {level!r}")
    c = np.asarray(centre, float)[-2:]
    d = np.hypot(dx[None, :] - c[0], dy[:, None] - c[1]).ravel()
    order = np.argsort(d, kind="stable")
    mass = np.cumsum(np.asarray(probs, float).ravel()[order])
    i = int(np.searchsorted(mass, level * mass[-1] - 1e-12))
    return float(d[order[min(i, len(order) - 1)]])


def radius(posterior, centre: np.ndarray, level: float = LEVEL) -> float:
    """:func:`radius_of` for a :class:`~kbcli.core.adaptation.posteriors.posterior.Posterior` (angles summed out)."""
    g = posterior.grid
    return radius_of(g.dx, g.dy, posterior.translation_marginal(), centre, level)


def covers(posterior, centre: np.ndarray, truth: np.ndarray, level: float = LEVEL) -> bool:
    """Whether the ``level`` disc around ``centre`` holds the true translation ``truth``: whether
    the grid cell nearest the truth (a cell stands for its box) is among the disc's cells."""
    g = posterior.grid
    t, c = np.asarray(truth, float)[-2:], np.asarray(centre, float)[-2:]
    ix = int(np.clip(np.rint((t[0] - g.dx[0]) / g.resolution), 0, len(g.dx) - 1))
    iy = int(np.clip(np.rint((t[1] - g.dy[0]) / g.resolution), 0, len(g.dy) - 1))
    cell = np.array([g.dx[ix], g.dy[iy]])
    return bool(np.hypot(*(cell - c)) <= radius(posterior, c, level) + 1e-9)
