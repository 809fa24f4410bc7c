"""Benchmark of learning the instrument model (issue 3): sample efficiency and speed.

On the default 4 x 8 keyboard of 50 px keys, each exploration strategy learns the model from
``seeds`` seeds (``SeedSequence(seed).spawn(seeds)``; run ``i`` uses the same seed for every
strategy) up to the largest budget. Every ``resolution`` reaches and at each budget the model is
scored on a 2 px grid over the working area (accuracy, :mod:`kbcli.core.accuracy`). Reported per
strategy: the median accuracy at each budget, the median number of reaches until the accuracy first
reaches 99 % (runs that never do count as more than the largest budget), and the median boundary
error (px, on a 1 px grid) at ``boundary_budget`` reaches. Speed: the wall time of a whole
``learn`` stage run at ``boundary_budget`` reaches (the first seed, active strategy) and the
``dynamics`` simulator's reaches per second on one core.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from kbcli.core import accuracy as scoring
from kbcli.core.explore import STRATEGIES, Exploration, ExploreConfig
from kbcli.core.keyboard import Keyboard, KeyboardConfig
from kbcli.errors import ConfigError
from kbcli.sim import MODES, SimConfig, World, make_reacher
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage

DEFAULT_BUDGETS = (50, 100, 200, 400, 800, 1600)
STRATEGY_ORDER = ("active", "random")


@dataclass(frozen=True, kw_only=True)
class BenchConfig:
    """Benchmark settings (see the module docstring)."""

    seeds: int = 10
    budgets: tuple[int, ...] = DEFAULT_BUDGETS
    strategies: tuple[str, ...] = STRATEGY_ORDER
    mode: str = "ideal"
    reach_noise: float = 0.0
    seed: int = 0
    resolution: int = 50
    boundary_budget: int = 800

    def __post_init__(self) -> None:
        if not isinstance(self.seeds, int) or self.seeds < 1:
            raise ConfigError(f"seeds must be a whole number >= 1, got {self.seeds!r}")
        if not self.budgets or any(not isinstance(b, int) or b < 1 for b in self.budgets):
            raise ConfigError(f"budgets must be whole numbers >= 1, got {self.budgets!r}")
        object.__setattr__(self, "budgets", tuple(sorted(set(self.budgets))))
        for s in self.strategies:
            if s not in STRATEGIES:
                raise ConfigError(f"unknown strategy {s!r}; valid: {', '.join(sorted(STRATEGIES))}")
        if not self.strategies:
            raise ConfigError("give at least one strategy")
        SimConfig(mode=self.mode, reach_noise=self.reach_noise)
        if not isinstance(self.resolution, int) or self.resolution < 1:
            raise ConfigError(f"resolution must be a whole number >= 1, got {self.resolution!r}")
        if not isinstance(self.boundary_budget, int) or self.boundary_budget < 1:
            raise ConfigError(f"boundary budget must be >= 1, got {self.boundary_budget!r}")

    @property
    def max_budget(self) -> int:
        return max(*self.budgets, self.boundary_budget)

    def sim(self) -> SimConfig:
        return SimConfig(mode=self.mode, reach_noise=self.reach_noise)


@dataclass
class RunResult:
    """One strategy and seed: accuracy at each checkpoint, boundary error at the boundary budget."""

    strategy: str
    seed_index: int
    checkpoints: list[int] = field(default_factory=list)
    accuracy: list[float] = field(default_factory=list)
    boundary_error: float = float("nan")

    def at(self, n: int) -> float:
        return self.accuracy[self.checkpoints.index(n)]

    def reaches_to(self, level: float) -> float:
        """First checkpoint whose accuracy is at least ``level`` (inf if none)."""
        for n, a in zip(self.checkpoints, self.accuracy, strict=True):
            if a >= level:
                return float(n)
        return float("inf")


def one_run(cfg: BenchConfig, strategy: str, seed_index: int, seed: np.random.SeedSequence,
            kb: Keyboard) -> RunResult:
    """Learn with one strategy and seed up to the largest budget, scoring along the way."""
    rng = np.random.default_rng(seed)
    world = World(kb, make_reacher(cfg.sim()))
    ex = Exploration(ExploreConfig(strategy=strategy, budget=cfg.max_budget), world.touch, kb.area,
                     kb.config.match_threshold, rng)
    res = RunResult(strategy, seed_index)
    marks = set(cfg.budgets) | {cfg.boundary_budget}
    for step in ex:
        n = step.n_reaches
        crossed = [b for b in marks if n - len(step.targets) < b <= n]
        if n % cfg.resolution == 0 or crossed:
            res.checkpoints.append(n)
            res.accuracy.append(scoring.accuracy(step.model, kb, learn_stage.CURVE_STEP))
        if any(b == cfg.boundary_budget for b in crossed):
            pred, true = scoring.key_maps(step.model, kb, learn_stage.EVAL_STEP)
            res.boundary_error = scoring.boundary_error(pred, true, learn_stage.EVAL_STEP)
    return res


def runs(cfg: BenchConfig) -> Iterator[RunResult]:
    """Every (strategy, seed) run, one at a time."""
    kb = Keyboard(KeyboardConfig())
    seeds = np.random.SeedSequence(cfg.seed).spawn(cfg.seeds)
    for strategy in cfg.strategies:
        for i, s in enumerate(seeds):
            yield one_run(cfg, strategy, i, s, kb)


def nearest_checkpoint(r: RunResult, budget: int) -> float:
    """Accuracy at the first checkpoint at or after ``budget`` (batches may overshoot it)."""
    for n, a in zip(r.checkpoints, r.accuracy, strict=True):
        if n >= budget:
            return a
    return r.accuracy[-1]


def summarize(cfg: BenchConfig, results: list[RunResult]) -> list[dict]:
    """Per strategy: median accuracy per budget, median reaches to 99 %, boundary error."""
    rows = []
    for strategy in cfg.strategies:
        rs = [r for r in results if r.strategy == strategy]
        if not rs:
            continue
        to99 = np.array([r.reaches_to(learn_stage.TARGET_ACCURACY) for r in rs])
        rows.append({
            "strategy": strategy,
            "runs": len(rs),
            "accuracy": {b: float(np.median([nearest_checkpoint(r, b) for r in rs]))
                         for b in cfg.budgets},
            "to99": float(np.median(to99)),
            "never99": int(np.isinf(to99).sum()),
            "boundary_error": float(np.median([r.boundary_error for r in rs])),
        })
    return rows


def learn_wall_time(cfg: BenchConfig) -> float:
    """Seconds for one whole ``learn`` stage run at ``boundary_budget`` reaches (active, seed 0)."""
    kb_art = keyboard_stage.run(KeyboardConfig())
    lc = learn_stage.LearnConfig(strategy="active", budget=cfg.boundary_budget, sim=cfg.sim())
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


__all__ = ["MODES", "BenchConfig", "RunResult", "runs", "summarize", "learn_wall_time",
           "dynamics_rate"]
