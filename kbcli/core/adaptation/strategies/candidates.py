"""Where candidate actions come from: uniform over the working area, sampled from the model as
Algorithm 1 plays, or on the model's class boundaries carried into the pad by a hypothesis."""

from __future__ import annotations

import numpy as np

from kbcli.core.adaptation.strategies.base import Context
from kbcli.core.instrument import transforms
from kbcli.core.instrument.transforms import FAMILIES


def uniform_actions(area: tuple[float, float, float, float], n: int,
                    rng: np.random.Generator) -> np.ndarray:
    """(n, 2) uniform points over ``area``."""
    x0, y0, x1, y1 = area
    return rng.uniform((x0, y0), (x1, y1), size=(n, 2))


def clip(area: tuple[float, float, float, float], pts: np.ndarray) -> np.ndarray:
    """``pts`` (n, 2) clipped into ``area``."""
    x0, y0, x1, y1 = area
    return np.clip(pts, (x0, y0), (x1, y1))


def model_actions(ctx: Context, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) actions sampled from the model as Algorithm 1 plays: a sound uniform over the model's
    sounds (silence excluded: the robot plays notes), then an action from p(action | sound)
    (``ctx.sampler``), clipped to the working area."""
    c = ctx.table.n_classes
    if c < 2:
        return uniform_actions(ctx.area, n, rng)
    cls = rng.integers(1, c, size=n)
    out = np.empty((n, 2))
    for k in np.unique(cls):  # one draw per sound heard, in class order
        sel = np.flatnonzero(cls == k)
        out[sel] = ctx.sampler.sample_actions(int(k), len(sel), rng)
    return clip(ctx.area, out)


def boundary_candidates(ctx: Context, n_edges: int, n_corners: int, hyp: np.ndarray,
                        weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Model edge and corner points carried into the pad by hypotheses drawn from ``weights``.

    Returns
    -------
    (n, 2) ndarray, n <= n_edges + n_corners (fewer when the model has no edges or corners).
    """
    src = []
    if len(ctx.edges) and n_edges > 0:
        src.append(ctx.edges[rng.integers(len(ctx.edges), size=n_edges)])
    if len(ctx.corners) and n_corners > 0:
        src.append(ctx.corners[rng.integers(len(ctx.corners), size=n_corners)])
    if not src:
        return np.empty((0, 2))
    pts = np.vstack(src)
    h = hyp[rng.choice(len(hyp), size=len(pts), p=weights)]
    # put the boundary half a cell off the hypothesis, between grid cells: then every cell lies
    # cleanly on one side and the cell nearest the truth always agrees with the outcome
    h = h.copy()
    h[:, -2:] += rng.choice([-0.5, 0.5], size=(len(h), 2)) * ctx.posterior.grid.resolution
    if not FAMILIES.get(ctx.family).rotates:
        out = pts + h
    else:
        out = transforms.apply_many(ctx.family, h, pts[:, None, :], ctx.centre)[:, 0, :]
    return clip(ctx.area, out)
