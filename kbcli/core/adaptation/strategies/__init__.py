"""Where to touch next: the action-selection strategies of the adaptation (paper Sect. III-E).

A strategy is a plain function registered by name in :data:`STRATEGIES` (the protocol and what
it sees, :class:`Context`: :mod:`~kbcli.core.adaptation.strategies.base`), one module per
strategy, each with its own options::

    fn(ctx: Context, rng: numpy.random.Generator) -> (2,) ndarray   # the next action, pad px

It sees the robot's side only: the current posterior, the rasterised model, the working area and
the model's class boundaries (never the true pose). Registered, in this order:

``random`` (the paper's baseline, :mod:`~kbcli.core.adaptation.strategies.random`)
    Uniform over the working area, or sampled from the model.
``active`` (our first reading of the paper's, :mod:`~kbcli.core.adaptation.strategies.active`)
    The most confusing uniform candidates, then the lowest simulated entropy.
``paper-active`` (the paper's, :mod:`~kbcli.core.adaptation.strategies.paper_active`)
    Candidates sampled from the model, ranked by its confusion factor, simulated with the
    adapter's own term.
``infogain`` (ours, :mod:`~kbcli.core.adaptation.strategies.infogain`)
    The largest expected information gain over the whole posterior predictive.

The model-based ones work for hard (exact) and soft (learned) models alike
(:mod:`~kbcli.core.adaptation.strategies.predictive`).
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
