"""The likelihood term of one observation (ours, the default posterior; paper Sect. III-D).

``log p_eps(s_t | T_h^-1(a_t))`` for every cell h of the hypothesis grid, read from a
:class:`~kbcli.core.model.table.LikelihoodTable`: over a translation grid, one vectorised gather.
For the rigid family, where one angle step moves a far key by more than a raster cell, the term is
*cell-averaged* (a cell stands for a box of hypotheses, not a point): the map of the heard class is
blurred by the spread of ``T_h^-1(a_t)`` within one cell (:func:`cell_sigma`) and read on a raster
of half the grid step.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter

from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.model.table import LikelihoodTable


def inverse_coords(grid: HypothesisGrid, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of ``T_h^-1(action)`` for every cell, each broadcastable to ``grid.shape``."""
    a = np.asarray(action, float)
    if not grid.rigid:
        return (a[0] - grid.dx)[None, :], (a[1] - grid.dy)[:, None]
    th = np.deg2rad(grid.angles)[:, None, None]
    c, s = np.cos(th), np.sin(th)
    u = a - grid.centre  # T^-1(a) = R(-th)(a - centre - d) + centre
    dx = grid.dx[None, None, :]
    dy = grid.dy[None, :, None]
    ex = (u[0] - dx).astype(np.float32)
    ey = (u[1] - dy).astype(np.float32)
    c32, s32 = c.astype(np.float32), s.astype(np.float32)
    x = c32 * ex + s32 * ey
    x += np.float32(grid.centre[0])
    y = c32 * ey - s32 * ex
    y += np.float32(grid.centre[1])
    return x, y


def cell_sigma(grid: HypothesisGrid, action: np.ndarray) -> float:
    """Std (px) of ``T_h^-1(action)`` over one grid cell (uniform within the cell).

    A cell stands for a box of hypotheses, not a point: its translation spans ``resolution`` px on
    each axis (std ``resolution / sqrt(12)``) and, for the rigid family, its angle spans
    ``angle_resolution``, which moves the point by ``r * dtheta`` tangentially, with ``r`` the
    distance of the action from the rotation centre.
    """
    var = grid.resolution**2 / 12
    if grid.rigid and len(grid.angles) > 1:
        r = float(np.hypot(*(np.asarray(action, float) - grid.centre)))
        var += (r * np.deg2rad(grid.angles[1] - grid.angles[0])) ** 2 / 12
    return math.sqrt(var)


def likelihood_term(grid: HypothesisGrid, table: LikelihoodTable, action: np.ndarray,
                    cls: int, sigma: float = 0.0) -> np.ndarray:
    """``log p_eps(cls | T_h^-1(action))`` for every cell h: an array of ``grid.shape``.

    Parameters
    ----------
    sigma : float
        Std (px) of an isotropic Gaussian the model's map is blurred by before it is read (the
        cell-averaged likelihood, see :func:`cell_sigma`). Below half a raster cell it is ignored
        and the raster is read as it is.
    """
    x, y = inverse_coords(grid, action)
    if sigma < 0.5 * table.step:
        return np.broadcast_to(table.log_prob(x, y, cls), grid.shape)
    pad = 4 * sigma
    x0, x1 = float(np.min(x)) - pad, float(np.max(x)) + pad
    y0, y1 = float(np.min(y)) - pad, float(np.max(y)) + pad
    patch, org = table.window(cls, (x0, y0, x1, y1))
    patch = gaussian_filter(patch, sigma / table.step, mode="nearest", truncate=4.0)
    logpatch = np.log((1 - table.eps) * patch + table.eps / table.n_classes)
    h, w = patch.shape
    col = cell_index(x, org[0], table.step, w)
    row = cell_index(y, org[1], table.step, h)
    return np.broadcast_to(logpatch[row, col], grid.shape)


def cell_index(v: np.ndarray, origin: float, step: float, n: int) -> np.ndarray:
    """Nearest cell index of coordinates ``v`` on an axis of ``n`` cells, clipped into range."""
    u = np.subtract(v, origin, dtype=np.float32 if v.size > 4096 else float)
    u /= step
    np.rint(u, out=u)
    idx = u.astype(np.intp)
    np.clip(idx, 0, n - 1, out=idx)
    return idx
