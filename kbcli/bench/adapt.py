"""Benchmark of the adaptation (paper Sect. IV-A, IV-B): sample efficiency and speed.

On a layout's default keyboard (``--layout``; the 4 x 8 grid of 50 px keys unless told otherwise)
or a learned model's own, ``ideal`` mode, ``experiments`` runs per displacement category and
strategy, each run ``max_steps`` observations. True displacements come from
:func:`kbcli.stages.perturb.draw` (its size categories); run ``i`` of a category uses the same
displacement and seed for every strategy (a paired design). Per strategy and category it reports
the median observations until the error is below 4, 2, 1, 0.5 px (runs that never get there
within T count as T + 1), the RMSE at steps 1, 2, 3, 5, 10, 20, 40, the Wilcoxon signed-rank
p-value of those counts against ``random`` (:func:`kbcli.core.adaptation.stats.signed_rank_pvalues`)
and the median milliseconds per step. For the rigid family a threshold of ``t`` px also asks the
angle to be within ``t / 2`` degrees. The sections (``--section``) are :data:`SECTIONS`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Annotated, ClassVar

import numpy as np
from pydantic import AfterValidator, Field, Strict

from kbcli.core.adaptation import stats
from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.setup import build_samples, build_table
from kbcli.core.config import Config, Count, Name, NonNegative, NonNegativeInt, each, member_of
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.layouts import LAYOUTS, example_config_fields
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.core.model.base import ExactModel
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError
from kbcli.stages.adapt import AdaptConfig, experiment
from kbcli.stages.perturb import CATEGORIES, draw

STRATEGY_ORDER = ("random", "active", "infogain")
THRESHOLDS = (4.0, 2.0, 1.0, 0.5)
RMSE_STEPS = (1, 2, 3, 5, 10, 20, 40)
#: The true displacements' random stream per family.
_TRUTH_STREAM = {"translation": 0, "rigid": 2}


@dataclass(frozen=True)
class Section:
    """One section of the benchmark: its rows (label, adaptation config, model) and its table.

    ``variants(cfg, base, exact, learned) -> [(label, AdaptConfig, model), ...]`` gives the rows in
    print order; ``family`` is the true displacements'; ``title`` may use ``{noise}`` and
    ``{model}``; ``learned``: needs ``--model`` (the table shows its boundary error); ``angle``: the
    table shows the final angle RMSE; ``timed``: first time one step of the section's posterior.
    """

    variants: Callable[..., list[tuple[str, AdaptConfig, object]]]
    family: str = "translation"
    title: str = ""
    learned: bool = False
    angle: bool = False
    default: bool = True
    timed: bool = False


#: The benchmark's sections (``--section``), in print order.
SECTIONS: Registry[Section] = Registry("section")


def _with_loop(acfg: AdaptConfig, **changes) -> AdaptConfig:
    """A copy with loop options (reach noise, feedback) changed."""
    return AdaptConfig.from_dict({**acfg.to_dict(), **changes})


def _exact(cfg, base, exact, learned):
    return [(s, base.with_robot(strategy=s), exact) for s in cfg.strategies]


def _noise(cfg, base, exact, learned):
    rows = [(f"{s}/aim", _with_loop(base.with_robot(strategy=s), reach_noise=cfg.noise,
                                    feedback="aim"), exact) for s in cfg.strategies]
    landed = _with_loop(base.with_robot(strategy="infogain"), reach_noise=cfg.noise)
    return [*rows, ("infogain/landed", landed, exact)]


def _rigid(cfg, base, exact, learned):
    return [(s, base.with_robot(strategy=s, family="rigid"), exact) for s in cfg.strategies]


def _kde(cfg, base, exact, learned):
    rows = []
    for s in KDE_PAIRED:
        if s in cfg.strategies:
            rows.append((f"{s}/kde", base.with_robot(strategy=s, posterior="kde"), exact))
            rows.append((f"{s}/likelihood", base.with_robot(strategy=s), exact))
    return rows


#: The strategies the ``kde`` section runs with both posteriors, and the one the ``learned``
#: section also runs on the unsoftened map (the sections' own definitions).
KDE_PAIRED, UNSOFTENED = ("random", "infogain"), "infogain"


def _learned(cfg, base, exact, learned):
    soft = base.with_robot(model_blur=cfg.model_blur)
    rows = [(s, soft.with_robot(strategy=s), learned) for s in cfg.strategies]
    if UNSOFTENED in cfg.strategies:
        rows.append(("infogain/unsoftened", base.with_robot(model_blur=0.0), learned))
    return rows


def _learned_rigid(cfg, base, exact, learned):
    soft = base.with_robot(model_blur=cfg.model_blur, family="rigid")
    return [(s, soft.with_robot(strategy=s), learned) for s in cfg.strategies]


_RIGID_NOTE = ("rigid family (angles up to 5 deg); a threshold of t px also needs the angle "
               "within t/2 deg")
SECTIONS.register("exact", Section(_exact, title="exact model, translation, no reach noise"),
                  summary="the exact model, translation, no reach noise")
SECTIONS.register("noise", Section(
    _noise, title="exact model, translation, {noise} px reach noise (aim: the robot knows only "
    "where it aimed; landed: where it landed)"), summary="2 px reach noise, aim-only feedback")
SECTIONS.register("rigid", Section(_rigid, family="rigid", angle=True,
                                   title="exact model, " + _RIGID_NOTE),
                  summary="the rigid family (angles up to 5 degrees)")
SECTIONS.register("kde", Section(
    _kde, timed=True, title="the paper's KDE posterior (Eq. 7) against the likelihood posterior"),
    summary="the paper's KDE posterior against the likelihood one")
SECTIONS.register("learned", Section(_learned, learned=True, title="learned model{model}"),
                  summary="a learned model (--model)")
SECTIONS.register("learned-rigid", Section(_learned_rigid, family="rigid", learned=True,
                                           angle=True, default=False,
                                           title="learned model{model}, " + _RIGID_NOTE),
                  summary="the learned model with the rigid family")


def default_sections(learned: bool) -> tuple[str, ...]:
    """The sections run when none is named: every default one; the learned ones need a model."""
    return tuple(n for n, sec in SECTIONS.items() if sec.default and (learned or not sec.learned))


def section_title(name: str, cfg: BenchConfig, model: str | None = None) -> str:
    """The title of a section's table (``model``: the learned model's path, if any)."""
    desc = (f" ({model})" if model else "")
    if name == "learned" and cfg.model_blur is not None:
        desc += f", map softened by {cfg.model_blur:g} px"
    return SECTIONS.get(name).title.format(noise=f"{cfg.noise:g}", model=desc)


def _check_strategy(v: str) -> str:
    AdapterConfig(strategy=v)
    return v


def _check_blur(v: float | None) -> float | None:
    AdapterConfig(model_blur=v)
    return v


class BenchConfig(Config):
    """Benchmark settings (see the module docstring)."""

    what: ClassVar[str] = "bench adapt"

    experiments: Annotated[int, Strict(), Field(ge=2)] = 50
    max_steps: Count = 40
    seed: NonNegativeInt = 0
    sections: Annotated[tuple[Name, ...], AfterValidator(each(SECTIONS.get))] = (
        "exact", "noise", "rigid", "kde")
    strategies: Annotated[tuple[Annotated[Name, AfterValidator(_check_strategy)], ...],
                          Field(min_length=1)] = STRATEGY_ORDER
    categories: Annotated[tuple[Name, ...], AfterValidator(
        each(member_of("category", CATEGORIES)))] = tuple(CATEGORIES)
    noise: NonNegative = 2.0
    model_blur: Annotated[float | None, AfterValidator(_check_blur)] = None
    layout: Annotated[Name, AfterValidator(LAYOUTS.check)] = "grid"


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
    ss = np.random.SeedSequence([cfg.seed, _TRUTH_STREAM[family], list(CATEGORIES).index(category)])
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
    for name in cfg.sections:
        section = SECTIONS.get(name)
        if section.learned and learned_model is None:
            raise ConfigError(f"section {name} needs a learned model: pass --model model.h5")
        for label, acfg, model in section.variants(cfg, base, exact, learned_model):
            cells.extend(Cell(name, label, acfg.robot.strategy.name, cat, acfg, model,
                              _truths(cfg, section.family, cat), seeds, keyboard=kb)
                         for cat in cfg.categories)
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
        shared = acfg.kind.sample_key(acfg)
        skey = None if shared is None else key + shared
        if skey is not None and skey not in samples:  # once per class
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

    ``steps`` touches uniform over the model's area, each classified by the model, update both
    posteriors; timed per step: ``Adapter.observe_class`` plus the ML and mean estimates. The
    KDE's per-class samples are drawn (and timed) before, once per class.

    Returns ``kde_ms``, ``likelihood_ms`` ((steps,) wall time), ``kde_cpu_ms``,
    ``likelihood_cpu_ms`` (this process's CPU time), ``sample_ms`` (drawing one class's samples,
    median over the ``classes`` heard) and ``grid_cells``.
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
