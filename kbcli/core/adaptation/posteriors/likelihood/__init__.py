"""``likelihood`` (ours, the default): each touch multiplies the posterior by the model's classifier
read at the touch (Eq. 8 with the learned p(sound | action), :mod:`kbcli.core.adaptation.posteriors.likelihood.term`); it can
be made robust to the model's own errors (:mod:`kbcli.core.adaptation.posteriors.likelihood.robust`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
from pydantic import Field, model_validator

from kbcli.core.adaptation.fields import Blur, Fraction
from kbcli.core.adaptation.posteriors.base import POSTERIORS, KindBase, Observation
from kbcli.core.adaptation.posteriors.likelihood.robust import (
    ROBUST_OPTIONS,
    Nuisance,
    robust_terms,
)
from kbcli.core.adaptation.posteriors.likelihood.term import cell_sigma, likelihood_term
from kbcli.core.config import Flag, NonNegative, Positive, Rate
from kbcli.core.options import Options


@dataclass(frozen=True)
class LikelihoodPosterior(KindBase):
    """The model's classifier at each touch; the robust posterior applies to it."""

    name = "likelihood"
    robust = True

    def term(self, obs: Observation) -> tuple[np.ndarray, None]:
        """``log p_eps(cls | T_h^-1(action))``, cell-averaged when the options say so."""
        sigma = cell_sigma(obs.grid, obs.action) if obs.cfg.posterior.cell_average else 0.0
        return likelihood_term(obs.grid, obs.table, obs.action, obs.cls, sigma), None

    def robust_terms(self, obs: Observation, nuisance: Nuisance) -> np.ndarray:
        """The term under every nuisance value (:func:`kbcli.core.adaptation.posteriors.likelihood.robust.robust_terms`);
        cell-averaged for a rotating grid only."""
        grid = obs.grid
        sigma = cell_sigma(grid, obs.action) if obs.cfg.posterior.cell_average and grid.rigid \
            else 0.0
        return robust_terms(grid, obs.table, obs.action, obs.cls, nuisance, sigma)


class LikelihoodOptions(Options):
    """The likelihood posterior's options.

    Parameters
    ----------
    robust : bool
        Marginalise the model's error (boundary blur ``robust_blurs`` and outlier rate
        ``robust_outliers``, uniform prior) online (:mod:`.robust`). False: the plain posterior,
        which reads the map as the truth.
    robust_blurs : tuple of float or None
        Boundary blurs (px) the robust posterior weighs; None: 0, 1, 2.5 and 5 px (translation),
        widened by ``WIDE_BLUR_FACTOR`` times the model's own cross-validated boundary error when
        that is wider (:func:`kbcli.core.adaptation.config.robust_blurs`); 0 px only (rigid).
    robust_outliers : tuple of float or None
        Outlier rates the robust posterior weighs; None: the family's (0.001, 0.02 and 0.1 for a
        translation, 0.001 and 0.05 for a rotating family), resolved by the adapter's config.
    robust_eta : float or None
        Learning rate in (0, 1] the robust posterior tempers the log-likelihood with after 30
        touches (:mod:`.robust`); None: resolved with the model,
        ``min(1, (TEMPER_PX / b)^2)`` for its own boundary error ``b`` px
        (:func:`kbcli.core.adaptation.config.learning_rate`). 1: untempered.
    redundancy_radius : float or None
        With ``robust``, touches within this radius (px) of earlier ones count as one spot: the
        ``k``-th enters the posterior with weight ``1 / k``, and infogain divides a candidate's
        gain by the same ``k``. None: ``REDUNDANCY_FACTOR`` (4) times the model's own boundary
        error (0 for the exact model or a model without an estimate). 0: off.
    cell_average : bool
        Read the likelihood of a grid cell averaged over the cell (a Gaussian of the cell's spread,
        :func:`.term.cell_sigma`) rather than at its centre (the plain posterior; the robust one
        on a rotating grid only).
    repair : bool
        Adapt with the model repaired by the touches (:mod:`kbcli.core.adaptation.repair`): a
        joint belief over the shift and the model's map (the translation family, robust).
    repair_kernel, repair_scale, repair_blur : float or None
        The repaired map's kernel width (px; None: 10), the scale of the model's local blur
        (None: 0.6) and the blur under it everywhere (px; None: the model's landing scatter).
    """

    what: ClassVar[str] = "posterior likelihood"

    robust: Flag = True
    robust_blurs: Annotated[tuple[Blur, ...], Field(min_length=1)] | None = None
    robust_outliers: Annotated[tuple[Rate, ...], Field(min_length=1)] | None = None
    robust_eta: Fraction | None = None
    redundancy_radius: NonNegative | None = None
    cell_average: Flag = True
    repair: Flag = False
    repair_kernel: Positive | None = None
    repair_scale: NonNegative | None = None
    repair_blur: Blur | None = None

    @model_validator(mode="after")
    def _repair_is_robust(self) -> LikelihoodOptions:
        if self.repair and not self.robust:
            raise ValueError("repair works with the robust likelihood posterior "
                             "(robust = false was given)")
        return self

    def inactive(self) -> dict[str, str]:
        """The robust posterior's options without ``robust``, its per-touch options under the
        repaired belief (which keeps ``robust_outliers``), the repair's without ``repair``."""
        out = {}
        if not self.robust:
            out.update({o: "robust = false" for o in ROBUST_OPTIONS})
        elif self.repair:
            out.update({o: "repair = true" for o in ROBUST_OPTIONS if o != "robust_outliers"})
        if not self.repair:
            out.update({o: "repair = false" for o in REPAIR_OPTIONS})
        return out


#: The repaired belief's options (:mod:`kbcli.core.adaptation.repair`).
REPAIR_OPTIONS = ("repair_kernel", "repair_scale", "repair_blur")


POSTERIORS.register("likelihood", LikelihoodPosterior(),
                    summary="the model's classifier at each touch (ours)",
                    traits={"options": LikelihoodOptions})
