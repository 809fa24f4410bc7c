"""Benchmark of the adaptation that repairs the model: weak models, and a lifelong robot.

**Side by side.** Weak models, as ``kbcli learn --strategy random --budget 250 --seed S`` learns
them (seeds 1-3, the ideal and the realistic arm), each adapted to the same ``moves``
displacements (:func:`moves`), each ``replicates`` times (one adaptation seed each), with
``touches`` infogain touches by three methods on the same seeds:
``plain`` (the robust posterior, kbcli's default), ``repair`` (``repair = true``:
:mod:`kbcli.core.adaptation.repair`) and ``exact`` (the keyboard's own geometry, the reference). Per
method: the median final error, the share of runs under 1 px, the median touches to *stay* under
1 px (``touches + 1`` when never), the runs made worse than ``plain`` by more than 0.5 px, the share
of 90 % credible discs holding the truth (:mod:`kbcli.core.adaptation.credible`) and the median
time of a touch; per model, the median final error, beside the model's samples floor
(:func:`sample_floors`), and the final offset split into the model's *systematic* part (its mean
offset over its runs, the same whatever the move and seed) and the *spread* around it
(:func:`systematic`).

**Lifelong.** A weak model, the keyboard moved ``episodes`` times in a row
(:func:`lifelong_moves`), the robot adapting with ``repair`` and carrying its repaired model
(:func:`kbcli.stages.repair.repaired_model`) from episode to episode, beside ``plain`` with the
model as learned, and beside ``repair`` with the model as learned (what carrying the model
changed). Per episode: the three's touches to stay under 1 px and final error, and the carried
model's boundary error; per model, what the lifelong targets read of it (:func:`lifelong_summary`).

Pure: returns rows.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from kbcli.bench.repair_floor import model_floor
from kbcli.core.adaptation import credible
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.sim import SimConfig
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage
from kbcli.stages import repair as repair_stage
from kbcli.stages.adapt import AdaptConfig, build_shared_table, experiment
from kbcli.stages.models import load_model

#: The methods, in print order: (name, robot options, exact model).
METHODS = (("plain", {}, False), ("repair", {"repair": True}, False), ("exact", {}, True))
#: The arms of the weak models: (mode, arm preset).
ARMS = (("ideal", "ideal"), ("dynamics", "realistic"))
#: A run made worse than plain by more than this (px) counts as harmed.
WORSE_PX = 0.5
#: The golden angle (rad): successive moves point in well-spread directions.
GOLDEN = np.pi * (3.0 - np.sqrt(5.0))


def moves(n: int, low: float = 5.0, high: float = 30.0) -> np.ndarray:
    """(n, 2) displacements: magnitudes evenly spread over [low, high] px, directions stepping
    by the golden angle."""
    mags = np.linspace(low, high, n) if n > 1 else np.array([(low + high) / 2])
    ang = 0.3 + GOLDEN * np.arange(n)
    return np.column_stack([mags * np.cos(ang), mags * np.sin(ang)])


def lifelong_moves(n: int, seed: int = 0) -> np.ndarray:
    """(n, 2) poses of the keyboard for ``n`` moves in a row: magnitudes uniform in [5, 30] px,
    directions uniform (each pose relative to the model's reference frame)."""
    rng = np.random.default_rng([seed, 42])
    mags = rng.uniform(5.0, 30.0, n)
    ang = rng.uniform(0.0, 2 * np.pi, n)
    return np.column_stack([mags * np.cos(ang), mags * np.sin(ang)])


@dataclass(frozen=True)
class WeakModel:
    """A weak model learned for the benchmark: its artifact (in memory), model and arm."""

    name: str
    artifact: object
    model: object
    mode: str
    arm: str


def weak_models(seeds=(1, 2, 3), budget: int = 250, arms=ARMS,
                progress: Callable[[str], None] | None = None) -> list[WeakModel]:
    """The weak models of the protocol (``kbcli learn --strategy random --budget 250 --seed S``,
    ``--mode MODE --arm ARM``), learned in memory on the default keyboard."""
    kb_art = keyboard_stage.run(KeyboardConfig())
    out = []
    for mode, arm in arms:
        for s in seeds:
            if progress is not None:
                progress(f"learning {arm} arm, seed {s}")
            cfg = learn_stage.LearnConfig(strategy="random", budget=int(budget),
                                          sim=SimConfig(mode=mode, arm=arm))
            art = learn_stage.run(cfg, kb_art, rng=np.random.default_rng(s), seed=s)
            out.append(WeakModel(f"{arm}-{s}", art, load_model(art), mode, arm))
    return out


def sample_floors(models: list[WeakModel]) -> dict[str, float]:
    """Each model's samples floor (px, :mod:`kbcli.bench.repair_floor`): what its own training
    samples pin the shift to with the whole moved keyboard known."""
    return {wm.name: model_floor(wm.model, keyboard_stage.load(wm.artifact)) for wm in models}


def stay_under(errors: np.ndarray, level: float = 1.0) -> int:
    """The touch from which every error is below ``level`` (1-based; ``len + 1`` when the last
    is not)."""
    e = np.asarray(errors, float)
    above = np.flatnonzero(e >= level)
    return 1 if len(above) == 0 else int(above[-1]) + 2


@dataclass
class Run:
    """One adaptation of the side-by-side section."""

    method: str
    model: str
    move: int
    errors: np.ndarray
    covered: bool
    step_ms: float
    offset: np.ndarray

    @property
    def final(self) -> float:
        return float(self.errors[-1])


def adapt_once(wm: WeakModel, model, truth: np.ndarray, options: dict, touches: int,
               rng: np.random.Generator, table=None) -> tuple[dict, object]:
    """One adaptation of ``model`` (``wm``'s arm) to ``truth``: (its records, its adapter)."""
    cfg = AdaptConfig(strategy="infogain", mode=wm.mode, arm=wm.arm, max_steps=touches, **options)
    keep: dict = {}
    kb = keyboard_stage.load(wm.artifact)
    table = build_shared_table(cfg, model) if table is None else table
    res = experiment(cfg, model, kb, truth, rng=rng, table=table, keep=keep)
    return res, keep["adapter"]


def side_by_side(models: list[WeakModel], *, n_moves: int = 8, touches: int = 30, seed: int = 0,
                 replicates: int = 1, methods=METHODS,
                 progress: Callable[[int], None] | None = None) -> list[Run]:
    """Every method on every model and move, paired (the same seed per model and move), each
    move adapted ``replicates`` times (adaptation seeds ``seed``, ``seed + 1``, ...: run
    ``r * n_moves + k`` is move ``k`` at seed ``seed + r``)."""
    runs = []
    for mi, wm in enumerate(models):
        for name, options, exact in methods:
            model = ExactModel(keyboard_stage.load(wm.artifact)) if exact else wm.model
            cfg = AdaptConfig(strategy="infogain", mode=wm.mode, arm=wm.arm, **options)
            table = build_shared_table(cfg, model)
            for r in range(replicates):
                for k, truth in enumerate(moves(n_moves)):
                    rng = np.random.default_rng([seed + r, mi, k])
                    res, ad = adapt_once(wm, model, truth, options, touches, rng, table)
                    est = np.asarray(ad.estimate(), float)
                    runs.append(Run(name, wm.name, r * n_moves + k,
                                    np.asarray(res["errors"], float),
                                    credible.covers(ad.posterior, est, truth),
                                    float(np.median(res["step_ms"])), est[-2:] - truth))
                    if progress is not None:
                        progress(1)
    return runs


def systematic(offsets: np.ndarray, groups) -> tuple[float, dict]:
    """Split final offsets (estimate - truth, (n, 2) px) by ``groups`` (n,; a model's name):
    (the share of the total squared offset that the groups' mean offsets carry, and per group its
    systematic part, the length of its mean offset, and its spread, the rms distance of its
    offsets from that mean). Per group, systematic^2 + spread^2 is its mean squared offset.
    """
    off = np.asarray(offsets, float).reshape(-1, 2)
    keys = np.asarray(groups)
    per, between = {}, 0.0
    for g in dict.fromkeys(keys.tolist()):
        e = off[keys == g]
        mu = e.mean(axis=0)
        between += len(e) * float(mu @ mu)
        per[g] = (float(np.hypot(*mu)), float(np.sqrt(((e - mu) ** 2).sum(axis=1).mean())))
    total = float((off**2).sum())
    return (between / total if total > 0 else 0.0), per


def summarize(runs: list[Run], touches: int) -> list[dict]:
    """One row per method (see the module docstring)."""
    plain = {(r.model, r.move): r.final for r in runs if r.method == "plain"}
    plain_ms = np.median([r.step_ms for r in runs if r.method == "plain"]) if plain else np.nan
    rows = []
    for name in dict.fromkeys(r.method for r in runs):
        mine = [r for r in runs if r.method == name]
        fin = np.array([r.final for r in mine])
        stay = np.array([stay_under(r.errors) for r in mine])
        worse = sum(1 for r in mine if r.final - plain.get((r.model, r.move), np.inf) > WORSE_PX)
        per_model = {m: float(np.median([r.final for r in mine if r.model == m]))
                     for m in dict.fromkeys(r.model for r in mine)}
        ms = float(np.median([r.step_ms for r in mine]))
        share, split = systematic(np.array([r.offset for r in mine]), [r.model for r in mine])
        rows.append({"method": name, "runs": len(mine), "median_final_px": float(np.median(fin)),
                     "under_1px": float(np.mean(fin < 1.0)),
                     "median_touches_stay_1px": float(np.median(stay)),
                     "never_stay_1px": int((stay > touches).sum()),
                     "worse_than_plain": int(worse) if name != "plain" else 0,
                     "coverage_90": float(np.mean([r.covered for r in mine])),
                     "median_ms": ms, "ms_ratio": float(ms / plain_ms),
                     "per_model": per_model, "systematic_share": share,
                     "per_model_offset": split})
    return rows


@dataclass
class Episode:
    """One move of the lifelong section."""

    episode: int
    truth: np.ndarray
    repair_stay: int
    repair_final: float
    plain_stay: int
    plain_final: float
    boundary_error: float
    absorbed: int
    generation: int
    learned_stay: int
    learned_final: float
    extra: dict = field(default_factory=dict)


def lifelong(wm: WeakModel, *, episodes: int = 5, touches: int = 30, seed: int = 0,
             progress: Callable[[int], None] | None = None) -> tuple[float, list[Episode]]:
    """The lifelong section on ``wm``: (its boundary error before the first move, one
    :class:`Episode` per move)."""
    art, model = wm.artifact, wm.model
    start = float(art.attrs["boundary_error_px"])
    tables: dict = {}  # the learned model's raster per method, built once for every move

    def as_learned(options: dict, truth: np.ndarray, e: int) -> tuple[dict, object]:
        key = tuple(sorted(options))
        if key not in tables:
            cfg = AdaptConfig(strategy="infogain", mode=wm.mode, arm=wm.arm, max_steps=touches,
                              **options)
            tables[key] = build_shared_table(cfg, wm.model)
        return adapt_once(wm, wm.model, truth, options, touches,
                          np.random.default_rng([seed, 100, e]), tables[key])

    out = []
    for e, truth in enumerate(lifelong_moves(episodes, seed)):
        if e == 0:  # the first move's model is the learned one
            res, ad = as_learned({"repair": True}, truth, e)
        else:
            res, ad = adapt_once(wm, model, truth, {"repair": True}, touches,
                                 np.random.default_rng([seed, 100, e]))
        plain, _ = as_learned({}, truth, e)
        learned = res if e == 0 else as_learned({"repair": True}, truth, e)[0]
        t0 = time.perf_counter()
        art, summary = repair_stage.repaired_model(
            art, model, [repair_stage.run_adaptation(ad, res)], source="bench")
        model = load_model(art)
        out.append(Episode(e + 1, truth, stay_under(res["errors"]), float(res["errors"][-1]),
                           stay_under(plain["errors"]), float(plain["errors"][-1]),
                           float(summary["boundary_error_px"]), int(summary["absorbed"]),
                           int(summary["generation"]), stay_under(learned["errors"]),
                           float(learned["errors"][-1]), {"refit_s": time.perf_counter() - t0}))
        if progress is not None:
            progress(1)
    return start, out


def lifelong_summary(start: float, episodes: list[Episode]) -> dict:
    """What the lifelong targets read of one model's section: the carried model's boundary
    error before the first move and after each (``errors``), the moves after which it fell
    (``falls``), whether it fell after every move, the touches the repaired belief needed to stay
    under 1 px on the first and on the last move (``touches + 1``: never), and on the ``later``
    moves (all but the first, which adapts with the learned model either way) how often the
    carried model ended closer to the truth than the model as learned, and how often further."""
    errors = [float(start)] + [float(e.boundary_error) for e in episodes]
    falls = int(sum(b < a for a, b in zip(errors[:-1], errors[1:], strict=True)))
    later = episodes[1:]  # the first move adapts with the learned model either way
    return {"errors": errors, "falls": falls, "falls_every": falls == len(episodes),
            "first_stay": int(episodes[0].repair_stay) if episodes else 0,
            "last_stay": int(episodes[-1].repair_stay) if episodes else 0,
            "carried_closer": int(sum(e.repair_final < e.learned_final for e in later)),
            "carried_further": int(sum(e.repair_final > e.learned_final for e in later)),
            "later": len(later)}
