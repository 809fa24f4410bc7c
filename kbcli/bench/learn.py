"""Benchmark of learning the instrument model: sample efficiency and speed, per layout and class.

For each layout (:func:`bench_keyboard`, or a given keyboard), model class and exploration
strategy, the model is learned from ``seeds`` seeds up to the largest budget and scored on a grid
of ``eval_step`` px. Per row: the median accuracy at each budget, the median reaches to 97 % and
99 %, the median boundary error at ``boundary_budget`` reaches and the median fit time; and the
wall time of a ``learn`` run and the ``dynamics`` simulator's reaches per second.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated, ClassVar

import numpy as np
from pydantic import AfterValidator, Field, model_validator

from kbcli import __version__
from kbcli.core.config import Config, Count, Name, NonNegativeInt, Positive, each, member_of
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.layouts import LAYOUTS, example_config_fields
from kbcli.core.model import accuracy as scoring
from kbcli.core.model.classes import check_learned, fit_model
from kbcli.core.model.explore import STRATEGIES, Exploration, ExploreConfig
from kbcli.io.atomic import atomic_path
from kbcli.sim import MODES, SimConfig, World, check_keyboard_reachable, make_reacher
from kbcli.sim.config import ReachNoise
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage

DEFAULT_BUDGETS = (200, 400, 800, 1600)
STRATEGY_ORDER = ("active", "random")
#: The strategy the benchmark measures against the baseline (the exploration registered as one).
COMPARED = "active"
LEVELS = (0.97, 0.99)


def bench_keyboard(layout: str) -> Keyboard:
    """The default keyboard of a layout (polygons: the fan of ``pipelines/layouts/polygons.toml``)."""
    return Keyboard(KeyboardConfig(layout=layout, **example_config_fields(layout)))


class BenchConfig(Config):
    """Benchmark settings (see the module docstring)."""

    what: ClassVar[str] = "bench learn"

    seeds: Count = 5
    #: sorted, each once
    budgets: Annotated[tuple[Count, ...], Field(min_length=1),
                       AfterValidator(lambda v: tuple(sorted(set(v))))] = DEFAULT_BUDGETS
    strategies: Annotated[tuple[Name, ...], Field(min_length=1),
                          AfterValidator(each(member_of("strategy", STRATEGIES)))] = STRATEGY_ORDER
    layouts: Annotated[tuple[Name, ...], Field(min_length=1),
                       AfterValidator(each(LAYOUTS.get))] = ("grid",)
    model_classes: Annotated[tuple[Name, ...], Field(min_length=1),
                             AfterValidator(each(check_learned))] = ("lines",)
    mode: Name = "ideal"
    reach_noise: ReachNoise = 0.0
    seed: NonNegativeInt = 0
    resolution: Count = 50
    boundary_budget: Count = 800
    eval_step: Positive = 1.0

    @model_validator(mode="after")
    def _sim(self) -> BenchConfig:
        SimConfig(mode=self.mode, reach_noise=self.reach_noise)
        return self

    @property
    def max_budget(self) -> int:
        return max(*self.budgets, self.boundary_budget)

    @property
    def n_runs(self) -> int:
        return len(self.layouts) * len(self.model_classes) * len(self.strategies) * self.seeds

    def sim(self) -> SimConfig:
        return SimConfig(mode=self.mode, reach_noise=self.reach_noise)


@dataclass
class RunResult:
    """One layout, class, strategy and seed: accuracy at each checkpoint, boundary error at the
    boundary budget, the time of the last fit."""

    strategy: str
    seed_index: int
    layout: str = "grid"
    model_class: str = "lines"
    checkpoints: list[int] = field(default_factory=list)
    accuracy: list[float] = field(default_factory=list)
    boundary_error: float = float("nan")
    fit_seconds: float = float("nan")

    def at(self, n: int) -> float:
        return self.accuracy[self.checkpoints.index(n)]

    def reaches_to(self, level: float) -> float:
        """First checkpoint whose accuracy is at least ``level`` (inf if none)."""
        for n, a in zip(self.checkpoints, self.accuracy, strict=True):
            if a >= level:
                return float(n)
        return float("inf")


def one_run(cfg: BenchConfig, strategy: str, seed_index: int, seed: np.random.SeedSequence,
            kb: Keyboard, model_class: str = "lines") -> RunResult:
    """Learn with one class, strategy and seed up to the largest budget, scoring along the way."""
    rng = np.random.default_rng(seed)
    world = World(kb, make_reacher(cfg.sim()))
    ex = Exploration(ExploreConfig(strategy=strategy, budget=cfg.max_budget,
                                   model_class=model_class),
                     world.touch, kb.area, kb.config.match_threshold, rng)
    res = RunResult(strategy, seed_index, kb.layout, model_class)
    marks = set(cfg.budgets) | {cfg.boundary_budget}
    for step in ex:
        n = step.n_reaches
        crossed = [b for b in marks if n - len(step.targets) < b <= n]
        if n % cfg.resolution == 0 or crossed:
            res.checkpoints.append(n)
            res.accuracy.append(scoring.accuracy(step.model, kb, cfg.eval_step))
        if any(b == cfg.boundary_budget for b in crossed):
            pred, true = scoring.key_maps(step.model, kb, learn_stage.EVAL_STEP)
            res.boundary_error = scoring.boundary_error(pred, true, learn_stage.EVAL_STEP)
    t0 = time.perf_counter()
    fit_model(model_class, ex.landed, ex.perceived, match_threshold=kb.config.match_threshold,
              area=kb.area, targets=ex.targets)
    res.fit_seconds = time.perf_counter() - t0
    return res


def _cache_file(cache: Path, cfg: BenchConfig, kb: Keyboard, model_class: str, strategy: str,
                i: int) -> Path:
    """Where one run's result is kept: named by everything that determines it."""
    key = json.dumps({"keyboard": kb.config.to_dict(), "class": model_class,
                      "strategy": strategy, "seed": cfg.seed, "i": i, "budgets": cfg.budgets,
                      "boundary": cfg.boundary_budget, "mode": cfg.mode,
                      "noise": cfg.reach_noise, "resolution": cfg.resolution,
                      "eval_step": cfg.eval_step, "version": __version__}, sort_keys=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    return cache / f"learn-{kb.layout}-{model_class}-{strategy}-{i}-{digest}.json"


def runs(cfg: BenchConfig, keyboard: Keyboard | None = None,
         cache: str | os.PathLike | None = None) -> Iterator[RunResult]:
    """Every (layout, class, strategy, seed) run, one at a time (``keyboard``: instead of the
    layouts' default keyboards). With ``cache`` (a folder), a run already done with the same
    settings is read back instead of run again (runs are deterministic), and each new run is
    kept there."""
    seeds = np.random.SeedSequence(cfg.seed).spawn(cfg.seeds)
    kbs = [keyboard] if keyboard is not None else [bench_keyboard(name) for name in cfg.layouts]
    folder = None if cache is None else Path(cache)
    for kb in kbs:
        check_keyboard_reachable(cfg.sim(), kb)
        for model_class in cfg.model_classes:
            for strategy in cfg.strategies:
                for i, s in enumerate(seeds):
                    path = None if folder is None else _cache_file(folder, cfg, kb, model_class,
                                                                   strategy, i)
                    if path is not None and path.is_file():
                        yield RunResult(**json.loads(path.read_text()))
                        continue
                    res = one_run(cfg, strategy, i, s, kb, model_class)
                    if path is not None:
                        with atomic_path(path, suffix=".json") as tmp:
                            Path(tmp).write_text(json.dumps(asdict(res)))
                    yield res


def nearest_checkpoint(r: RunResult, budget: int) -> float:
    """Accuracy at the first checkpoint at or after ``budget`` (batches may overshoot it)."""
    for n, a in zip(r.checkpoints, r.accuracy, strict=True):
        if n >= budget:
            return a
    return r.accuracy[-1]


def summarize(cfg: BenchConfig, results: list[RunResult]) -> list[dict]:
    """Per (layout, class, strategy): median accuracy per budget, median reaches to 97 % and 99 %
    (and how many runs never got there), boundary error, fit time."""
    rows = []
    keys = dict.fromkeys((r.layout, r.model_class, r.strategy) for r in results)
    for layout, model_class, strategy in keys:
        rs = [r for r in results
              if (r.layout, r.model_class, r.strategy) == (layout, model_class, strategy)]
        to = {lv: np.array([r.reaches_to(lv) for r in rs]) for lv in LEVELS}
        rows.append({
            "layout": layout,
            "model_class": model_class,
            "strategy": strategy,
            "runs": len(rs),
            "accuracy": {b: float(np.median([nearest_checkpoint(r, b) for r in rs]))
                         for b in cfg.budgets},
            "to": {lv: float(np.median(v)) for lv, v in to.items()},
            "never": {lv: int(np.isinf(v).sum()) for lv, v in to.items()},
            "to99": float(np.median(to[0.99])),
            "never99": int(np.isinf(to[0.99]).sum()),
            "boundary_error": float(np.median([r.boundary_error for r in rs])),
            "fit_seconds": float(np.median([r.fit_seconds for r in rs])),
        })
    return rows


def ratios(rows: list[dict], level: float = 0.97) -> list[dict]:
    """Per (layout, class) with both strategies: active's median reaches to ``level`` over
    random's (an upper bound when random never got there: ``bound``)."""
    out = []
    by = {(r["layout"], r["model_class"], r["strategy"]): r for r in rows}
    for (layout, model_class, strategy), r in by.items():
        other = by.get((layout, model_class, STRATEGIES.having("baseline")[0]))
        if strategy != COMPARED or other is None:
            continue
        a, b = r["to"][level], other["to"][level]
        out.append({"layout": layout, "model_class": model_class, "active": a, "random": b,
                    "ratio": a / b if np.isfinite(a) and np.isfinite(b) else
                    (float("nan") if not np.isfinite(a) else 0.0),
                    "bound": bool(np.isfinite(a) and not np.isfinite(b))})
    return out


def learn_wall_time(cfg: BenchConfig, keyboard: Keyboard | None = None) -> float:
    """Seconds for one whole ``learn`` stage run at ``boundary_budget`` reaches (active, seed 0,
    the first layout and model class)."""
    kb = keyboard if keyboard is not None else bench_keyboard(cfg.layouts[0])
    kb_art = keyboard_stage.run(kb.config)
    lc = learn_stage.LearnConfig(strategy="active", budget=cfg.boundary_budget, sim=cfg.sim(),
                                 model_class=cfg.model_classes[0])
    t = time.perf_counter()
    learn_stage.run(lc, kb_art, rng=np.random.default_rng(cfg.seed), seed=cfg.seed)
    return time.perf_counter() - t


def dynamics_rate(n: int = 1000, seed: int = 0, reach_noise: float = 0.0) -> float:
    """Reaches per second of the ``dynamics`` arm over targets uniform in the working area."""
    kb = Keyboard(KeyboardConfig())
    reacher = make_reacher(SimConfig(mode="dynamics", reach_noise=reach_noise))
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = kb.area
    targets = rng.uniform((x0, y0), (x1, y1), size=(n, 2))
    t = time.perf_counter()
    reacher.reach(targets, rng)
    return n / (time.perf_counter() - t)


__all__ = ["MODES", "LAYOUTS", "BenchConfig", "RunResult", "runs", "summarize", "ratios",
           "learn_wall_time", "dynamics_rate", "bench_keyboard"]


def _reaches(r: dict, level: float, max_budget: int) -> str:
    v = r["to"][level]
    txt = f"> {max_budget}" if np.isinf(v) else f"{v:g}"
    never = r["never"][level]
    return txt + (f" ({never} never)" if never else "")


def table(cfg: BenchConfig, rows: list[dict]) -> tuple[list[str], list[list[str]]]:
    """The benchmark table: header and rows of text (printed by ``kbcli bench learn`` and written
    by ``kbcli bench layouts``)."""
    head = ["layout", "model class", "strategy", *[f"@{b}" for b in cfg.budgets],
            "reaches to 97 %", "reaches to 99 %", f"boundary err @{cfg.boundary_budget} (px)",
            f"fit @{cfg.max_budget} (s)"]
    body = []
    for r in rows:
        body.append([r["layout"], r["model_class"], r["strategy"],
                     *[f"{100 * r['accuracy'][b]:.2f}" for b in cfg.budgets],
                     _reaches(r, 0.97, cfg.max_budget), _reaches(r, 0.99, cfg.max_budget),
                     f"{r['boundary_error']:.2f}", f"{r['fit_seconds']:.2f}"])
    return head, body


def ratio_lines(cfg: BenchConfig, rows: list[dict]) -> list[str]:
    """One line per (layout, class): active / random reaches to 97 %."""
    out = []
    for q in ratios(rows, 0.97):
        if q["bound"]:
            txt = (f"< {q['active'] / cfg.max_budget:.2f} (random never reached 97 % within "
                   f"{cfg.max_budget})")
        elif np.isnan(q["ratio"]):
            txt = "n/a (active never reached 97 %)"
        else:
            txt = f"{q['ratio']:.2f}"
        out.append(f"{q['layout']}, {q['model_class']}: active / random reaches to 97 %: {txt}")
    return out
