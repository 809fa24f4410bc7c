"""The sweep's tasks: one per model to learn, one per adaptation, each with its seed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kbcli.stages.config import check_total
from kbcli.stages.quality.config import EXACT, IDEAL_ROW, QualityConfig, model_names

#: Spawn keys of the learning and the adapting seeds.
LEARN_KEY = 1
ADAPT_KEY = 2


@dataclass(frozen=True)
class LearnTask:
    name: str
    exploration: str
    budget: int
    seed: int


def learn_tasks(cfg: QualityConfig) -> list[LearnTask]:
    """One task per model; model ``i`` is learned with seed ``SeedSequence(seed, (1, i))``'s."""
    out = []
    for i, (name, e, b) in enumerate(model_names(cfg)):
        ss = np.random.SeedSequence(cfg.seed, spawn_key=(LEARN_KEY, i))
        out.append(LearnTask(name, e, b, int(ss.generate_state(1)[0])))
    return out


@dataclass(frozen=True)
class Task:
    row: int
    model: str
    category: str
    param_index: int
    params: tuple[float, ...]
    method: str
    rep: int
    entropy: int
    spawn_key: tuple[int, ...]


def plan(cfg: QualityConfig) -> list[Task]:
    """Every adaptation of the sweep, in artifact order (model, category, displacement, row,
    repetition; then, with ``ideal``, the exact model's). The seed depends on (category,
    displacement, repetition) only: the same for every model and row (paired)."""
    names = [n for n, _, _ in model_names(cfg)]
    cells = sum(len(cat.displacements) for cat in cfg.categories) * cfg.experiments
    check_total((len(names) * len(cfg.rows) + bool(cfg.ideal)) * cells, "quality")
    tasks: list[Task] = []
    for name, rows in [*((n, list(cfg.rows)) for n in names),
                       *([(EXACT, [IDEAL_ROW])] if cfg.ideal else [])]:
        for ci, cat in enumerate(cfg.categories):
            for p, params in enumerate(cat.displacements):
                for row in rows:
                    for rep in range(cfg.experiments):
                        tasks.append(Task(len(tasks), name, cat.name, p, tuple(params), row, rep,
                                          int(cfg.seed), (ADAPT_KEY, ci, p, rep)))
    return tasks


