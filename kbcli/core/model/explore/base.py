"""The exploration strategies' registry, their one signature (:data:`Strategy`) and the
exploration's config.

A strategy registers under its name in :data:`STRATEGIES` and declares what it does
(``traits={"covers": True}``: it reaches around its samples, so its cover is bounded first).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import AfterValidator

from kbcli.core.config import Config, Count, Name, Positive
from kbcli.core.model.classes import DEFAULT_MODEL_CLASS, check_choice
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: Most candidate points the cover of the working area may take (``active`` and ``balanced`` grid
#: it every ``explore_radius / 5`` px): a radius so small that it needs more is refused before any
#: reach (``--explore-radius 1e-6`` would allocate without bound).
MAX_COVER_POINTS = 1_000_000


def check_cover(area: tuple, explore_radius: float) -> None:
    """ConfigError when covering ``area`` to ``explore_radius`` takes more than
    :data:`MAX_COVER_POINTS` candidate points, naming the smallest radius that fits."""
    x0, y0, x1, y1 = area
    cells = (x1 - x0) * (y1 - y0)
    points = cells / (explore_radius / 5) ** 2
    if points > MAX_COVER_POINTS:
        least = 5 * float(np.sqrt(cells / MAX_COVER_POINTS))
        raise ConfigError(f"explore_radius {explore_radius:g} px: covering the working area would "
                          f"take {points:,.0f} candidate points, more than {MAX_COVER_POINTS:,}; "
                          f"use at least {least:.2g} px")

#: A strategy: ``(exploration, n, rng) -> (k, 2)`` targets inside ``exploration.area``, usually
#: k = n; more is a plan the exploration carries out over the next batches. It may read
#: ``exploration.targets``, ``.landed``, ``.perceived``, ``.cfg`` and ``.model`` (fitted on demand).
Strategy = Callable[[Any, int, np.random.Generator], np.ndarray]
STRATEGIES: Registry[Strategy] = Registry("exploration strategy")


def _strategy(name: str) -> str:
    return STRATEGIES.check(name)


class ExploreConfig(Config):
    """How exploration proceeds.

    Parameters
    ----------
    strategy : str
        A name in :data:`STRATEGIES`.
    budget : int
        Number of reaches.
    batch : int
        Reaches proposed per model refit.
    explore_radius : float
        ``active``: cover the working area until no point is further than this (px) from a reach.
    n_candidates : int
        ``active``: uniform candidates from which to spread reaches while no boundary is known.
    model_class : str
        The model fitted to the samples (:data:`kbcli.core.model.classes.MODEL_CLASSES`): the
        ``active`` strategy bisects its boundary bands, whatever the class. ``auto``: the
        exploration starts with :func:`kbcli.core.model.select.explore_class` and re-chooses the class
        it refits every :data:`kbcli.core.model.select.RESELECT` reaches
        (:func:`kbcli.core.model.select.explore_choice`); the final class is chosen by cross-validation
        once the samples are in (:func:`kbcli.core.model.select.choose`).
    """

    what: ClassVar[str] = "explore"

    strategy: Annotated[Name, AfterValidator(_strategy)] = "active"
    budget: Count = 800
    batch: Count = 10
    explore_radius: Positive = 20.0
    n_candidates: Count = 4000
    model_class: Annotated[Name, AfterValidator(check_choice)] = DEFAULT_MODEL_CLASS
