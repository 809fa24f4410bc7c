"""Benchmark of the failure detectors (Sect. III-C) against river's drift detectors.

Streams of MATCH (0) / NO_MATCH (1) results are Bernoulli sequences: a pre-change failure rate
``p_pre``, then, from a random step, the post-change rate of the melody player after a random
displacement of the category (:func:`kbcli.core.playing.play.expected_failure_rate`), or a given
one.

Every detector is first *tuned* on change-free streams: its threshold (ours) or sensitivity
parameter (DDM ``drift_threshold``, FHDDM ``confidence_level``, ADWIN ``delta``) is set to the most
sensitive value whose false-alarm rate (alarms per action, each stream stopped at its first alarm)
is at most ``fa_target`` per 10,000 actions. Then all detectors run, with restarts, on the same
evaluation streams: false alarms per 10,000 pre-change actions, and the delay, the post-change
results seen at the first alarm after the change (later than ``horizon``: missed, infinite in the
percentiles).

river is an optional dependency, imported only here. Its FHDDM flags a drop of its input's mean,
so it is fed successes (1 = MATCH); DDM and ADWIN are fed failures; ADWIN runs with ``clock=1``.
DDM is tuned with warm-ups of 1, 2, 3, 5, 10 times ours (``n_lt + n_st``), the first for which some
``drift_threshold`` reaches the target (its default warm-up of 30 often holds no failure at 0.01).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Annotated, ClassVar

import numpy as np
from pydantic import AfterValidator, Field, model_validator

from kbcli.core.config import Config, Count, Name, Positive, Rate, Whole, each, member_of
from kbcli.core.detection import detectors as det
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.melody import DEFAULT_MELODY, parse_melody
from kbcli.core.model.base import ExactModel
from kbcli.core.playing.play import expected_failure_rate
from kbcli.errors import KbcliError
from kbcli.stages.perturb import CATEGORIES, draw

OURS = ("binomial", "cusum", "bocpd")
RIVER = ("fhddm", "ddm", "adwin")


class BenchConfig(Config):
    """Benchmark settings (see the module docstring).

    ``p_post``: explicit post-change rates, one table row each, instead of the ``categories``'
    computed ones; ``streams`` per category (or ``p_post`` value); the change is at a step uniform
    in ``[change_min, change_max]``; undetected ``horizon`` results after it, a miss;
    ``tune_actions`` change-free actions tune every detector; ``fa_target`` per 10,000 actions;
    ``n_lt``, ``n_st``: our detectors' windows.
    """

    what: ClassVar[str] = "bench detect"

    p_pre: Rate = 0.01
    p_post: tuple[Annotated[float, Field(gt=0, le=1)], ...] | None = None
    categories: Annotated[tuple[Name, ...],
                          AfterValidator(each(member_of("category", CATEGORIES)))] = (
        "small", "medium", "large")
    streams: Count = 400
    change_min: Count = 300
    change_max: Count = 1300
    horizon: Count = 1000
    tune_actions: Count = 1_000_000
    fa_target: Positive = 1.0
    n_lt: Whole = 100
    n_st: Whole = 10
    detectors: Annotated[tuple[Name, ...],
                         AfterValidator(each(member_of("detector", OURS + RIVER)))] = OURS + RIVER

    @model_validator(mode="after")
    def _consistent(self) -> BenchConfig:
        if self.change_max < self.change_min:
            raise ValueError("change_max must be >= change_min")
        det.DetectorConfig(n_lt=self.n_lt, n_st=self.n_st)  # validates the windows
        return self


@dataclass
class Row:
    """One detector on one group of streams."""

    group: str
    detector: str
    setting: str
    tuned_fa: float  # per 10,000 actions on the tuning streams
    fa: float  # per 10,000 pre-change actions on the evaluation streams
    median: float  # inf when more than half are missed
    p90: float
    missed: int
    streams: int


@dataclass
class BenchResult:
    rows: list[Row] = field(default_factory=list)
    groups: dict[str, dict] = field(default_factory=dict)  # group -> post-rate summary
    p_pre: float = 0.0


# -- streams ---------------------------------------------------------------------------------------
def post_rates(
    category: str, n: int, *, rng: np.random.Generator, model=None, keyboard: Keyboard | None = None,
    melody: str = DEFAULT_MELODY,
) -> np.ndarray:
    """(n,) failure rates of the melody player after ``n`` random translations of a category."""
    kb = keyboard if keyboard is not None else Keyboard(KeyboardConfig())
    model = ExactModel(kb) if model is None else model
    mel = parse_melody(melody, kb)
    params = draw(category, "translation", n, rng=rng)
    return expected_failure_rate(model, kb, mel, "translation", params, rng=rng)


def make_streams(
    p_pre: float, p_post: np.ndarray, change: np.ndarray, length: int, *, rng: np.random.Generator
) -> np.ndarray:
    """(S, length) int8 Bernoulli failures: rate ``p_pre`` before ``change[s]``, ``p_post[s]`` after."""
    t = np.arange(length)[None, :]
    p = np.where(t < np.asarray(change)[:, None], p_pre, np.asarray(p_post)[:, None])
    return (rng.random(p.shape) < p).astype(np.int8)


# -- river -----------------------------------------------------------------------------------------
def _river(warm_start: int = 110) -> dict[str, Callable[[float], object]]:
    try:
        from river.drift import ADWIN
        from river.drift.binary import DDM, FHDDM
    except ImportError:  # pragma: no cover - depends on the environment
        raise KbcliError(
            "the detector benchmark compares against river: pip install 'kbcli[bench]' (or river)"
        ) from None
    return {
        "ddm": lambda v: DDM(drift_threshold=v, warm_start=warm_start),
        "fhddm": lambda v: FHDDM(confidence_level=10.0**v),
        "adwin": lambda v: ADWIN(delta=10.0**v, clock=1),
    }


#: river detector -> (name of the tuned parameter, search interval, larger is less sensitive?)
RIVER_PARAM = {
    "ddm": ("drift_threshold", (2.0, 40.0), True),
    "fhddm": ("log10 confidence_level", (-60.0, -1e-3), False),
    "adwin": ("log10 delta", (-20.0, -1e-3), False),
}
FLIP = {"fhddm": True, "ddm": False, "adwin": False}  # FHDDM watches the success rate


def river_run(name: str, value: float, x: np.ndarray, *, warm_start: int = 110,
              stop_after: np.ndarray | None = None) -> list[list[int]]:
    """Alarm steps of a river detector on each stream (it restarts itself after an alarm).

    ``warm_start``: DDM's warm-up (we give it ours, ``n_lt + n_st``). ``stop_after[s]``: stop
    stream ``s`` at its first alarm at or after that step (None: at the first alarm).
    """
    make = _river(warm_start)[name]
    flip = FLIP[name]
    out = []
    for s, row in enumerate(x):
        d = make(value)
        alarms: list[int] = []
        stop = 0 if stop_after is None else int(stop_after[s])
        vals = (1 - row if flip else row).tolist()
        for t, v in enumerate(vals):
            d.update(v)
            if d.drift_detected:
                alarms.append(t)
                if t >= stop:
                    break
        out.append(alarms)
    return out


# -- tuning --------------------------------------------------------------------------------------
def tuning_streams(cfg: BenchConfig, *, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Change-free streams shaped like the evaluation's pre-change segments.

    Returns ``x`` (S, change_max) and the length of each stream (S,), uniform in
    ``[change_min, change_max]``, so that the tuned false-alarm rate is the one measured on the
    evaluation's pre-change actions. ``S`` gives about ``tune_actions`` actions in all.
    """
    mean_len = (cfg.change_min + cfg.change_max) / 2
    n = max(1, int(round(cfg.tune_actions / mean_len)))
    lengths = rng.integers(cfg.change_min, cfg.change_max + 1, size=n)
    x = make_streams(cfg.p_pre, np.full(n, cfg.p_pre), np.full(n, cfg.change_max), cfg.change_max,
                     rng=rng)
    return x, lengths


