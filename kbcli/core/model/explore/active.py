"""``active``: cover the working area, then bisect the widest boundary band.

1. *Cover.* First a hexagonal lattice of spacing ``explore_radius * sqrt(3)`` (randomly shifted
   and turned, visited in farthest-point order), whose covering radius is ``explore_radius``;
   then, while some point of the working area is further than ``explore_radius`` from every
   landing (near the area's border), the furthest such point. A sound region nobody has heard
   holds an empty disc, so covering to radius r finds every region that contains a disc of
   radius r (a 50 px key holds one of 25 px), with about area / (2.6 r^2) reaches.
2. *Bisect the widest boundary band.* Every model class (:mod:`kbcli.core.model.classes`)
   reports its predictive uncertainty as ``boundary_sites``: points on the boundaries it predicts
   between sounds, each with the width (px) of the band the boundary could lie in there, where the
   model cannot tell which sound an action makes (the paper's confusion factor, Sect. III-E:
   p(i | a) is neither 0 nor 1 there). ``lines`` (:mod:`kbcli.core.model.lines`) places each
   boundary on a straight line that must pass between the samples heard on either side, the band
   between their hulls, with sites every 1 px along every boundary piece (and 25 px past its
   ends); ``svc`` (:mod:`kbcli.core.model.svc`) puts its sites where its machines change sign, the
   band between the nearest samples of either sound. The next target is the site with the widest
   band (capped at twice the distance to the nearest landing: a reach already made there said what
   it could). A batch is chosen greedily: after a pick of width w every site's width is capped at
   w / 2 + its distance to the pick.

Why: the misclassified area along a boundary is its band width integrated along it, so the most
useful reach is where the band is widest; a reach in the middle of the band lands on one side or
the other and halves the band there (bisection), and because one line is fitted to all the samples
along an edge (and along edges that continue each other, across keys), a few bisections at the
ends of a long edge pin it down everywhere. Random reaches spend most of the budget inside regions
whose sound is already known (``kbcli bench learn`` compares the two).
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
