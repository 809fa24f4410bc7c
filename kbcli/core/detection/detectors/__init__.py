"""Failure detection on the MATCH / NO_MATCH history (paper Sect. III-C, Eq. 4-6).

The robot keeps a history ``H`` of action results, ``1`` for a failed action (NO_MATCH) and ``0``
for a success. A detector reads that 0/1 stream one value at a time and says when the failure rate
has gone up (the keyboard has probably moved).

Every detector produces a *score* in (0, 1] at each step and fires when the score drops below
``threshold``; small scores are strong evidence of a change. Registered in :data:`DETECTORS`
(:mod:`~kbcli.core.detection.detectors.base`), one module each:

``binomial`` (Eq. 4-6 as kbcli reads them, the default; :mod:`~kbcli.core.detection.detectors.binomial`)
    The upper binomial tail of the recent failures under the long-term failure rate.
``cusum`` (:mod:`~kbcli.core.detection.detectors.cusum`)
    Page's Bernoulli CUSUM, self-starting.
``bocpd`` (:mod:`~kbcli.core.detection.detectors.bocpd`)
    Bayesian online changepoint detection with a Beta-Bernoulli segment model.

All detectors stay silent (score 1) until ``n_lt + n_st`` results have been seen since their last
reset, so the long-term window is full. The online and batch forms share one implementation
(:mod:`~kbcli.core.detection.detectors.online`).
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
