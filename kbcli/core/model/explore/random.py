"""``random``: targets uniform over the working area, the baseline."""

from __future__ import annotations

import numpy as np

from kbcli.core.model.explore.base import STRATEGIES
from kbcli.core.model.explore.cover import uniform


@STRATEGIES.register("random", traits={"baseline": True})
def random_strategy(exploration, n: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform targets over the working area (the baseline)."""
    return uniform(exploration.area, n, rng)
