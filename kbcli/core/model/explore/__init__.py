"""Exploration: where to reach next to learn the instrument model (paper ref. [11]).

A strategy proposes the next reach targets from what has been heard so far; :class:`Exploration`
(:mod:`~kbcli.core.model.explore.loop`) runs the loop (propose, touch, refit) as an iterator that
yields one batch at a time. Strategies (:data:`STRATEGIES`, one signature, :data:`Strategy`), one
module each: ``active`` (cover the working area, then bisect the widest boundary band),
``balanced`` (coverage and boundary seeking in one greedy rule) and ``random`` (the baseline).
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
