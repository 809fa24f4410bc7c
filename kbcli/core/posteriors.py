"""The kinds of posterior over the transform (Sect. III-D): a registry read by name.

``AdapterConfig.posterior`` names one :class:`PosteriorKind`:

``likelihood`` (ours)
    Each touch multiplies the posterior by the model's classifier read at the touch (Eq. 8 with
    the learned p(sound | action)); it can be made robust to the model's own errors
    (:mod:`kbcli.core.robust`).
``kde`` (the paper's, Eq. 7)
    Each touch multiplies it by a kernel density estimate of p(action | sound) built from
    samples of the model (:class:`~kbcli.core.kde.ActionSamples`).
"""

from __future__ import annotations

from dataclasses import dataclass

from kbcli.core.registry import Registry


@dataclass(frozen=True)
class PosteriorKind:
    """A registered kind of posterior.

    Attributes
    ----------
    name : str
    uses_samples : bool
        Whether its terms are built from per-class samples of p(action | sound) (drawn once per
        class and shared between adaptations of one model).
    robust : bool
        Whether the robust posterior (the model's error marginalised online) applies to it.
    """

    name: str
    uses_samples: bool = False
    robust: bool = False


#: The posteriors (``--posterior``), read with ``POSTERIORS.get(name)``.
POSTERIORS: Registry[PosteriorKind] = Registry("posterior")
POSTERIORS.register("likelihood", PosteriorKind("likelihood", robust=True),
                    summary="the model's classifier at each touch (ours)")
POSTERIORS.register("kde", PosteriorKind("kde", uses_samples=True),
                    summary="the paper's product of KDEs of p(action | sound) (Eq. 7)")
