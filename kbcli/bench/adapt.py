"""Benchmark of the adaptation (issue 5; paper Sect. IV-A, IV-B): sample efficiency and speed.

On a layout's default keyboard (the 4 x 8 grid of 50 px keys unless told otherwise), ``ideal`` mode, ``experiments`` runs per displacement
category and strategy, each run ``max_steps`` observations. True displacements come from
:func:`kbcli.stages.perturb.draw` (the same categories as ``kbcli perturb``: the largest per-axis
displacement in (0, 10], (10, 20] or (20, 40] px; rigid draws also turn by up to 5 degrees); run
``i`` of a category uses the same displacement and the same seed (``SeedSequence(seed).spawn(n)``)
for every strategy (a paired design). The categories are :mod:`kbcli.stages.perturb`'s: the
Euclidean norm of the translation in (0, 10], (10, 20] or (20, 40] px. Per strategy and category it
reports the median observations until the error is below 4, 2, 1, 0.5 px (first step below; runs
that never get there within T count as T + 1, and how many never do), the RMSE at steps 1, 2, 3, 5,
10, 20, 40, the p-value of the Wilcoxon signed-rank test of those counts against ``random`` on the
paired runs (:func:`kbcli.core.stats.signed_rank_pvalues`; the smallest p-value ``n`` pairs can
give is ``2 / 2^n``) and the median milliseconds per step (decision plus update).

For the rigid family a threshold of ``t`` px also asks the angle to be within ``t / 2`` degrees
(1 px and 0.5 degree, the issue's target): the counted error is ``max(px error, 2 * angle error)``.

Sections (``--section``):

- ``exact``: the exact model, translation, no reach noise (estimator quality alone);
- ``noise``: 2 px reach noise, the robot knowing only where it *aimed* (``feedback = aim``: its
  likelihood is blurred by the noise); plus infogain knowing where it landed, for reference;
- ``rigid``: the rigid family (angles up to 5 degrees);
- ``kde``: the paper's KDE posterior (Eq. 7) against the likelihood posterior; and, with a learned
  model (``--model``, default ``data/default-model.h5`` when present), the speed of one KDE step
  (:func:`kde_speed`: Algorithm 2's binning and FFT plus the posterior update, with the per-class
  samples drawn once) against a likelihood step, in ms;
- ``learned``: a learned model (``--model``, any model class), with its boundary error beside the
  final error; its map softened by ``model_blur`` (default: 1 px, the adapter's default for learned
  models) and, for reference, infogain on the unsoftened map;
- ``learned-rigid``: the learned model with the rigid family.

Every section runs on one keyboard: the default keyboard of ``layout`` (grid, hex, piano, pads,
polygons; ``kbcli bench adapt --layout``), or the learned model's own keyboard.

Measured before the size categories became Euclidean and the test paired (seed 0, 50 runs per row, shared 2-core machine; medians to < 1 px for small / medium /
large): exact model, infogain 6 / 6 / 5 and active 7 / 7 / 6 observations, random 27 / 22 / 23 of 50
runs never within 40; p <= 1e-13 at 1 px; about 0.7-1 ms per step. 2 px noise, aim-only: infogain
RMSE at step 20 0.97 / 1.01 / 0.90 px (near the information limit of a 2 px-blurred edge; with
landed feedback 0.41 / 0.29 / 0.36). Rigid: infogain 8 / 8 / 7, active 10 / 10 / 9 (to 1 px and 0.5
deg), 27-34 ms per step. KDE posterior: infogain 6 / 6 / 5, about 5 ms per step. ``kbcli learn``'s
default model (800 active reaches, 0.15 px boundary error): infogain 5 / 4 / 4 to < 2 px, final
0.23 px. A 400-reach random model (4.15 px boundary error): infogain drifts to 14-16 px with the
map unsoftened or softened by 1 px (worse than random, 4-5 px), 2.6 px softened by 4 px.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from kbcli.core import stats
from kbcli.core.adapt import Adapter, AdapterConfig, build_samples, build_table
from kbcli.core.keyboard import Keyboard, KeyboardConfig
from kbcli.core.layouts import LAYOUTS, example_config_fields
from kbcli.core.model import ExactModel
from kbcli.core.posteriors import POSTERIORS
from kbcli.core.transforms import FAMILIES
from kbcli.errors import ConfigError
from kbcli.stages.adapt import AdaptConfig, experiment
from kbcli.stages.perturb import CATEGORIES, draw

SECTIONS = ("exact", "noise", "rigid", "kde", "learned", "learned-rigid")
STRATEGY_ORDER = ("random", "active", "infogain")
THRESHOLDS = (4.0, 2.0, 1.0, 0.5)
RMSE_STEPS = (1, 2, 3, 5, 10, 20, 40)


@dataclass(frozen=True, kw_only=True)
class BenchConfig:
    """Benchmark settings (see the module docstring)."""

    experiments: int = 50
    max_steps: int = 40
    seed: int = 0
    sections: tuple[str, ...] = ("exact", "noise", "rigid", "kde")
    strategies: tuple[str, ...] = STRATEGY_ORDER
    categories: tuple[str, ...] = tuple(CATEGORIES)
    noise: float = 2.0
    model_blur: float | None = None
    layout: str = "grid"

    def __post_init__(self) -> None:
        LAYOUTS.get(self.layout)
        if not isinstance(self.experiments, int) or self.experiments < 2:
            raise ConfigError(f"experiments must be a whole number >= 2, got {self.experiments!r}")
        if not isinstance(self.max_steps, int) or self.max_steps < 1:
            raise ConfigError(f"max_steps must be a whole number >= 1, got {self.max_steps!r}")
        for s in self.sections:
            if s not in SECTIONS:
                raise ConfigError(f"unknown section {s!r}; valid: {', '.join(SECTIONS)}")
        for c in self.categories:
            if c not in CATEGORIES:
                raise ConfigError(f"unknown category {c!r}; valid: {', '.join(CATEGORIES)}")
        if not self.strategies:
            raise ConfigError("give at least one strategy")
        for s in self.strategies:
            AdapterConfig(strategy=s)
        if not (np.isfinite(self.noise) and self.noise >= 0):
            raise ConfigError(f"noise must be >= 0 px, got {self.noise!r}")
        AdapterConfig(model_blur=self.model_blur)


@dataclass
class Cell:
    """One (section, variant, category) batch of experiments."""

    section: str
    label: str  # strategy (and variant) as printed
    strategy: str
    category: str
    cfg: AdaptConfig
    model: object
    truths: np.ndarray  # (n, P)
    seeds: list  # SeedSequence per experiment
    errors: list = field(default_factory=list)
    angle_errors: list = field(default_factory=list)
    keyboard: Keyboard | None = None  # the world's keyboard (set by plan)
    step_ms: list = field(default_factory=list)


def _truths(cfg: BenchConfig, family: str, category: str) -> np.ndarray:
    ss = np.random.SeedSequence([cfg.seed, SECTIONS.index("exact") if family == "translation"
                                 else SECTIONS.index("rigid"), list(CATEGORIES).index(category)])
    return draw(category, family, cfg.experiments, rng=np.random.default_rng(ss))


def bench_keyboard(cfg: BenchConfig) -> Keyboard:
    """The default keyboard of ``cfg.layout`` (polygons: ``pipelines/layouts/polygons.toml``'s)."""
    return Keyboard(KeyboardConfig(layout=cfg.layout, **example_config_fields(cfg.layout)))


def plan(cfg: BenchConfig, learned_model=None, keyboard: Keyboard | None = None) -> list[Cell]:
    """All batches of the requested sections, in print order, on ``keyboard`` (default: the
    layout's default keyboard; it must be the keyboard the learned model was learned on)."""
    kb = bench_keyboard(cfg) if keyboard is None else keyboard
    exact = ExactModel(kb)
    seeds = np.random.SeedSequence(cfg.seed).spawn(cfg.experiments)
    base = AdaptConfig(max_steps=cfg.max_steps)
    cells: list[Cell] = []

    def add(section: str, label: str, acfg: AdaptConfig, model, family: str) -> None:
        for cat in cfg.categories:
            cells.append(Cell(section, label, acfg.strategy, cat, acfg, model,
                              _truths(cfg, family, cat), seeds))

    def with_(acfg: AdaptConfig, **robot) -> AdaptConfig:
        return acfg.with_robot(**robot)

    for section in cfg.sections:
        if section == "exact":
            for s in cfg.strategies:
                add(section, s, with_(base, strategy=s), exact, "translation")
        elif section == "noise":
            for s in cfg.strategies:
                aim = with_(base, strategy=s).replace(reach_noise=cfg.noise, feedback="aim")
                add(section, f"{s}/aim", aim, exact, "translation")
            add(section, "infogain/landed", with_(base, strategy="infogain").replace(
                reach_noise=cfg.noise), exact, "translation")
        elif section == "rigid":
            for s in cfg.strategies:
                add(section, s, with_(base, strategy=s, family="rigid"), exact, "rigid")
        elif section == "kde":
            for s in ("random", "infogain"):
                if s in cfg.strategies:
                    add(section, f"{s}/kde", with_(base, strategy=s, posterior="kde"), exact,
                        "translation")
                    add(section, f"{s}/likelihood", with_(base, strategy=s), exact,
                        "translation")
        elif section == "learned":
            if learned_model is None:
                raise ConfigError("section learned needs a learned model: pass --model model.h5")
            soft = with_(base, model_blur=cfg.model_blur)
            for s in cfg.strategies:
                add(section, s, with_(soft, strategy=s), learned_model, "translation")
            if "infogain" in cfg.strategies:
                add(section, "infogain/unsoftened", with_(base, model_blur=0.0), learned_model,
                    "translation")
        elif section == "learned-rigid":
            if learned_model is None:
                raise ConfigError("section learned-rigid needs a learned model: pass --model "
                                  "model.h5")
            soft = with_(base, model_blur=cfg.model_blur, family="rigid")
            for s in cfg.strategies:
                add(section, s, with_(soft, strategy=s), learned_model, "rigid")
    for cell in cells:
        cell.keyboard = kb
    return cells


def run_cells(cells: list[Cell]) -> Iterator[tuple[Cell, int]]:
    """Run every experiment of every cell, yielding ``(cell, i)`` after each (for progress bars).

    The model raster is built once per (model, raster settings) and shared.
    """
    tables: dict = {}
    samples: dict = {}
    for cell in cells:
        kb = cell.keyboard if cell.keyboard is not None else Keyboard(KeyboardConfig())
        acfg = cell.cfg.adapter_config()
        key = (id(cell.model), acfg.family, acfg.resolution, acfg.raster_step, acfg.blur,
               acfg.model_blur, acfg.outlier)
        if key not in tables:
            tables[key] = build_table(cell.model, acfg)
        skey = key + (acfg.kde_samples, acfg.kde_bandwidth)
        if POSTERIORS.get(acfg.posterior).uses_samples and skey not in samples:  # once per class
            samples[skey] = build_samples(cell.model, acfg, [0])
        for i, truth in enumerate(cell.truths):
            # a fresh copy: spawning from a shared SeedSequence would advance it for later cells
            ss = np.random.SeedSequence(cell.seeds[i].entropy, spawn_key=cell.seeds[i].spawn_key)
            res = experiment(cell.cfg, cell.model, kb, truth, rng=np.random.default_rng(ss),
                             table=tables[key], samples=samples.get(skey))
            cell.errors.append(res["errors"])
            cell.angle_errors.append(res["angle_errors"])
            cell.step_ms.append(res["step_ms"])
            yield cell, i


def counted_errors(cell: Cell) -> np.ndarray:
    """(n, T) the error the thresholds apply to (``max(px, 2 * deg)`` for the rigid family)."""
    e = np.asarray(cell.errors, float)
    if FAMILIES.get(cell.cfg.family).rotates:
        e = np.maximum(e, 2 * np.asarray(cell.angle_errors, float))
    return e


def summarize(cells: list[Cell]) -> list[dict]:
    """One row per cell: medians to thresholds, runs that never got there, RMSE at steps,
    paired signed-rank p-values against the same section's random (or random/kde, random/aim)
    cell, ms per step."""
    rows = []
    by_key = {(c.section, c.label, c.category): c for c in cells}
    for c in cells:
        T = c.cfg.max_steps
        e = counted_errors(c)
        counts = stats.samples_to_threshold(e, np.array(THRESHOLDS))
        med = stats.median_samples(counts, T)
        never = (counts > T).sum(axis=0)
        rm = stats.rmse_curve(np.asarray(c.errors, float))
        rmse = {s: float(rm[s - 1]) for s in RMSE_STEPS if s <= T}
        variant = c.label.split("/", 1)[1] if "/" in c.label else None
        ref_label = "random" if variant is None else f"random/{variant}"
        pvals = None
        ref = by_key.get((c.section, ref_label, c.category))
        if ref is not None and ref is not c:
            rc = stats.samples_to_threshold(counted_errors(ref), np.array(THRESHOLDS))
            _, p = stats.signed_rank_pvalues(counts, rc)
            pvals = [float(v) for v in p]
        rows.append({
            "section": c.section, "label": c.label, "category": c.category,
            "median": [float(v) for v in med], "never": [int(v) for v in never],
            "rmse": rmse, "p": pvals,
            "final_rmse": float(rm[-1]),
            "final_angle_rmse": float(np.sqrt(np.mean(np.square(np.asarray(c.angle_errors)[:, -1])))),
            "ms": float(np.median(np.concatenate(c.step_ms))),
            "n": len(c.errors), "T": T, "min_p": stats.min_pvalue_paired(len(c.errors)),
        })
    return rows


def kde_speed(model, *, steps: int = 200, seed: int = 0, resolution: float = 0.5,
              prior_halfwidth: float = 45.0, kde_samples: int = 10000) -> dict:
    """Milliseconds of one adaptation update with the KDE posterior and with the likelihood one.

    ``steps`` touches uniform over the model's working area, each classified by the model
    (``predict_proba``'s most probable class), update both posteriors; timed per step: the
    observation term and the product (``Adapter.observe_class``) plus the maximum-likelihood and
    mean estimates. The KDE's per-class samples are drawn before the timing starts (that is the
    point: once per class, not per touch) and their drawing is timed separately.

    Returns
    -------
    dict
        ``kde_ms``, ``likelihood_ms``: (steps,) ndarrays of wall time; ``kde_cpu_ms``,
        ``likelihood_cpu_ms``: the same in this process's CPU time (what a busy machine's other
        processes do not add to); ``sample_ms``: drawing one class's samples, median over the
        classes heard; ``classes``: how many; ``grid_cells``.
    """
    import time

    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = model.area
    acts = rng.uniform((x0, y0), (x1, y1), size=(steps, 2))
    cls = np.argmax(model.predict_proba(acts), axis=1)
    kcfg = AdapterConfig(strategy="random", posterior="kde", estimator="ml", resolution=resolution,
                         prior_halfwidth=prior_halfwidth, kde_samples=kde_samples)
    lcfg = AdapterConfig(strategy="random", resolution=resolution, prior_halfwidth=prior_halfwidth)
    samples = build_samples(model, kcfg, [seed])
    sample_ms = []
    for c in np.unique(cls):
        t0 = time.perf_counter()
        samples.get(int(c))
        sample_ms.append(1e3 * (time.perf_counter() - t0))
    table = build_table(model, lcfg)
    out = {}
    for name, acfg in (("kde", kcfg), ("likelihood", lcfg)):
        ad = Adapter(model, acfg, rng=np.random.default_rng(seed), table=table, samples=samples)
        ms = np.empty(steps)
        cpu = np.empty(steps)
        for i, (a, c) in enumerate(zip(acts, cls, strict=True)):
            t0, c0 = time.perf_counter(), time.process_time()
            ad.observe_class(a, int(c))
            ad.posterior.ml()
            ad.posterior.mean()
            ms[i] = 1e3 * (time.perf_counter() - t0)
            cpu[i] = 1e3 * (time.process_time() - c0)
        out[f"{name}_ms"] = ms
        out[f"{name}_cpu_ms"] = cpu
    out.update(sample_ms=float(np.median(sample_ms)), classes=len(sample_ms),
               grid_cells=kcfg.grid_cells)
    return out
