"""The exploration strategies' registry, their one signature (:data:`Strategy`) and the
exploration's config.

A strategy registers under its name in :data:`STRATEGIES` with its own options
(``traits={"options": ...}``, a :class:`~kbcli.core.options.Options`); one that reaches around its
samples takes :class:`Covering`'s, and its cover is bounded first.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from pydantic import model_validator

from kbcli.core.config import Config, Count, Positive
from kbcli.core.model.classes import DEFAULT_MODEL_CLASS, model_choice, route_options
from kbcli.core.options import Options, part_field, route
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
#: The field of :class:`ExploreConfig` that chooses the strategy and carries its options.
SLOTS = {"strategy": (STRATEGIES, "active")}


class Covering(Options):
    """Options of a strategy that covers the working area: ``explore_radius``, the radius (px)
    within which every point of the area gets a reach (bounded by :func:`check_cover`)."""

    what: ClassVar[str] = "exploration strategy"
    explore_radius: Positive = 20.0


class ExploreConfig(Config):
    """How exploration proceeds.

    Parameters
    ----------
    strategy : Options
        A strategy of :data:`STRATEGIES` with its own options (``active``'s and ``balanced``'s
        ``explore_radius``); a name, a table or its options given flat beside it are read, and an
        option the strategy does not take is refused by it.
    budget : int
        Number of reaches.
    batch : int
        Reaches proposed per model refit.
    model_class : Options
        The model fitted to the samples (:data:`kbcli.core.model.classes.MODEL_CLASSES`), with
        the options of its own that are set (a name or a table; given flat beside it too): the
        ``active`` strategy bisects its boundary bands, whatever the class. ``auto``: the
        exploration starts with :func:`kbcli.core.model.select.explore_class` and re-chooses the class
        it refits every :data:`kbcli.core.model.select.RESELECT` reaches
        (:func:`kbcli.core.model.select.explore_choice`); the final class is chosen by cross-validation
        once the samples are in (:func:`kbcli.core.model.select.choose`).
    """

    what: ClassVar[str] = "explore"

    strategy: part_field(STRATEGIES, "active") = "active"
    budget: Count = 800
    batch: Count = 10
    model_class: model_choice(DEFAULT_MODEL_CLASS) = DEFAULT_MODEL_CLASS

    @model_validator(mode="before")
    @classmethod
    def _part(cls, data: Any) -> Any:
        """The strategy's and the model class's options given flat go to them
        (:func:`kbcli.core.options.route`)."""
        if not isinstance(data, dict):
            return data
        return route_options(route(data, SLOTS, cls.model_fields), cls.model_fields,
                             DEFAULT_MODEL_CLASS)
