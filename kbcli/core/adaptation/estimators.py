"""Estimators of the transform: which point of the posterior the robot acts on (Sect. III-D).

A registry of :class:`Estimator` entries (``AdapterConfig.estimator``): each reads its estimate off
a posterior (:class:`~kbcli.core.adaptation.posteriors.posterior.Posterior`: the maximum-likelihood cell or the mean) and
names the per-step record of a ``run`` artifact that holds it. An estimator with options of its own
registers their model (``traits={"options": ...}``, :mod:`kbcli.core.options`); ``mean`` and
``ml`` take none.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from kbcli.core.registry import Registry


@dataclass(frozen=True)
class Estimator:
    """A registered estimator.

    Attributes
    ----------
    name : str
    record : str
        The per-step record of a run that holds this estimate (``means`` or ``estimates``).
    read : callable
        ``read(posterior, options) -> (P,) ndarray`` (``options``: ``AdapterConfig.estimator``).
    """

    name: str
    record: str
    read: Callable[[Any, Any], np.ndarray]

    def final(self, records: dict[str, np.ndarray]) -> np.ndarray:
        """The last estimate in a run's per-step ``records``."""
        return np.asarray(records[self.record], float)[-1]


#: The estimators (``--estimator``), read with ``ESTIMATORS.get(name)``.
ESTIMATORS: Registry[Estimator] = Registry("estimator")
ESTIMATORS.register("mean", Estimator("mean", "means", lambda post, _: post.mean()),
                    summary="the posterior mean (RMSE-optimal; ours)")
def _ml_departure(r: dict) -> str:
    """How the ML cell departs from the paper's text (its tie rule, which the paper leaves open)."""
    if r.get("ml_ties") == "random":
        return ("the maximum-likelihood cell; ties broken uniformly at random (seeded), so no "
                "corner of the prior box is favoured")
    return ("the maximum-likelihood cell; ties go to the lowest grid index (the corner and "
            "edges of the prior box), so every ML verdict is also read with the posterior mean "
            "of the same runs")


ESTIMATORS.register("ml", Estimator("ml", "estimates", lambda post, _: post.ml()),
                    summary="the maximum-likelihood cell (the paper's)",
                    traits={"ties": True, "departures": {"ml": _ml_departure}})
