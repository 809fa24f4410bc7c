"""The protocol every kind of posterior follows, and the registry that holds them.

A kind turns one classified touch into a log term over the hypothesis grid (Eq. 8). The adapter
never asks a kind's name, only the registered object (``POSTERIORS.get(cfg.posterior)``). Adding a
posterior is one module with a class that follows :class:`PosteriorKind` (most simply a subclass
of :class:`KindBase`), registered with ``POSTERIORS.register(name, kind, summary=...)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.model.table import LikelihoodTable
from kbcli.core.registry import Registry


@dataclass(frozen=True)
class Observation:
    """What a kind of posterior may read to build the term of one touch.

    Attributes
    ----------
    grid : HypothesisGrid
        The hypothesis grid the term is laid out on (``grid.shape``).
    table : LikelihoodTable
        The model, rasterised (reference frame).
    model : SoundModel
        The model itself (``sample_actions``, ``classify``...).
    cfg : AdapterConfig
        The adapter's config (``outlier``, ``cell_average``, ``kde_samples``...).
    samples : ActionSamples or None
        Per-class samples of p(action | sound) (set when the kind ``uses_samples``).
    action : (2,) ndarray
        Where the touch was read (felt position, or the aim), pad px.
    cls : int
        The perceived sound class (0: silence; never -1, unknown sounds are skipped).
    """

    grid: HypothesisGrid
    table: LikelihoodTable
    model: Any
    cfg: Any
    samples: Any
    action: np.ndarray
    cls: int


@runtime_checkable
class PosteriorKind(Protocol):
    """Everything the adaptation needs from a kind of posterior.

    Attributes
    ----------
    name : str
    uses_samples : bool
        Whether its terms are built from per-class samples of p(action | sound) (the adapter then
        draws them once per class, shared between adaptations of one model:
        :func:`kbcli.core.adaptation.setup.build_samples`).
    robust : bool
        Whether the robust posterior (the model's error marginalised online,
        :mod:`kbcli.core.adaptation.posteriors.likelihood.robust`) applies to it; such a kind also has :meth:`robust_terms`.
    """

    name: str
    uses_samples: bool
    robust: bool

    def term(self, obs: Observation) -> tuple[np.ndarray, float | None]:
        """``(log term of grid.shape, kernel bandwidth px or None)`` of one observation."""
        ...


@dataclass(frozen=True)
class KindBase:
    """What most kinds of posterior are: terms that need no samples of p(action | sound), and no
    robust posterior. A kind that subclasses it names itself (``name = "kde"``) and sets only the
    attributes of :class:`PosteriorKind` it differs in."""

    name: ClassVar[str]
    uses_samples: ClassVar[bool] = False
    robust: ClassVar[bool] = False

    def draws_fresh(self, cfg: Any) -> bool:
        """Whether the kind draws from the adapter's own generator at every touch (then the
        adapter spawns it one)."""
        return False

    def sample_key(self, cfg: Any) -> tuple | None:
        """What decides the samples the kind's terms share between adaptations of one model
        (two configs with one key share them); None: the kind shares none."""
        return None

    def sources(self, adapter: Any, fresh: Any, rng: Any, samples: Any) -> tuple[Any, Any]:
        """``(samples, simulation samples)`` the kind's terms read for ``adapter`` (given
        ``samples``, shared between adaptations, or None; ``fresh``, the adapter's own generator
        when :meth:`draws_fresh`; ``rng``, the adapter's): here ``samples`` for both."""
        return samples, samples


class RobustKind(PosteriorKind, Protocol):
    """A kind the robust posterior applies to (``robust`` True)."""

    def robust_terms(self, obs: Observation, nuisance: Any) -> np.ndarray:
        """``(K, *grid.shape)`` log terms of one observation, one per nuisance value."""
        ...


#: The posteriors (``--posterior``), read with ``POSTERIORS.get(name)``.
POSTERIORS: Registry[PosteriorKind] = Registry("posterior")
