"""Where to touch next: the action-selection strategies of the adaptation (paper Sect. III-E).

A strategy is a plain function registered by name in :data:`STRATEGIES`, one module per strategy,
each with its own options::

    fn(ctx: Context, rng: numpy.random.Generator) -> (2,) ndarray   # the next action, pad px

It sees the robot's side only (:class:`Context`, :mod:`~kbcli.core.adaptation.strategies.base`):
the current posterior, the rasterised model, the working area and the model's class boundaries,
never the true pose. Registered, in this order: ``random`` (the paper's baseline), ``active``,
``paper-active`` (the paper's) and ``infogain`` (ours: the largest expected information gain).
"""

from __future__ import annotations

from kbcli.core.adaptation.strategies.base import STRATEGIES, Context

# isort: split
# registration order is the order ``--help`` and error messages list the strategies in
from kbcli.core.adaptation.strategies import random as _random  # noqa: F401  registers "random"

# isort: split
from kbcli.core.adaptation.strategies import active as _active  # noqa: F401  registers "active"

# isort: split
from kbcli.core.adaptation.strategies import paper_active as _paper  # noqa: F401

# isort: split
from kbcli.core.adaptation.strategies import infogain as _infogain  # noqa: F401
from kbcli.core.adaptation.strategies.predictive import (
    entropy_rows,
    information_gain,
    outcome_distribution,
)

__all__ = ["STRATEGIES", "Context", "entropy_rows", "information_gain", "outcome_distribution"]
