"""The kinds of posterior over the transform (Sect. III-D): a registry read by name.

``AdapterConfig.posterior`` names one :class:`~kbcli.core.adaptation.posteriors.base.PosteriorKind`
(the protocol: :mod:`kbcli.core.adaptation.posteriors.base`), one module per kind: ``likelihood``
(ours, Eq. 8, robust or not) and ``kde`` (the paper's, Eq. 7).
"""

from __future__ import annotations

# registration order is the order ``--help`` and error messages list the kinds in
from kbcli.core.adaptation.posteriors import likelihood as _likelihood  # noqa: F401  registers "likelihood"

# isort: split
from kbcli.core.adaptation.posteriors import kde as _kde  # noqa: F401  registers "kde"
from kbcli.core.adaptation.posteriors.base import (
    POSTERIORS,
    KindBase,
    Observation,
    PosteriorKind,
    RobustKind,
)

__all__ = ["POSTERIORS", "KindBase", "Observation", "PosteriorKind", "RobustKind"]
