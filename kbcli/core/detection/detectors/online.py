"""A detector in its two forms: online on one stream (:class:`Detector`, ``update(x) -> fired``,
for a play loop or the closed loop) and offline on many streams at once (:func:`run_batch`,
vectorized across streams, for benchmarks). Both run the same :class:`Bank`; a detector that
fires is reset (its windows are emptied), as the robot starts adapting and rebuilds its history.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from kbcli.core.detection.detectors.base import DetectorConfig, make_bank
from kbcli.errors import ConfigError

#: The result values :meth:`Detector.update` takes, by name (the play history's H values).
RESULTS = {"MATCH": 0, "NO_MATCH": 1}


class Detector:
    """A detector on one stream, fed one result at a time (the public ``kbcli.Detector``).

    Parameters
    ----------
    cfg : DetectorConfig, optional
        The whole config; or give its fields as keywords (``detector="cusum", threshold=0.01``).

    Examples
    --------
    >>> det = Detector(detector="binomial")   # Eq. 4-6, N_LT 100, N_ST 10, threshold 0.01
    >>> fired = [det.update(x) for x in ["MATCH"] * 110 + ["NO_MATCH"] * 3]
    >>> fired.index(True)  # the second failure in a row after 110 successes
    111
    """

    def __init__(self, cfg: DetectorConfig | None = None, **options) -> None:
        if cfg is None:
            cfg = DetectorConfig.from_dict(options)
        elif options:
            raise ConfigError(f"give either cfg or options, not both ({', '.join(options)})")
        self.cfg = cfg
        self._bank = make_bank(cfg, 1)
        self.score = 1.0
        self.steps = 0

    def update(self, result: int | bool | str) -> bool:
        """Add the result of one action; return whether the detector fires now.

        Parameters
        ----------
        result : int, bool or str
            The play history's value H: ``0`` / ``"MATCH"`` for a success, ``1`` / ``"NO_MATCH"``
            for a failure (a bool counts True as a failure: ``update(failed)``).

        After firing it resets itself, so the next firing needs a new warm-up of ``n_lt + n_st``.
        """
        if isinstance(result, str):
            try:
                result = RESULTS[result.upper()]
            except KeyError:
                raise ConfigError(f"unknown result {result!r}; valid: MATCH, NO_MATCH, 0, 1") \
                    from None
        elif not (isinstance(result, (bool, np.bool_)) or result in (0, 1)):
            raise ConfigError(f"a result is 0 (MATCH) or 1 (NO_MATCH), got {result!r}")
        x = 1 if result else 0
        self.score = float(self._bank.step(np.array([x]))[0])
        self.steps += 1
        fired = self.score < self.cfg.threshold
        if fired:
            self._bank.reset()
        return fired

    def reset(self) -> None:
        """Forget the history (e.g. after the robot adapted to a new pose)."""
        self._bank.reset()
        self.score = 1.0


def detect_stream(cfg: DetectorConfig, results: Iterable[int]) -> Iterator[tuple[float, bool]]:
    """Run a detector online over a 0/1 stream: yields ``(score, fired)`` per result."""
    det = Detector(cfg)
    for x in results:
        fired = det.update(x)
        yield det.score, fired


def run_batch(
    cfg: DetectorConfig, x: np.ndarray, *, restart: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Run a detector over many streams at once (vectorized across streams).

    Parameters
    ----------
    x : (S, T) array of 0/1
        Failure streams.
    restart : bool
        Reset a stream's detector where it fires (as the online form does). Without restarts the
        scores are those of a detector that never stops, used to tune thresholds: the first time a
        stream's score falls below any threshold is then its first alarm.

    Returns
    -------
    scores : (S, T) float ndarray
    fired : (S, T) bool ndarray
    """
    x = np.atleast_2d(np.asarray(x))
    s, t = x.shape
    bank = make_bank(cfg, s)
    scores = np.empty((s, t))
    fired = np.zeros((s, t), dtype=bool)
    for j in range(t):
        sc = bank.step(x[:, j])
        scores[:, j] = sc
        f = sc < cfg.threshold
        fired[:, j] = f
        if restart and f.any():
            bank.reset(f)
    return scores, fired


def first_crossing(scores: np.ndarray, threshold: float) -> np.ndarray:
    """(S,) index of the first score below ``threshold`` in each row of (S, T) scores, -1 if none."""
    below = np.asarray(scores) < threshold
    idx = np.argmax(below, axis=1)
    return np.where(below.any(axis=1), idx, -1)
