"""``kde`` (the paper's Eq. 7): each touch multiplies the posterior by a kernel density estimate of
p(action | sound) built from samples of the model (:mod:`kbcli.core.kde`,
:class:`~kbcli.core.kde.ActionSamples`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kbcli.core.kde import kde_term, kde_terms
from kbcli.core.posteriors.base import POSTERIORS, KindBase, Observation
from kbcli.core.registry import Uses


@dataclass(frozen=True)
class KdePosterior(KindBase):
    """The paper's product of KDEs of p(action | sound), from per-class samples of the model."""

    name = "kde"
    uses_samples = True

    def term(self, obs: Observation) -> tuple[np.ndarray, float]:
        """``log KDE_t(h)`` with the floor ``cfg.kde_eps`` (``kde_floor``, or ``outlier`` when
        that is None), and the kernel bandwidth (px) it used."""
        return kde_term(obs.grid, obs.model, obs.action, obs.cls, n_samples=obs.cfg.kde_samples,
                        eps=obs.cfg.kde_eps, samples=obs.samples)

    def terms(self, observations: Sequence[Observation]) -> np.ndarray:
        """``(k, *grid.shape)`` log terms of ``k`` observations of one adaptation (the same grid,
        model, config and samples), the same numbers as :meth:`term` of each in turn (their
        samples drawn in that order), the kernel densities computed together."""
        first = observations[0]
        draws = [first.samples.get(int(o.cls)) for o in observations]
        actions = np.array([o.action for o in observations], float).reshape(-1, 2)
        return kde_terms(first.grid, actions, np.stack([d for d, _ in draws]),
                         [bw for _, bw in draws], first.cfg.kde_eps)


def _fresh(cfg) -> bool:
    return cfg.kde_draw == "fresh"


POSTERIORS.register("kde", KdePosterior(),
                    summary="the paper's product of KDEs of p(action | sound) (Eq. 7)",
                    uses=("kde_samples", "kde_draw", "kde_beyond", "kde_floor", "kde_bandwidth",
                          Uses("kde_sampler", _fresh, 'kde_draw = "fresh"', 'kde_draw = "shared"')))