def fa_rate(alarms: list, lengths: np.ndarray) -> float:
    """False alarms per 10,000 actions: alarm steps per stream, counted within each stream's length."""
    lengths = np.asarray(lengths)
    n = sum(int((np.asarray(al) < lengths[s]).sum()) for s, al in enumerate(alarms))
    return 1e4 * n / max(int(lengths.sum()), 1)


def tune_ours(cfg: det.DetectorConfig, x: np.ndarray, lengths: np.ndarray,
              target: float) -> tuple[float, float]:
    """Largest threshold with at most ``target`` false alarms per 10,000 actions on ``x``.

    Searched on the scores of a detector that never restarts (the first crossing is the first alarm;
    a second alarm in a stream is ignored); the returned rate is measured with restarts. Returns
    ``(threshold, rate)``.
    """
    scores, _ = det.run_batch(cfg, x, restart=False)
    below_end = np.arange(x.shape[1])[None, :] < np.asarray(lengths)[:, None]
    running_min = np.minimum.accumulate(np.where(below_end, scores, 1.0), axis=1)

    def rate(log_thr: float) -> float:
        first = det.first_crossing(running_min, 10.0**log_thr)
        return fa_rate([[f] if f >= 0 else [] for f in first], lengths)

    lo, hi = -300.0, math.log10(0.999)
    if rate(hi) > target:
        for _ in range(60):
            mid = (lo + hi) / 2
            if rate(mid) <= target:
                lo = mid
            else:
                hi = mid
        hi = lo
    thr = 10.0**hi
    while True:  # restarts can add a few alarms: step down until the measured rate is in target
        _, fired = det.run_batch(cfg.replace(threshold=thr), x, restart=True)
        r = fa_rate([np.flatnonzero(f) for f in fired], lengths)
        if r <= target or thr < 1e-300:
            return thr, r
        crossed = running_min[running_min < thr]
        thr = float(crossed.max()) if crossed.size else thr * 0.5  # the next lower score level


