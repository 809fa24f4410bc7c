"""Exploration: where to reach next to learn the instrument model (paper ref. [11]).

The robot learns p(sound, action) by touching the pad and listening. A strategy proposes the next
reach targets from what has been heard so far; :class:`Exploration`
(:mod:`~kbcli.core.model.explore.loop`) runs the loop (propose, touch, refit) as an iterator that
yields one batch at a time.

Strategies (registry :data:`STRATEGIES`, one signature, :data:`Strategy`:
:mod:`~kbcli.core.model.explore.base`), one module each:

``active`` (:mod:`~kbcli.core.model.explore.active`)
    Cover the working area to ``explore_radius``, then bisect the model's widest boundary band.
``balanced`` (:mod:`~kbcli.core.model.explore.balanced`)
    Boundary seeking and coverage weighed in one greedy rule: a coarse cover first, then the
    widest gap, a boundary band or an unexplored hole, whichever is wider.
``random`` (:mod:`~kbcli.core.model.explore.random`)
    Targets uniform over the working area: the baseline.
"""

from __future__ import annotations

from kbcli.core.model.explore.base import (
    MAX_COVER_POINTS,
    STRATEGIES,
    ExploreConfig,
    check_cover,
)

# isort: split
# registration order is the order ``--help`` and error messages list the strategies in
from kbcli.core.model.explore import active as _active  # noqa: F401  registers "active"

# isort: split
from kbcli.core.model.explore import balanced as _balanced  # noqa: F401  registers "balanced"

# isort: split
from kbcli.core.model.explore import random as _random  # noqa: F401  registers "random"
from kbcli.core.model.explore.cover import farthest_points, hex_lattice
from kbcli.core.model.explore.loop import Exploration, ExploreStep

__all__ = ["MAX_COVER_POINTS", "STRATEGIES", "Exploration", "ExploreConfig", "ExploreStep",
           "check_cover", "farthest_points", "hex_lattice"]
