"""``bocpd``, Bayesian online changepoint detection (Adams and MacKay 2007).

The posterior over the run length ``r_t`` (the number of results since the last change) with a
Beta-Bernoulli segment model (prior ``(a, b)``) and a constant ``hazard`` of a change per step,
in log space. Run lengths are truncated to ``n_lt + n_st``: the last bin holds every longer run,
with the failure counts of the whole run since the reset. The score is ``P(r_t >= n_lt | H)``:
the posterior probability that no change happened within the long-term window. It is set to 1
unless the posterior failure rate of the recent segments exceeds the long run's, so it fires
only on more failures, never on fewer.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
from scipy.special import logsumexp

from kbcli.core.detection.detectors.base import DETECTORS, Bank, DetectorConfig, Probability
from kbcli.core.options import Options


class BocpdOptions(Options):
    """``bocpd``'s option: ``hazard``, the prior probability of a change at each step; in (0, 1)."""

    what: ClassVar[str] = "detector bocpd"
    hazard: Probability = 1e-3


@DETECTORS.register("bocpd", traits={"options": BocpdOptions})
class BocpdBank(Bank):
    """Bayesian online changepoint detection with a Beta-Bernoulli model (run lengths truncated)."""

    def __init__(self, cfg: DetectorConfig, n_streams: int) -> None:
        super().__init__(cfg, n_streams)
        self.r_max = cfg.warmup  # run lengths 0 .. r_max, the last bin holds every longer run
        a, b = cfg.prior
        self._den = np.broadcast_to(a + b + np.arange(self.r_max + 1.0), (self.n_streams, self.r_max + 1)).copy()
        self._log_h = math.log(cfg.detector.hazard)
        self._log_1mh = math.log1p(-cfg.detector.hazard)
        self.log_post = np.full((self.n_streams, self.r_max + 1), -np.inf)
        self.log_post[:, 0] = 0.0
        # failures in the last r results; the last bin counts the whole run since the reset
        self.counts = np.zeros((self.n_streams, self.r_max + 1))

    def _reset_extra(self, m) -> None:
        self.log_post[m] = -np.inf
        self.log_post[m, 0] = 0.0
        self.counts[m] = 0.0

    def _score(self, x: np.ndarray) -> np.ndarray:
        a, b = self.cfg.prior
        den = self._den
        den[:, -1] = a + b + np.maximum(self.seen - 1, self.r_max)
        p1 = (a + self.counts) / den  # predictive p(fail | run length r), (S, R + 1)
        lik = np.where(x[:, None] > 0, p1, 1.0 - p1)
        log_joint = self.log_post + np.log(lik)
        new = np.empty_like(log_joint)
        new[:, 0] = logsumexp(log_joint, axis=1) + self._log_h
        new[:, 1:] = log_joint[:, :-1] + self._log_1mh
        new[:, -1] = np.logaddexp(new[:, -1], log_joint[:, -1] + self._log_1mh)
        new -= logsumexp(new, axis=1)[:, None]
        self.log_post = new
        c = self.counts
        c[:, 1:] = c[:, :-1] + x[:, None]  # the right side is a new array: no overlap
        c[:, 0] = 0.0
        c[:, -1] = self.k_old + self.n_f  # the whole run since the reset
        den[:, -1] = a + b + np.maximum(self.seen, self.r_max)
        n_lt = self.cfg.n_lt
        post = np.exp(new)
        score = post[:, n_lt:].sum(axis=1)  # P(no change within the long term)
        # fire only when the recent segment fails more often than the long run
        p_now = (a + c[:, :n_lt]) / den[:, :n_lt]
        w_short = post[:, :n_lt].sum(axis=1)
        p_short = (post[:, :n_lt] * p_now).sum(axis=1) / np.maximum(w_short, 1e-300)
        up = p_short > (a + c[:, -1]) / den[:, -1]
        return np.where(up, np.minimum(score, 1.0), 1.0)