def tune_river(name: str, x: np.ndarray, lengths: np.ndarray, target: float, *,
               warm_start: int = 110, iters: int = 9) -> tuple[float, float]:
    """Most sensitive parameter of a river detector with at most ``target`` false alarms per 10,000
    actions on ``x`` (bisection); returns ``(value, rate)``; the rate is above ``target`` when even
    the least sensitive value of the search interval does not reach it."""
    _, (a, b), larger_safer = RIVER_PARAM[name]
    xs = [row[:n] for row, n in zip(x, lengths, strict=True)]

    def rate(v: float) -> float:
        return fa_rate(river_run(name, v, xs, warm_start=warm_start, stop_after=lengths), lengths)

    safe, risky = (b, a) if larger_safer else (a, b)
    r_safe = rate(safe)
    if r_safe > target:
        return safe, r_safe
    for _ in range(iters):
        mid = (safe + risky) / 2
        r = rate(mid)
        if r <= target:
            safe, r_safe = mid, r
        else:
            risky = mid
    return safe, r_safe


#: DDM warm-ups tried in turn, multiples of ours (n_lt + n_st); the first reaching the target wins
DDM_WARM_STARTS = (1, 2, 3, 5, 10)


# -- evaluation -------------------------------------------------------------------------------------
def _summary(group: str, name: str, setting: str, tuned: float, alarms: list[np.ndarray],
             change: np.ndarray, horizon: int) -> Row:
    n_fa = 0
    delays = np.full(len(change), np.inf)
    for s, al in enumerate(alarms):
        al = np.asarray(al)
        n_fa += int((al < change[s]).sum())
        after = al[(al >= change[s]) & (al < change[s] + horizon)]
        if len(after):
            delays[s] = after[0] - change[s] + 1
    fa = 1e4 * n_fa / change.sum()
    med = float(np.quantile(delays, 0.5, method="inverted_cdf"))
    p90 = float(np.quantile(delays, 0.9, method="inverted_cdf"))
    return Row(group=group, detector=name, setting=setting, tuned_fa=tuned, fa=fa, median=med,
               p90=p90, missed=int(np.isinf(delays).sum()), streams=len(change))


def run(cfg: BenchConfig, *, rng: np.random.Generator, model=None, keyboard: Keyboard | None = None,
        melody: str = DEFAULT_MELODY) -> Iterator[tuple[str, BenchResult]]:
    """Run the benchmark; yields ``(what is done, result so far)`` after each piece of work."""
    res = BenchResult(p_pre=cfg.p_pre)
    tune_rng, rate_rng, eval_rng = rng.spawn(3)
    tune_x, tune_len = tuning_streams(cfg, rng=tune_rng)
    settings: dict[str, tuple[float, float, str]] = {}
    warm_starts: dict[str, int] = {}
    for name in cfg.detectors:
        if name in OURS:
            dc = det.DetectorConfig(detector=name, n_lt=cfg.n_lt, n_st=cfg.n_st)
            thr, r = tune_ours(dc, tune_x, tune_len, cfg.fa_target)
            settings[name] = (thr, r, f"threshold {thr:.3g}")
        else:
            for mult in DDM_WARM_STARTS if name == "ddm" else (1,):
                warm = mult * (cfg.n_lt + cfg.n_st)
                v, r = tune_river(name, tune_x, tune_len, cfg.fa_target, warm_start=warm)
                if r <= cfg.fa_target:
                    break
            shown = {"ddm": f"drift_threshold {v:.3g}, warm_start {warm}",
                     "fhddm": f"confidence_level {10.0**v:.3g}",
                     "adwin": f"delta {10.0**v:.3g}"}[name]
            settings[name] = (v, r, shown)
            warm_starts[name] = warm
        yield f"tuned {name}", res

    if cfg.p_post is not None:
        groups = {f"p_post={p:g}": np.full(cfg.streams, p) for p in cfg.p_post}
    else:
        groups = {c: post_rates(c, cfg.streams, rng=rate_rng, model=model, keyboard=keyboard,
                                melody=melody) for c in cfg.categories}
    for group, p_post in groups.items():
        res.groups[group] = {"median_p_post": float(np.median(p_post)),
                             "p10": float(np.quantile(p_post, 0.1)),
                             "p90": float(np.quantile(p_post, 0.9))}
        change = eval_rng.integers(cfg.change_min, cfg.change_max + 1, size=cfg.streams)
        length = cfg.change_max + cfg.horizon
        x = make_streams(cfg.p_pre, p_post, change, length, rng=eval_rng)
        for name in cfg.detectors:
            value, tuned, shown = settings[name]
            if name in OURS:
                dc = det.DetectorConfig(detector=name, n_lt=cfg.n_lt, n_st=cfg.n_st, threshold=value)
                _, fired = det.run_batch(dc, x, restart=True)
                alarms = [np.flatnonzero(f) for f in fired]
            else:
                alarms = river_run(name, value, x, warm_start=warm_starts[name], stop_after=change)
            res.rows.append(_summary(group, name, shown, tuned, alarms, change, cfg.horizon))
            yield f"{group}: {name}", res
