"""Benchmark of the robust posterior on a given model: accuracy and cost per step.

For each reach setting (ideal; ``dynamics`` with the ``realistic`` arm), strategy and posterior
(``robust``, the default; ``plain``, softened by 1 px for a learned model), ``experiments`` paired
adaptations per displacement category, ``max_steps`` touches each. Per row and category: the
median touches until the error first drops below 1 px (``T + 1`` when never), the median and 90th
percentile of the final error, the median step time and the run's CPU time per touch
(:func:`step_time` times the posterior's step alone). Pure: returns rows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from kbcli.stages.adapt import AdaptConfig, build_shared_table, experiment
from kbcli.stages.perturb import CATEGORIES, draw

SETTINGS = (("ideal", "ideal"), ("dynamics", "realistic"))
STRATEGIES = ("random", "active", "infogain")
POSTERIORS = ("robust", "plain")


@dataclass(frozen=True)
class Row:
    mode: str
    arm: str
    strategy: str
    posterior: str
    category: str
    runs: int
    touches_1px: float
    final_median: float
    final_p90: float
    ms_wall: float
    ms_cpu: float


def run(model, keyboard, *, experiments: int = 30, max_steps: int = 30, seed: int = 0,
        settings=SETTINGS, strategies=STRATEGIES, posteriors=POSTERIORS,
        categories=tuple(CATEGORIES), progress=None) -> list[Row]:
    """Rows of the benchmark (see the module docstring); ``progress(n)`` is called per run."""
    rows = []
    for mode, arm in settings:
        for cat in categories:
            truths = draw(cat, "translation", experiments,
                          rng=np.random.default_rng([seed, list(CATEGORIES).index(cat)]))
            seeds = np.random.SeedSequence([seed, 7, list(CATEGORIES).index(cat)]).spawn(
                experiments)
            for strat in strategies:
                for post in posteriors:
                    cfg = AdaptConfig(strategy=strat, mode=mode, arm=arm, max_steps=max_steps,
                                      robust=post == "robust")
                    table = build_shared_table(cfg, model)
                    t1, fin, wall, cpu = [], [], [], []
                    for truth, ss in zip(truths, seeds, strict=True):
                        c0 = time.process_time()
                        out = experiment(cfg, model, keyboard, truth, rng=np.random.default_rng(ss),
                                         table=table)
                        c1 = time.process_time()
                        e = out["errors"]
                        hit = np.flatnonzero(e < 1.0)
                        t1.append(hit[0] + 1 if len(hit) else max_steps + 1)
                        fin.append(e[-1])
                        wall.append(float(np.median(out["step_ms"])))
                        # CPU per step: the whole run's CPU time (reaching included) over its steps
                        cpu.append(1e3 * (c1 - c0) / len(e))
                        if progress is not None:
                            progress(1)
                    rows.append(Row(mode, arm, strat, post, cat, experiments,
                                    float(np.median(t1)), float(np.median(fin)),
                                    float(np.percentile(fin, 90)), float(np.median(wall)),
                                    float(np.median(cpu))))
    return rows


def step_time(model, keyboard, *, runs: int = 10, steps: int = 30, seed: int = 0) -> dict:
    """CPU ms of one translation step of the posterior alone (update with a touch, then the
    estimate; no decision, no reaching), median and 90th percentile over ``runs`` x ``steps``
    touches of the ideal arm at random actions, for the robust and the plain posterior. Run it with
    one thread (``OMP_NUM_THREADS=1``) for a one-core figure."""
    from kbcli.core.adaptation.adapter import Adapter
    from kbcli.core.adaptation.config import AdapterConfig
    from kbcli.core.adaptation.setup import build_table
    from kbcli.sim import SimConfig, World, make_reacher

    out = {}
    for post in POSTERIORS:
        cfg = AdapterConfig(strategy="random", robust=post == "robust")
        table = build_table(model, cfg)
        ms = []
        for r in range(runs):
            rng = np.random.default_rng([seed, 11, r])
            ad = Adapter(model, cfg, rng=rng, table=table)
            world = World(keyboard, make_reacher(SimConfig()), rng.uniform(-20, 20, 2),
                          "translation")
            for _ in range(steps):
                a = ad.suggest()
                felt, heard = world.touch(a[None], rng)
                c0 = time.process_time()
                ad.observe(a, heard[0], felt_position=felt[0])
                ad.estimate()
                ms.append(1e3 * (time.process_time() - c0))
        out[post] = (float(np.median(ms)), float(np.percentile(ms, 90)))
    return out
