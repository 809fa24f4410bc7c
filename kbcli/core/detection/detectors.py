"""Failure detection on the MATCH / NO_MATCH history (paper Sect. III-C, Eq. 4-6).

The robot keeps a history ``H`` of action results, ``1`` for a failed action (NO_MATCH) and ``0``
for a success. A detector reads that 0/1 stream one value at a time and says when the failure rate
has gone up (the keyboard has probably moved).

Every detector here produces a *score* in (0, 1] at each step and fires when the score drops below
``threshold``; small scores are strong evidence of a change. The detectors:

``binomial`` (Eq. 4-6 as kbcli reads them, the default)
    The last ``n_st`` results form the short-term window, the ``n_lt`` results before them the
    long-term window. The long-term window gives the failure probability (Eq. 4),
    ``p_fail = (k_lt + a) / (n_lt + a + b)`` where ``k_lt`` counts its failures and ``(a, b)`` are
    Beta prior pseudo-counts (default ``(1, 1)``, Laplace's rule of succession: this keeps ``p_fail``
    above 0 for a model that never failed, where Eq. 6 would otherwise give probability 0 to any
    failure and fire on the first one). The short-term window counts recent failures ``n_f``
    (Eq. 5). The score is the *upper tail* of the binomial law of Eq. 6,
    ``P(X >= n_f; n_st, p_fail)``: Eq. 6 as printed is the point probability ``P(X = n_f)``, which
    also becomes small when there are unusually *few* failures (and for every ``n_f`` when ``n_st``
    is large); the upper tail fires only on an excess of failures, which is the event the robot
    must react to. The tail of every ``(k_lt, n_f)`` pair is tabulated once, so a step costs a
    lookup.

``cusum`` (Page's Bernoulli CUSUM)
    The cumulative log-likelihood ratio ``S_t = max(0, S_{t-1} + log p1(x_t) / p0(x_t))`` of a
    failure rate ``p1 = p0 + shift`` against the current rate ``p0``. ``p0`` is estimated like
    ``p_fail`` above (same Beta prior) but from *all* results since the last reset except the
    short-term window, so that it is not dragged up by the failures it has to detect during the
    first ``n_lt`` results after a change (a self-starting CUSUM). The score is ``exp(-S_t)``, so
    ``threshold = alpha`` means the alarm level ``h = log(1 / alpha)``, for which the in-control
    average run length is at least about ``1 / alpha`` when ``p0`` is right. CUSUM is the optimal
    detector (Lorden's minimax delay) for a known jump size.

``bocpd`` (Bayesian online changepoint detection, Adams and MacKay 2007)
    The posterior over the run length ``r_t`` (the number of results since the last change) with a
    Beta-Bernoulli segment model (prior ``(a, b)``) and a constant ``hazard`` of a change per step,
    in log space. Run lengths are truncated to ``n_lt + n_st``: the last bin holds every longer run,
    with the failure counts of the whole run since the reset. The score is ``P(r_t >= n_lt | H)``:
    the posterior probability that no change happened within the long-term window. It is set to 1
    unless the posterior failure rate of the recent segments exceeds the long run's, so it fires
    only on more failures, never on fewer. Like the binomial test it has a memory of about
    ``n_lt`` results: a change it has not flagged by then is absorbed into the long run.

All detectors stay silent (score 1) until ``n_lt + n_st`` results have been seen since their last
reset, so the long-term window is full. A detector that fires is reset (its windows are emptied), as
the robot starts adapting and then rebuilds its history.

Two forms share one implementation: a *bank* holds the state of a detector on ``S`` parallel
streams and advances all of them with one vectorized :meth:`Bank.step` (benchmarks:
:func:`run_batch`); :class:`Detector` wraps a bank of one stream into the online form,
``update(x) -> fired``, for a play loop or the closed loop.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np
from pydantic import field_validator, model_validator
from scipy import stats
from scipy.special import logsumexp

from kbcli.core.config import Config, Name, Number, Positive, Whole, between
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: Largest long-term window ``n_lt`` (the binomial detector tabulates (n_lt + 1) x (n_st + 1)
#: tails, the bocpd detector tracks n_lt + n_st run lengths per step).
MAX_N_LT = 10_000
#: Largest short-term window ``n_st``.
MAX_N_ST = 1_000

_Probability = between(Number, 0.0, 1.0, low_open=True, high_open=True)


class DetectorConfig(Config):
    """Which detector and its parameters.

    Parameters
    ----------
    detector : str
        One of :data:`DETECTORS` (``binomial``, ``cusum``, ``bocpd``).
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
    shift : float
        ``cusum`` only: the failure-rate increase it is tuned to, ``p1 = p0 + shift``; in (0, 1).
    hazard : float
        ``bocpd`` only: prior probability of a change at each step; in (0, 1).
    """

    what = "detector"

    detector: Name = "binomial"
    n_lt: between(Whole, 1, MAX_N_LT) = 100
    n_st: between(Whole, 1, MAX_N_ST) = 10
    threshold: _Probability = 0.01
    prior: tuple[Positive, Positive] = (1.0, 1.0)
    shift: _Probability = 0.15
    hazard: _Probability = 1e-3

    @field_validator("detector")
    @classmethod
    def _known(cls, v: str) -> str:
        return DETECTORS.check(v)

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


#: name -> factory(cfg, n_streams) -> Bank
DETECTORS: Registry[Callable[[DetectorConfig, int], Bank]] = Registry("detector")


def make_bank(cfg: DetectorConfig, n_streams: int) -> Bank:
    """A bank of ``cfg.detector`` on ``n_streams`` streams."""
    return DETECTORS.get(cfg.detector)(cfg, n_streams)


# -- the binomial detector (Eq. 4-6, the upper tail of Eq. 6) -----------------------------------
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


class _Binomial(Bank):
    def __init__(self, cfg: DetectorConfig, n_streams: int) -> None:
        super().__init__(cfg, n_streams)
        self.table = binomial_tail_table(cfg.n_lt, cfg.n_st, cfg.prior)

    def _score(self, x: np.ndarray) -> np.ndarray:
        return self.table[self.k_lt, self.n_f]


@DETECTORS.register("binomial")
def binomial(cfg: DetectorConfig, n_streams: int) -> Bank:
    """The paper's detector (Eq. 4-6): upper binomial tail of recent failures."""
    return _Binomial(cfg, n_streams)


