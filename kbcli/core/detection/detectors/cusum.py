"""``cusum``, Page's Bernoulli CUSUM.

The cumulative log-likelihood ratio ``S_t = max(0, S_{t-1} + log p1(x_t) / p0(x_t))`` of a
failure rate ``p1 = p0 + shift`` against the current rate ``p0``. ``p0`` is estimated like the
binomial detector's ``p_fail`` (same Beta prior) but from *all* results since the last reset except
the short-term window, so that it is not dragged up by the failures it has to detect during the
first ``n_lt`` results after a change (a self-starting CUSUM). The score is ``exp(-S_t)``, so
``threshold = alpha`` means the alarm level ``h = log(1 / alpha)``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kbcli.core.detection.detectors.base import DETECTORS, Bank, DetectorConfig, Probability
from kbcli.core.options import Options


class CusumOptions(Options):
    """``cusum``'s option: ``shift``, the failure-rate increase it is tuned to
    (``p1 = p0 + shift``); in (0, 1)."""

    what: ClassVar[str] = "detector cusum"
    shift: Probability = 0.15


@DETECTORS.register("cusum", traits={"options": CusumOptions})
class CusumBank(Bank):
    """Page's Bernoulli CUSUM for ``p0 -> p0 + shift``, ``p0`` from the long-term window."""

    def __init__(self, cfg: DetectorConfig, n_streams: int) -> None:
        super().__init__(cfg, n_streams)
        self.s = np.zeros(self.n_streams)

    def _reset_extra(self, m) -> None:
        self.s[m] = 0.0

    def _score(self, x: np.ndarray) -> np.ndarray:
        a, b = self.cfg.prior
        n_old = np.maximum(self.seen - self.cfg.n_st, 0)
        p0 = (self.k_old + a) / (n_old + a + b)
        p1 = np.minimum(p0 + self.cfg.detector.shift, 1.0 - 1e-9)
        llr = np.where(x > 0, np.log(p1 / p0), np.log1p(-p1) - np.log1p(-p0))
        active = self.seen >= self.cfg.warmup
        self.s = np.where(active, np.maximum(0.0, self.s + llr), 0.0)
        return np.exp(-self.s)
