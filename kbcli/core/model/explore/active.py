"""``active``: cover the working area, then bisect the widest boundary band.

1. *Cover.* A hexagonal lattice of spacing ``explore_radius * sqrt(3)`` (randomly shifted and
   turned, visited in farthest-point order), then, while some point of the working area is further
   than ``explore_radius`` from every landing, the furthest such point: every sound region holding
   a disc of radius ``explore_radius`` is heard.
2. *Bisect the widest boundary band.* Every model class reports its predictive uncertainty as
   ``boundary_sites`` (:mod:`kbcli.core.model.classes`): points on its predicted boundaries, each
   with the width (px) of the band the boundary could lie in (the paper's confusion factor, Sect.
   III-E). The next target is the site with the widest band, capped at twice the distance to the
   nearest landing; a batch is chosen greedily, a pick of width w capping every site's width at
   w / 2 + its distance to the pick.

A reach in the middle of a band lands on one side or the other and halves it there, and the
misclassified area along a boundary is its band width integrated along it (``kbcli bench learn``
compares this with random reaches).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kbcli.core.model.explore.base import STRATEGIES, Covering
from kbcli.core.model.explore.cover import (
    boundary_sites,
    cover_candidates,
    farthest_points,
    hex_lattice,
    uniform,
)

#: Uniform candidates from which reaches are spread while no boundary is known.
SPREAD_CANDIDATES = 4000


@STRATEGIES.register("active", traits={"options": Covering})
def active_strategy(exploration, n: int, rng: np.random.Generator) -> np.ndarray:
    """Cover the area to ``explore_radius``, then the widest places of the boundary bands."""
    taken, area, cfg = exploration.landed, exploration.area, exploration.cfg.strategy
    if len(taken) == 0:  # first: a lattice covering the area to explore_radius, spread-out order
        lattice = hex_lattice(area, cfg.explore_radius * np.sqrt(3), rng)
        return farthest_points(lattice, np.empty((0, 2)), len(lattice))
    tree = cKDTree(taken)
    cover = cover_candidates(area, cfg.explore_radius / 5, rng)
    cover = cover[tree.query(cover)[0] > cfg.explore_radius]
    picks = farthest_points(cover, taken, n)
    if len(picks):
        return picks
    model = exploration.model
    if model is None or model.n_classes < 2:
        return farthest_points(uniform(area, SPREAD_CANDIDATES, rng), taken, n)
    p, w = boundary_sites(model, area, tree, rng)
    if len(p) == 0:  # no boundary met yet: keep spreading reaches over the area
        return farthest_points(uniform(area, SPREAD_CANDIDATES, rng), taken, n)
    picks = []
    for _ in range(min(n, len(p))):  # loop over picks; each is vectorized over the sites
        i = int(np.argmax(w))
        picks.append(p[i])
        # the pick will halve the band there; nearby sites gain less the closer they are
        w = np.minimum(w, w[i] / 2 + np.hypot(*(p - p[i]).T))
    return np.array(picks)