# -- Bernoulli CUSUM --------------------------------------------------------------------------------
class _Cusum(Bank):
    def __init__(self, cfg: DetectorConfig, n_streams: int) -> None:
        super().__init__(cfg, n_streams)
        self.s = np.zeros(self.n_streams)

    def _reset_extra(self, m) -> None:
        self.s[m] = 0.0

    def _score(self, x: np.ndarray) -> np.ndarray:
        a, b = self.cfg.prior
        n_old = np.maximum(self.seen - self.cfg.n_st, 0)
        p0 = (self.k_old + a) / (n_old + a + b)
        p1 = np.minimum(p0 + self.cfg.shift, 1.0 - 1e-9)
        llr = np.where(x > 0, np.log(p1 / p0), np.log1p(-p1) - np.log1p(-p0))
        active = self.seen >= self.cfg.warmup
        self.s = np.where(active, np.maximum(0.0, self.s + llr), 0.0)
        return np.exp(-self.s)


@DETECTORS.register("cusum")
def cusum(cfg: DetectorConfig, n_streams: int) -> Bank:
    """Page's Bernoulli CUSUM for ``p0 -> p0 + shift``, ``p0`` from the long-term window."""
    return _Cusum(cfg, n_streams)


# -- Bayesian online changepoint detection ---------------------------------------------------------
class _Bocpd(Bank):
    def __init__(self, cfg: DetectorConfig, n_streams: int) -> None:
        super().__init__(cfg, n_streams)
        self.r_max = cfg.warmup  # run lengths 0 .. r_max, the last bin holds every longer run
        a, b = cfg.prior
        self._den = np.broadcast_to(a + b + np.arange(self.r_max + 1.0), (self.n_streams, self.r_max + 1)).copy()
        self._log_h = math.log(cfg.hazard)
        self._log_1mh = math.log1p(-cfg.hazard)
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


@DETECTORS.register("bocpd")
def bocpd(cfg: DetectorConfig, n_streams: int) -> Bank:
    """Bayesian online changepoint detection with a Beta-Bernoulli model (run lengths truncated)."""
    return _Bocpd(cfg, n_streams)


# -- the two forms ------------------------------------------------------------------------------------
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
