"""``kde`` (the paper's Eq. 7): each touch multiplies the posterior by a kernel density estimate of
p(action | sound) built from samples of the model (:mod:`kbcli.core.adaptation.posteriors.kde.density`,
:class:`~kbcli.core.adaptation.posteriors.kde.samples.ActionSamples`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.posteriors.base import POSTERIORS, KindBase, Observation
from kbcli.core.adaptation.posteriors.kde.density import (
    KERNEL_REACH,
    MAX_BANDWIDTH,
    ZERO_RTOL,
    kde_term,
    kde_terms,
)
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


# -- how it departs from the paper's text (the report's rows; ``r``: the recorded options) --------
def _samples(r: dict) -> str:
    n = r.get("kde_samples", "(default)")
    if r.get("kde_draw") == "fresh":
        return (f"Algorithm 2 as written: N = {n} new actions per observation (N is open), drawn "
                f"from the model's {r.get('kde_sampler', '(default)')} sampler")
    return (f"{n} actions per sound are drawn once and shared by every experiment of the "
            "evaluation, so the runs of a cell share their Monte-Carlo noise")


def _floor(r: dict) -> str:
    eps = r.get("kde_floor")
    if eps is None:  # None: the outlier rate (AdapterConfig.kde_eps)
        eps = r.get("outlier", 1e-3)
    if eps == 0:
        return ("no floor (Eq. 7 as written): a hypothesis that no sample of a touch's sound "
                "supports is ruled out by that touch")
    return f"every KDE factor is mixed with eps = {eps:g} of the uniform prior (a floor)"


def _beyond(r: dict) -> str:
    if r.get("kde_beyond", "unknown") == "silent":
        return ("kbcli's reading: the pad beyond the working area is silent, so silence's "
                "samples cover a ring beyond it as wide as a hypothesis can move a touch back "
                "(prior half-width plus a kernel's reach); a silent touch is never ruled out "
                "only because the samples stop at the area's edge (`kde_beyond = silent`)")
    return ("silence's samples stop at the working area's edge: a hypothesis that moves a "
            "silent touch beyond it gets no support"
            + (" (ruled out, no floor)" if r.get("kde_floor") == 0 else "")
            + " (`kde_beyond = unknown`, made before issue 39 or set so)")


def _bandwidth(r: dict) -> str:
    bw, res = r.get("kde_bandwidth"), r.get("resolution", "(default)")
    rule = (f"{bw:g} px" if bw is not None else
            "Scott's rule sigma n^(-1/6) with Silverman's robust spread min(std, IQR / 1.349), "
            f"clipped to [{res}, {MAX_BANDWIDTH:g}] px")
    return (f"a Gaussian kernel, its std {rule}, cut at {KERNEL_REACH:g} std; without a floor, "
            f"densities below {ZERO_RTOL:g} of a term's peak are read as zero (the FFT's "
            f"rounding); the product is evaluated on a grid of {res} px over "
            f"+-{r.get('prior_halfwidth', '(default)')} px, not sampled")


POSTERIORS.register("kde", KdePosterior(),
                    summary="the paper's product of KDEs of p(action | sound) (Eq. 7)",
                    traits={"departures": {"samples": _samples, "floor": _floor,
                                           "beyond": _beyond, "bandwidth": _bandwidth}},
                    uses=("kde_samples", "kde_draw", "kde_beyond", "kde_floor", "kde_bandwidth",
                          Uses("kde_sampler", _fresh, 'kde_draw = "fresh"', 'kde_draw = "shared"')))
