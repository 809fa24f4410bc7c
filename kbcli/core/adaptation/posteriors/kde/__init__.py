"""``kde`` (the paper's Eq. 7): each touch multiplies the posterior by a kernel density estimate of
p(action | sound) built from samples of the model (:mod:`kbcli.core.adaptation.posteriors.kde.density`,
:class:`~kbcli.core.adaptation.posteriors.kde.samples.ActionSamples`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np

from kbcli.core.adaptation.fields import MAX_KDE_SAMPLES, Floor, choice
from kbcli.core.adaptation.posteriors.base import POSTERIORS, KindBase, Observation
from kbcli.core.adaptation.posteriors.kde.density import ZERO_RTOL, kde_term, kde_terms
from kbcli.core.adaptation.posteriors.kde.samples import (
    KERNEL_REACH,
    MAX_BANDWIDTH,
    ActionSamples,
    FreshSamples,
    beyond_source,
)
from kbcli.core.config import Name, Positive, Whole, between
from kbcli.core.options import Options

#: How the KDE posterior gets its samples of p(action | sound) (``kde_draw``).
KDE_DRAWS = ("shared", "fresh")
#: What silence's samples of p(action | silence) cover (``kde_beyond``).
KDE_BEYOND = ("silent", "unknown")


class KdeOptions(Options):
    """The KDE posterior's options.

    Parameters
    ----------
    kde_samples : int
        N, actions drawn from p(action | sound) per KDE term (Algorithm 2, line 3).
    kde_draw : str
        ``shared``: each class's N actions are drawn once and reused by every touch (and, in the
        evaluation, by every experiment of a process; :class:`.samples.ActionSamples`).
        ``fresh``: Algorithm 2 as written, N new actions for every observation, from the
        adapter's own generator (:class:`.samples.FreshSamples`).
    simulate_draw : str or None
        How ``paper-active``'s simulated touches get their samples. None: as ``kde_draw`` says
        (the paper's text); ``shared``: each sound's N samples drawn once per adaptation and
        reused by every simulated touch (the real touches still draw as ``kde_draw`` says);
        ``fresh``: new samples for every simulated touch.
    kde_beyond : str
        What the KDE knows of the pad beyond the working area (where the paper is silent):
        ``silent`` (silence's samples cover a ring beyond it as wide as the hypotheses can move a
        touch back, :class:`.samples.SilentBeyond`) or ``unknown`` (no samples there).
    kde_floor : float or None
        Weight of the uniform floor mixed into each term (``(1 - w) KDE + w / |prior|``); 0: none
        (Eq. 7 as written); None: the adapter's ``outlier``.
    kde_bandwidth : float or None
        Kernel std, px; None: Scott's rule (:func:`.samples.scott_bandwidth`).
    """

    what: ClassVar[str] = "posterior kde"

    kde_samples: between(Whole, 10, MAX_KDE_SAMPLES) = 10000
    kde_draw: Annotated[Name, choice(*KDE_DRAWS)] = "shared"
    simulate_draw: Annotated[Name, choice(*KDE_DRAWS)] | None = None
    kde_beyond: Annotated[Name, choice(*KDE_BEYOND)] = "silent"
    kde_floor: Floor | None = None
    kde_bandwidth: Positive | None = None

    def samples_actions(self) -> bool:
        return self.kde_draw == "fresh"

    def eps(self, outlier: float) -> float:
        """The term's floor weight: ``kde_floor``, or ``outlier`` when it is None."""
        return float(outlier if self.kde_floor is None else self.kde_floor)


@dataclass(frozen=True)
class KdePosterior(KindBase):
    """The paper's product of KDEs of p(action | sound), from per-class samples of the model."""

    name = "kde"
    uses_samples = True

    def term(self, obs: Observation) -> tuple[np.ndarray, float]:
        """``log KDE_t(h)`` with the floor (``kde_floor``, or the adapter's ``outlier`` when that
        is None), and the kernel bandwidth (px) it used."""
        opts = obs.cfg.posterior
        return kde_term(obs.grid, obs.model, obs.action, obs.cls, n_samples=opts.kde_samples,
                        eps=opts.eps(obs.cfg.outlier), samples=obs.samples)

    def draws_fresh(self, cfg) -> bool:
        """Algorithm 2 as written (``kde_draw = "fresh"``): new samples at every touch."""
        return cfg.posterior.kde_draw == "fresh"

    def sample_key(self, cfg) -> tuple | None:
        """The options the shared samples depend on (None when drawn anew at every touch)."""
        o = cfg.posterior
        if o.kde_draw != "shared":
            return None
        return (o.kde_samples, o.kde_bandwidth, cfg.resolution, o.kde_beyond, cfg.family,
                cfg.prior_halfwidth, cfg.max_angle, cfg.angle_resolution)

    def sources(self, adapter, fresh, rng, samples):
        """The touches' samples: fresh ones from ``fresh`` (``kde_draw = "fresh"``), the given
        shared ones, or shared ones drawn from the model with a seed from ``rng``; and the
        simulated touches' (``simulate_draw``): the same, unless set apart from ``kde_draw`` (then
        drawn by the adapter's ``kde_sampler`` from a further child of ``rng``)."""
        opts, cfg = adapter.cfg.posterior, adapter.cfg

        def drawn():  # what fresh draws come from: the adapter's sampler, silent beyond
            return self._source(adapter, adapter.action_source())

        if opts.kde_draw == "fresh":  # Algorithm 2: new every touch
            samples = FreshSamples(drawn(), opts.kde_samples, fresh, bandwidth=opts.kde_bandwidth,
                                   resolution=cfg.resolution)
        elif samples is None:
            samples = ActionSamples(self._source(adapter, adapter.model), opts.kde_samples,
                                    [int(v) for v in rng.integers(2**32, size=2)],
                                    bandwidth=opts.kde_bandwidth, resolution=cfg.resolution)
        draw = opts.simulate_draw
        if draw is None or draw == opts.kde_draw:
            return samples, samples
        own = rng.spawn(1)[0]
        if draw == "fresh":
            return samples, FreshSamples(drawn(), opts.kde_samples, own,
                                         bandwidth=opts.kde_bandwidth, resolution=cfg.resolution)
        return samples, ActionSamples(drawn(), opts.kde_samples,
                                      [int(v) for v in own.integers(2**32, size=2)],
                                      bandwidth=opts.kde_bandwidth, resolution=cfg.resolution)

    @staticmethod
    def _source(adapter, source):
        """``source`` with silence beyond the working area as ``kde_beyond`` says."""
        return beyond_source(source, adapter.cfg.posterior, adapter.table, adapter.grid,
                             adapter.area)

    def terms(self, observations: Sequence[Observation]) -> np.ndarray:
        """``(k, *grid.shape)`` log terms of ``k`` observations of one adaptation (the same grid,
        model, config and samples), the same numbers as :meth:`term` of each in turn (their
        samples drawn in that order), the kernel densities computed together."""
        first = observations[0]
        draws = [first.samples.get(int(o.cls)) for o in observations]
        actions = np.array([o.action for o in observations], float).reshape(-1, 2)
        return kde_terms(first.grid, actions, np.stack([d for d, _ in draws]),
                         [bw for _, bw in draws], first.cfg.posterior.eps(first.cfg.outlier))


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
                                           "beyond": _beyond, "bandwidth": _bandwidth},
                            "options": KdeOptions})
