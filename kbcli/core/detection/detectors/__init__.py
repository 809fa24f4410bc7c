"""Failure detection on the MATCH / NO_MATCH history (paper Sect. III-C, Eq. 4-6).

A detector reads the 0/1 stream of action results (1: a failed action, NO_MATCH) one value at a
time, gives a score in (0, 1] at each step and fires when it drops below ``threshold`` (the
keyboard has probably moved). Registered in :data:`DETECTORS`, one module each: ``binomial`` (the
upper binomial tail of the recent failures, Eq. 4-6; the default), ``cusum`` (Page's Bernoulli
CUSUM, self-starting), ``bocpd`` (Bayesian online changepoint detection). Each stays silent
(score 1) until ``n_lt + n_st`` results have been seen since its last reset; the online and batch
forms share one implementation (:mod:`~kbcli.core.detection.detectors.online`).
"""

from __future__ import annotations

from kbcli.core.detection.detectors.base import (
    DETECTORS,
    MAX_N_LT,
    MAX_N_ST,
    DetectorConfig,
    make_bank,
)

# isort: split
# registration order is the order ``--help`` and error messages list the detectors in
from kbcli.core.detection.detectors.binomial import binomial_tail_table

# isort: split
from kbcli.core.detection.detectors import cusum as _cusum  # noqa: F401  registers "cusum"

# isort: split
from kbcli.core.detection.detectors import bocpd as _bocpd  # noqa: F401  registers "bocpd"
from kbcli.core.detection.detectors.online import (
    RESULTS,
    Detector,
    detect_stream,
    first_crossing,
    run_batch,
)

__all__ = ["DETECTORS", "MAX_N_LT", "MAX_N_ST", "RESULTS", "Detector", "DetectorConfig",
           "binomial_tail_table", "detect_stream", "first_crossing", "make_bank", "run_batch"]
