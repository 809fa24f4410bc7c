"""The strategies' registry, what a strategy may look at, and the options they share.

A strategy is a plain function registered by name in :data:`STRATEGIES`
(``@STRATEGIES.register(name, traits={"options": ...})``)::

    fn(ctx: Context, rng: numpy.random.Generator) -> (2,) ndarray   # the next action, pad px
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kbcli.core.adaptation.fields import MAX_CANDIDATES
from kbcli.core.adaptation.posteriors.posterior import Posterior
from kbcli.core.config import Whole, between
from kbcli.core.model.table import LikelihoodTable
from kbcli.core.options import Options
from kbcli.core.registry import Registry

StrategyFn = Callable[["Context", np.random.Generator], np.ndarray]

#: The adaptation strategies (``--strategy``), read with ``STRATEGIES.get(name)``.
STRATEGIES: Registry[StrategyFn] = Registry("strategy")


@dataclass
class Context:
    """What a strategy may look at.

    Attributes
    ----------
    posterior : Posterior
    table : LikelihoodTable
        The model, rasterised (reference frame).
    area : tuple of float
        (xmin, ymin, xmax, ymax) where actions may go.
    edges, corners : (n, 2) ndarrays
        The model's class boundaries in the reference frame (:meth:`LikelihoodTable.boundary_points`).
    cfg : AdapterConfig
        The adapter config; the strategy's own options are ``cfg.strategy`` (:attr:`options`).
    touched : (k, 2) ndarray
        Where the touches so far were read (felt positions).
    redundancy_radius : float
        Touches within this radius (px) count as one spot (0: off; ``AdapterConfig``).
    sampler : object
        Draws actions from p(action | sound) (``random`` with ``random_actions = "model"``,
        ``paper-active``).
    simulate, simulate_many : callable
        The adapter's own posterior term of a simulated touch, and of several at once
        (``paper-active``).
    """

    posterior: Posterior
    table: LikelihoodTable
    area: tuple[float, float, float, float]
    edges: np.ndarray
    corners: np.ndarray
    cfg: Any
    touched: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    redundancy_radius: float = 0.0
    #: ``sample_actions(cls, n, rng)``: draws of p(action | sound) (the model or its raster)
    sampler: Any = None
    #: ``simulate(action (2,), cls) -> log term``: the term a touch would multiply the posterior by
    simulate: Callable[[np.ndarray, int], np.ndarray] | None = None
    #: ``simulate_many(actions (k, 2), classes (k,)) -> (k, *grid.shape)``: ``simulate`` of each
    simulate_many: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    #: ``outcome(table, hyp (K, P), weights (K,), actions (M, 2)) -> (pred (M, C), cond (M,))``:
    #: the adapter's own predictive of a touch's outcome when it is not the table's (the
    #: repaired belief, :func:`kbcli.core.adaptation.repair.repair_outcome`); None: ``outcome_distribution``
    outcome: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None

    @property
    def options(self) -> Any:
        """The strategy's own options (``cfg.strategy``: ``candidates``, ...)."""
        return self.cfg.strategy

    @property
    def family(self) -> str:
        return self.posterior.grid.family

    @property
    def centre(self) -> np.ndarray:
        return self.posterior.grid.centre


class Candidates(Options):
    """Options of a strategy that ranks sampled candidate actions.

    Parameters
    ----------
    candidates : int
        Candidate actions per decision.
    """

    candidates: between(Whole, 1, MAX_CANDIDATES) = 256


class Kept(Candidates):
    """Options of a strategy that keeps the most confusing candidates: ``active_keep`` of them."""

    active_keep: between(Whole, 1, MAX_CANDIDATES) = 8
