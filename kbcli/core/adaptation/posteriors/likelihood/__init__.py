"""``likelihood`` (ours, the default): each touch multiplies the posterior by the model's classifier
read at the touch (Eq. 8 with the learned p(sound | action), :mod:`kbcli.core.adaptation.posteriors.likelihood.term`); it can
be made robust to the model's own errors (:mod:`kbcli.core.adaptation.posteriors.likelihood.robust`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.posteriors.base import POSTERIORS, KindBase, Observation
from kbcli.core.adaptation.posteriors.likelihood.robust import (
    ROBUST_OPTIONS,
    Nuisance,
    robust_terms,
)
from kbcli.core.adaptation.posteriors.likelihood.term import cell_sigma, likelihood_term
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.core.registry import Uses


@dataclass(frozen=True)
class LikelihoodPosterior(KindBase):
    """The model's classifier at each touch; the robust posterior applies to it."""

    name = "likelihood"
    robust = True

    def term(self, obs: Observation) -> tuple[np.ndarray, None]:
        """``log p_eps(cls | T_h^-1(action))``, cell-averaged when ``cfg.cell_average``."""
        sigma = cell_sigma(obs.grid, obs.action) if obs.cfg.cell_average else 0.0
        return likelihood_term(obs.grid, obs.table, obs.action, obs.cls, sigma), None

    def robust_terms(self, obs: Observation, nuisance: Nuisance) -> np.ndarray:
        """The term under every nuisance value (:func:`kbcli.core.adaptation.posteriors.likelihood.robust.robust_terms`);
        cell-averaged for a rotating grid only."""
        grid = obs.grid
        sigma = cell_sigma(grid, obs.action) if obs.cfg.cell_average and grid.rigid else 0.0
        return robust_terms(grid, obs.table, obs.action, obs.cls, nuisance, sigma)


def _robust(cfg) -> bool:
    return bool(cfg.robust)


def _robust_unrepaired(cfg) -> bool:
    """The robust posterior's own options: not read by the repaired belief (which keeps only
    ``robust_outliers``)."""
    return bool(cfg.robust) and not getattr(cfg, "repair", False)


def _repair(cfg) -> bool:
    return bool(getattr(cfg, "repair", False))


#: The repaired belief's options (:mod:`kbcli.core.adaptation.repair`).
REPAIR_OPTIONS = ("repair_kernel", "repair_scale", "repair_blur")


def _cell_averaged(cfg) -> bool:
    """The plain posterior always cell-averages; the robust one on a rotating grid only."""
    return not cfg.robust or (cfg.family in FAMILIES and FAMILIES.get(cfg.family).rotates)


POSTERIORS.register(
    "likelihood", LikelihoodPosterior(), summary="the model's classifier at each touch (ours)",
    uses=("robust", Uses("cell_average", _cell_averaged, "robust = false or the family rotates",
                         "robust = true and the family does not rotate"),
          *(Uses(o, _robust, "robust = true", "robust = false") for o in ("robust_outliers",)),
          *(Uses(o, _robust_unrepaired, "robust = true and repair = false",
                 "robust = false or repair = true") for o in ROBUST_OPTIONS
            if o != "robust_outliers"),
          "repair",
          *(Uses(o, _repair, "repair = true", "repair = false") for o in REPAIR_OPTIONS)))
