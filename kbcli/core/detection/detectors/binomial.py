"""``binomial`` (Eq. 4-6 as kbcli reads them, the default).

The last ``n_st`` results form the short-term window, the ``n_lt`` results before them the
long-term window. The long-term window gives the failure probability (Eq. 4),
``p_fail = (k_lt + a) / (n_lt + a + b)`` where ``k_lt`` counts its failures and ``(a, b)`` are
Beta prior pseudo-counts (default ``(1, 1)``: ``p_fail`` stays above 0 for a model that never
failed). The short-term window counts recent failures ``n_f`` (Eq. 5). The score is the *upper
tail* of the binomial law of Eq. 6, ``P(X >= n_f; n_st, p_fail)`` (not the point probability Eq. 6
prints): it fires only on an excess of failures. The tails are tabulated once per ``(k_lt, n_f)``.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from kbcli.core.detection.detectors.base import DETECTORS, Bank, DetectorConfig


def binomial_tail_table(n_lt: int, n_st: int, prior: tuple[float, float]) -> np.ndarray:
    """Upper tails ``P(X >= n_f; n_st, p_fail(k_lt))`` for every ``k_lt`` and ``n_f``.

    Returns
    -------
    (n_lt + 1, n_st + 1) ndarray
        Row ``k_lt`` (failures in the long-term window), column ``n_f`` (recent failures).
    """
    a, b = prior
    p = (np.arange(n_lt + 1) + a) / (n_lt + a + b)
    nf = np.arange(n_st + 1)
    return stats.binom.sf(nf[None, :] - 1, n_st, p[:, None])


@DETECTORS.register("binomial")
class BinomialBank(Bank):
    """The paper's detector (Eq. 4-6): upper binomial tail of recent failures."""

    def __init__(self, cfg: DetectorConfig, n_streams: int) -> None:
        super().__init__(cfg, n_streams)
        self.table = binomial_tail_table(cfg.n_lt, cfg.n_st, cfg.prior)

    def _score(self, x: np.ndarray) -> np.ndarray:
        return self.table[self.k_lt, self.n_f]
