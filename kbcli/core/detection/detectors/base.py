"""The detectors' registry, their shared config and the state they share: a *bank* of one
detector on ``S`` parallel 0/1 streams, with the short- and long-term windows of Eq. 4-5.

A detector registers a :class:`Bank` subclass under its name in :data:`DETECTORS`
(``DETECTORS.register(name, cls, traits={"options": ...})``, its own options a
:class:`~kbcli.core.options.Options` beside it): ``cls(cfg, n_streams)`` is a bank, and its
:meth:`Bank._score` turns the windows' counts into a score in (0, 1] (small: strong evidence of a
change).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from pydantic import field_validator, model_validator

from kbcli.core.config import Config, Number, Positive, Whole, between
from kbcli.core.options import part_field, route
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: Largest long-term window ``n_lt`` (the binomial detector tabulates (n_lt + 1) x (n_st + 1)
#: tails, the bocpd detector tracks n_lt + n_st run lengths per step).
MAX_N_LT = 10_000
#: Largest short-term window ``n_st``.
MAX_N_ST = 1_000

#: A probability in (0, 1) (a detector's own options use it too).
Probability = between(Number, 0.0, 1.0, low_open=True, high_open=True)

#: name -> factory(cfg, n_streams) -> Bank (a :class:`Bank` subclass)
DETECTORS: Registry[Callable[[DetectorConfig, int], Bank]] = Registry("detector")
#: The field of :class:`DetectorConfig` that chooses the detector and carries its options.
SLOTS = {"detector": (DETECTORS, "binomial")}


class DetectorConfig(Config):
    """Which detector and its parameters: the detector's own options in it, the windows shared.

    Parameters
    ----------
    detector : Options
        A detector of :data:`DETECTORS` (``binomial``, ``cusum``, ``bocpd``) with its own options
        (cusum's ``shift``, bocpd's ``hazard``); a name, a table ``{name, options...}`` or the
        options given flat beside it (``DetectorConfig(detector="cusum", shift=0.2)``) are read.
        An option the chosen detector does not take is refused by it.
    n_lt : int
        Long-term window N_LT (Eq. 4): results older than the short-term window; at most
        :data:`MAX_N_LT`.
    n_st : int
        Short-term window N_ST (Eq. 5): the most recent results; ``1 <= n_st < n_lt`` and at most
        :data:`MAX_N_ST`.
    threshold : float
        Fire when the score falls below it; in (0, 1).
    prior : tuple of float
        Beta pseudo-counts ``(a, b)`` of failures and successes added to the long-term window when
        estimating ``p_fail`` (and the segment prior of ``bocpd``); both > 0.
    """

    what = "detector"

    detector: part_field(DETECTORS, "binomial") = "binomial"
    n_lt: between(Whole, 1, MAX_N_LT) = 100
    n_st: between(Whole, 1, MAX_N_ST) = 10
    threshold: Probability = 0.01
    prior: tuple[Positive, Positive] = (1.0, 1.0)

    @model_validator(mode="before")
    @classmethod
    def _part(cls, data: Any) -> Any:
        """The detector's options given flat go to the detector (:func:`kbcli.core.options.route`)."""
        return route(data, SLOTS, cls.model_fields) if isinstance(data, dict) else data

    @field_validator("n_lt", "n_st", mode="before")
    @classmethod
    def _numpy_int(cls, v: Any) -> Any:
        return int(v) if isinstance(v, np.integer) else v

    @model_validator(mode="after")
    def _windows(self) -> DetectorConfig:
        if self.n_st >= self.n_lt:
            raise ConfigError(
                f"n_st must be smaller than n_lt (short-term window inside a longer history), "
                f"got n_st={self.n_st}, n_lt={self.n_lt}"
            )
        return self

    @property
    def warmup(self) -> int:
        """Results needed after a reset before the detector may fire (``n_lt + n_st``)."""
        return self.n_lt + self.n_st


class Bank:
    """State of one detector on ``S`` parallel 0/1 streams (1 = failure).

    Keeps the last ``n_lt + n_st`` results of each stream in a ring buffer with running counts of
    the short-term failures ``n_f`` (Eq. 5) and long-term failures ``k_lt`` (Eq. 4). Subclasses turn
    them into a score with :meth:`_score`.
    """

    def __init__(self, cfg: DetectorConfig, n_streams: int) -> None:
        self.cfg = cfg
        self.n_streams = int(n_streams)
        w = cfg.warmup
        self._buf = np.zeros((self.n_streams, w), dtype=np.int8)
        self._pos = w - 1  # column of the newest result
        self.n_f = np.zeros(self.n_streams, dtype=np.int64)
        self.k_lt = np.zeros(self.n_streams, dtype=np.int64)
        #: failures since the reset outside the short-term window (Eq. 4 over the whole past)
        self.k_old = np.zeros(self.n_streams, dtype=np.int64)
        self.seen = np.zeros(self.n_streams, dtype=np.int64)
        a, b = cfg.prior
        #: p_fail (Eq. 4, with the Beta prior) for every possible long-term count, (n_lt + 1,)
        self.p_table = (np.arange(cfg.n_lt + 1) + a) / (cfg.n_lt + a + b)

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Empty the windows of the streams in ``mask`` (all when None)."""
        m = slice(None) if mask is None else np.asarray(mask, bool)
        self._buf[m] = 0
        self.n_f[m] = 0
        self.k_lt[m] = 0
        self.k_old[m] = 0
        self.seen[m] = 0
        self._reset_extra(m)

    def _reset_extra(self, m) -> None:
        """Reset detector-specific state of the streams selected by ``m``."""

    def step(self, x: np.ndarray) -> np.ndarray:
        """Add one result per stream and return the scores.

        Parameters
        ----------
        x : (S,) array of 0/1 or bool
            1 (True) for a failed action.

        Returns
        -------
        (S,) float ndarray
            Score in (0, 1]; the detector fires where it is below ``threshold``.
        """
        x = np.asarray(x).reshape(self.n_streams).astype(np.int8)
        w = self.cfg.warmup
        pos = (self._pos + 1) % w
        leaving_lt = self._buf[:, pos]  # lag w + 1 after this step: leaves the long-term window
        entering_lt = self._buf[:, (pos - self.cfg.n_st) % w]  # lag n_st + 1: short -> long term
        self.k_lt += entering_lt - leaving_lt
        self.k_old += entering_lt
        self.n_f += x - entering_lt
        self._buf[:, pos] = x
        self._pos = pos
        self.seen += 1
        score = self._score(x)
        return np.where(self.seen >= w, score, 1.0)

    def _score(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


def make_bank(cfg: DetectorConfig, n_streams: int) -> Bank:
    """A bank of ``cfg.detector`` on ``n_streams`` streams."""
    return DETECTORS.get(cfg.detector.name)(cfg, n_streams)

