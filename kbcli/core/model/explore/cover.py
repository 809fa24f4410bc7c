"""Where exploration reaches go: uniform targets, a hexagonal lattice, the farthest of a set of
candidates, the holes of a cover and the widest places of the model's boundary bands."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def uniform(area: tuple, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) targets uniform over ``area``."""
    x0, y0, x1, y1 = area
    return rng.uniform((x0, y0), (x1, y1), size=(n, 2))


def farthest_points(candidates: np.ndarray, taken: np.ndarray, n: int) -> np.ndarray:
    """Greedy max-min picks: each time the candidate furthest from ``taken`` and earlier picks.

    Parameters
    ----------
    candidates : (m, 2) ndarray
    taken : (k, 2) ndarray
    n : int

    Returns
    -------
    (min(n, m), 2) ndarray
    """
    if len(candidates) == 0:
        return np.empty((0, 2))
    if len(taken):
        d = cKDTree(taken).query(candidates)[0]
    else:
        d = np.full(len(candidates), np.inf)
    picks = []
    for _ in range(min(n, len(candidates))):  # loop over picks; each is vectorized over candidates
        i = int(np.argmax(d))
        picks.append(candidates[i])
        d = np.minimum(d, np.hypot(*(candidates - candidates[i]).T))
    return np.array(picks)


def hex_lattice(area: tuple, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """(m, 2) points of a hexagonal lattice over ``area``, randomly shifted and rotated.

    Its covering radius is ``spacing / sqrt(3)``: every point of the plane is that close to a node.
    """
    x0, y0, x1, y1 = area
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    r = np.hypot(x1 - x0, y1 - y0) / 2 + spacing
    n = int(np.ceil(r / spacing)) + 1
    i, j = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1))
    p = np.column_stack([(i + 0.5 * j).ravel(), (j * np.sqrt(3) / 2).ravel()]) * spacing
    a = rng.uniform(0, np.pi / 3)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    p = p @ rot.T + c + rng.uniform(-spacing / 2, spacing / 2, size=2)
    inside = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    return p[inside]


def cover_candidates(area: tuple, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """(m, 2) jittered grid points every ``spacing`` px over ``area``."""
    x0, y0, x1, y1 = area
    xs = np.arange(x0 + spacing / 2, x1, spacing)
    ys = np.arange(y0 + spacing / 2, y1, spacing)
    g = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    g = g + rng.uniform(-spacing / 2, spacing / 2, size=g.shape)
    return np.clip(g, (x0, y0), (x1, y1))




def boundary_sites(model, area: tuple, tree: cKDTree,
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The model's boundary sites inside ``area`` and their band widths (px), each width capped at
    twice the distance to the nearest landing (``tree``: a reach right next to a site already told
    what it could there).

    Returns
    -------
    points : (m, 2) ndarray
    width : (m,) ndarray
    """
    sites = model.boundary_sites(step=1.0, phase=float(rng.uniform()))
    x0, y0, x1, y1 = area
    p, w = sites["points"], sites["width"]
    inside = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    p, w = p[inside], w[inside]
    return p, (np.minimum(w, 2 * tree.query(p)[0]) if len(p) else w)
