"""``balanced``: boundary seeking and coverage weighed in one greedy rule, instead of
``active``'s cover-then-bisect (not the default; why: ``docs/design-notes.md``, Model classes)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kbcli.core.model.explore.base import STRATEGIES, Covering
from kbcli.core.model.explore.cover import (
    boundary_sites,
    cover_candidates,
    farthest_points,
    hex_lattice,
)


@STRATEGIES.register("balanced", traits={"options": Covering})
def balanced_strategy(exploration, n: int, rng: np.random.Generator) -> np.ndarray:
    """Boundary seeking and coverage weighed in one rule, instead of ``active``'s
    cover-then-bisect.

    First a coarse hexagonal lattice (covering radius ``2 explore_radius``). Then every batch picks,
    greedily, the widest gap: a boundary site of the model (its band width w, capped as ``active``
    caps it) or a hole, a point at distance d from every landing, worth ``2 d``. A pick of width w
    caps every site's width at ``w / 2 + distance`` and every hole's at ``2 distance``.
    """
    taken, area, cfg = exploration.landed, exploration.area, exploration.cfg.strategy
    if len(taken) == 0:
        lattice = hex_lattice(area, 2 * cfg.explore_radius * np.sqrt(3), rng)
        return farthest_points(lattice, np.empty((0, 2)), len(lattice))
    tree = cKDTree(taken)
    holes = cover_candidates(area, cfg.explore_radius / 5, rng)
    hw = 2 * tree.query(holes)[0]
    p, w = np.empty((0, 2)), np.empty(0)
    model = exploration.model
    if model is not None and model.n_classes >= 2:
        p, w = boundary_sites(model, area, tree, rng)
    pts = np.vstack([p, holes])
    width = np.concatenate([w, hw])
    is_hole = np.r_[np.zeros(len(p), bool), np.ones(len(holes), bool)]
    picks = []
    for _ in range(min(n, len(pts))):  # loop over picks; each is vectorized over the candidates
        i = int(np.argmax(width))
        picks.append(pts[i])
        dist = np.hypot(*(pts - pts[i]).T)
        width = np.where(is_hole, np.minimum(width, 2 * dist),
                         np.minimum(width, width[i] / 2 + dist))
    return np.array(picks)
