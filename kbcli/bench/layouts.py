"""Learning and adapting on every layout, as tables and figures (issue 11; ``make reproduce-layouts``).

For each layout of ``pipelines/layouts.toml`` (its keyboard from ``pipelines/layouts/<layout>.toml``):

1. the learning benchmark (:mod:`kbcli.bench.learn`): every model class and exploration strategy,
   ``seeds`` runs each up to the largest budget, the accuracy on a 1 px grid at each budget, the
   reaches to 97 % and 99 %, the boundary error and the fit time (runs are kept in ``OUT/cache``);
2. the adaptation model: ``kbcli learn`` (active exploration, seed ``seed``) with the class that has
   the best median accuracy at the adaptation budget (or the one named), ``OUT/models/<layout>.h5``;
3. the adaptation benchmark (:mod:`kbcli.bench.adapt`, sections ``learned`` and ``learned-rigid``)
   with that model: median touches to 4, 2, 1 and 0.5 px per strategy and displacement category;
4. the report, ``OUT/report/``: ``README.md`` (the tables, each target of the issue with the measured
   figure beside it, every resolved setting), ``<layout>.png`` (the layout, the adaptation model's
   map, the learning curves and the adaptation curves) and ``results.json`` (the rows).

Every number in the report is measured by this run; the targets are the issue's.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import AfterValidator, Field, model_validator

from kbcli import __version__
from kbcli.bench import adapt as adapt_bench
from kbcli.bench import learn as learn_bench
from kbcli.core.config import Config, Count, Name, Names, NonNegativeInt, Whole, each
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.layouts import LAYOUTS
from kbcli.core.model.classes import check_learned
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.atomic import atomic_path
from kbcli.io.config import load_toml
from kbcli.sim import SimConfig
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage

#: The issue's targets.
TARGET_800, TARGET_1600, TARGET_RATIO, TARGET_GRID_LINES = 0.97, 0.99, 0.5, 0.99
TARGET_TOUCHES, TARGET_PX = 8.0, 2.0


def _check_class(v: str) -> str:
    if v != "best":
        check_learned(v)
    return v


class LayoutsConfig(Config):
    """The ``[layouts]`` table of ``pipelines/layouts.toml`` (see that file)."""

    what: ClassVar[str] = "layouts"

    layouts: Annotated[Names, AfterValidator(each(LAYOUTS.get))] = (
        "grid", "hex", "piano", "pads", "polygons")
    keyboards: Name = "pipelines/layouts"
    seed: NonNegativeInt = 0
    model_classes: Names = ("lines", "svc")
    strategies: Names = ("active", "random")
    seeds: Count = 5
    budgets: Annotated[tuple[Count, ...], Field(min_length=1)] = (200, 400, 800, 1600)
    boundary_budget: Count = 800
    mode: Name = "ideal"
    adapt_budget: Count = 800
    adapt_class: Annotated[Name, AfterValidator(_check_class)] = "best"
    experiments: Whole = 20
    adapt_strategies: Names = ("random", "active", "infogain")
    rigid_experiments: NonNegativeInt = 10
    rigid_strategies: Names = ("random", "infogain")
    max_steps: Count = 40
    #: the TOML file it was read from (named in the report)
    source: Name = "pipelines/layouts.toml"

    @model_validator(mode="after")
    def _parts(self) -> LayoutsConfig:
        """The learning and adaptation benchmarks' configs are valid."""
        self.learn_config()
        self.adapt_config("learned")
        if self.rigid_experiments:
            self.adapt_config("learned-rigid")
        return self

    def learn_config(self) -> learn_bench.BenchConfig:
        return learn_bench.BenchConfig(
            seeds=self.seeds, budgets=tuple(self.budgets), strategies=tuple(self.strategies),
            layouts=tuple(self.layouts), model_classes=tuple(self.model_classes), mode=self.mode,
            seed=self.seed, boundary_budget=self.boundary_budget)

    def adapt_config(self, section: str, layout: str = "grid") -> adapt_bench.BenchConfig:
        rigid = section == "learned-rigid"
        return adapt_bench.BenchConfig(
            experiments=self.rigid_experiments if rigid else self.experiments,
            max_steps=self.max_steps, seed=self.seed, sections=(section,),
            strategies=tuple(self.rigid_strategies if rigid else self.adapt_strategies),
            layout=layout)

    @classmethod
    def from_toml(cls, path: str | os.PathLike) -> LayoutsConfig:
        """Read ``[layouts]``, ``[layouts.learn]`` and ``[layouts.adapt]``; unknown keys refused."""
        doc = load_toml(path, "layouts")
        d = dict(doc)
        learn = d.pop("learn", {})
        adapt = d.pop("adapt", {})
        top = {"layouts", "keyboards", "seed"}
        bad = sorted(set(d) - top)
        if bad:
            raise ConfigError(f"unknown [layouts] option(s) {', '.join(bad)}; valid: "
                              f"{', '.join(sorted(top | {'learn', 'adapt'}))}")
        lkeys = {"model_classes", "strategies", "seeds", "budgets", "boundary_budget", "mode"}
        bad = sorted(set(learn) - lkeys)
        if bad:
            raise ConfigError(f"unknown [layouts.learn] option(s) {', '.join(bad)}; valid: "
                              f"{', '.join(sorted(lkeys))}")
        amap = {"budget": "adapt_budget", "model_class": "adapt_class",
                "experiments": "experiments", "strategies": "adapt_strategies",
                "rigid_experiments": "rigid_experiments", "rigid_strategies": "rigid_strategies",
                "max_steps": "max_steps"}
        bad = sorted(set(adapt) - set(amap))
        if bad:
            raise ConfigError(f"unknown [layouts.adapt] option(s) {', '.join(bad)}; valid: "
                              f"{', '.join(sorted(amap))}")
        kw: dict[str, Any] = dict(d)
        kw.update(learn)
        kw.update({amap[k]: v for k, v in adapt.items()})
        return cls(**kw, source=str(path))


@dataclass
class LayoutResult:
    """What the pipeline found for one layout."""

    layout: str
    keyboard: Keyboard
    learn_runs: list = field(default_factory=list)
    learn_rows: list = field(default_factory=list)
    model_class: str | None = None
    model_path: str | None = None
    model_attrs: dict = field(default_factory=dict)
    cells: list = field(default_factory=list)
    adapt_rows: list = field(default_factory=list)


class Pipeline:
    """The layouts pipeline, stage by stage; each long stage is an iterator (for progress bars).

    Parameters
    ----------
    cfg : LayoutsConfig
    out : path
        Output folder (``keyboards/``, ``models/``, ``cache/``, ``report/`` are made in it).
    """

    def __init__(self, cfg: LayoutsConfig, out: str | os.PathLike) -> None:
        self.cfg = cfg
        self.out = Path(out)
        self.results: dict[str, LayoutResult] = {}

    # -- 1. keyboards ---------------------------------------------------------------------------
    def keyboards(self) -> None:
        """Write every layout's keyboard artifact (from ``keyboards/<layout>.toml``)."""
        (self.out / "keyboards").mkdir(parents=True, exist_ok=True)
        for name in self.cfg.layouts:
            toml = Path(self.cfg.keyboards) / f"{name}.toml"
            kcfg = KeyboardConfig.from_dict(load_toml(toml, "keyboard"))
            if kcfg.layout.name != name:
                raise ConfigError(f"{toml}: a {kcfg.layout.name} keyboard, expected {name}")
            path = self.out / "keyboards" / f"{name}.h5"
            write_artifact(keyboard_stage.run(kcfg), path)
            self.results[name] = LayoutResult(name, Keyboard(kcfg))

    # -- 2. learning benchmark ------------------------------------------------------------------
    @property
    def n_learn_runs(self) -> int:
        c = self.cfg
        return len(c.layouts) * len(c.model_classes) * len(c.strategies) * c.seeds

    def learn(self) -> Iterator[learn_bench.RunResult]:
        bc = self.cfg.learn_config()
        cache = self.out / "cache"
        cache.mkdir(parents=True, exist_ok=True)
        for name, res in self.results.items():
            one = bc.replace(layouts=(name,))
            for r in learn_bench.runs(one, res.keyboard, cache):
                res.learn_runs.append(r)
                yield r
            res.learn_rows = learn_bench.summarize(one, res.learn_runs)

    # -- 3. adaptation models -------------------------------------------------------------------
    def best_class(self, res: LayoutResult) -> str:
        if self.cfg.adapt_class != "best":
            return self.cfg.adapt_class
        budget = self.cfg.adapt_budget
        rows = [r for r in res.learn_rows if r["strategy"] == learn_bench.COMPARED] or res.learn_rows
        acc = {r["model_class"]: float(np.median([
            learn_bench.nearest_checkpoint(run, budget) for run in res.learn_runs
            if (run.model_class, run.strategy) == (r["model_class"], r["strategy"])]))
            for r in rows}
        return max(acc, key=lambda k: (acc[k], -list(acc).index(k)))

    def models(self) -> Iterator[str]:
        (self.out / "models").mkdir(parents=True, exist_ok=True)
        for name, res in self.results.items():
            res.model_class = self.best_class(res)
            lc = learn_stage.LearnConfig(strategy="active", budget=self.cfg.adapt_budget,
                                         model_class=res.model_class,
                                         sim=SimConfig(mode=self.cfg.mode))
            path = self.out / "models" / f"{name}.h5"
            kb_art = read_artifact(self.out / "keyboards" / f"{name}.h5", "keyboard")
            if path.is_file():
                old = read_artifact(path, "model")
                if old.config == learn_stage.model_config(lc, kb_art.config) and \
                        old.seed == self.cfg.seed:
                    res.model_path, res.model_attrs = str(path), dict(old.attrs)
                    yield name
                    continue
            art = learn_stage.run(lc, kb_art, rng=np.random.default_rng(self.cfg.seed),
                                  seed=self.cfg.seed)
            write_artifact(art, path)
            res.model_path, res.model_attrs = str(path), dict(art.attrs)
            yield name

    # -- 4. adaptation benchmark ----------------------------------------------------------------
    def plan_adapt(self) -> int:
        """Plan every adaptation batch; returns the number of experiments."""
        from kbcli.stages.models import load_model

        total = 0
        for name, res in self.results.items():
            art = read_artifact(res.model_path, "model")
            model = load_model(art)
            sections = ["learned"] + (["learned-rigid"] if self.cfg.rigid_experiments else [])
            res.cells = []
            for sec in sections:
                cells = adapt_bench.plan(self.cfg.adapt_config(sec, name), model, res.keyboard)
                res.cells += [c for c in cells if c.label != "infogain/unsoftened"]
            total += sum(len(c.truths) for c in res.cells)
        return total

    def _adapt_cache(self, name: str, res: LayoutResult) -> Path:
        """Where one layout's adaptation results are kept: named by the model file's hash and
        every setting of the runs."""
        sha = read_artifact(res.model_path, "model").sha256
        key = json.dumps({"model": sha, "version": __version__, "cells": [
            (c.section, c.label, c.category, c.cfg.to_dict(), np.asarray(c.truths).tolist())
            for c in res.cells]}, sort_keys=True, default=str)
        digest = hashlib.sha256(key.encode()).hexdigest()[:16]
        return self.out / "cache" / f"adapt-{name}-{digest}.json"

    def adapt(self) -> Iterator[tuple[str, int]]:
        """Run every layout's adaptation batches (read back from ``cache/`` when done before)."""
        for name, res in self.results.items():
            path = self._adapt_cache(name, res)
            if path.is_file():
                stored = json.loads(path.read_text())
                for cell, rec in zip(res.cells, stored, strict=True):
                    cell.errors = [np.asarray(e) for e in rec["errors"]]
                    cell.angle_errors = [np.asarray(e) for e in rec["angle_errors"]]
                    cell.step_ms = [np.asarray(e) for e in rec["step_ms"]]
                    for i in range(len(cell.truths)):
                        yield name, i
            else:
                for _cell, i in adapt_bench.run_cells(res.cells):
                    yield name, i
                recs = [{k: [np.asarray(e).tolist() for e in getattr(c, k)]
                         for k in ("errors", "angle_errors", "step_ms")} for c in res.cells]
                with atomic_path(path, suffix=".json") as tmp:
                    Path(tmp).write_text(json.dumps(recs))
            res.adapt_rows = adapt_bench.summarize(res.cells)

    # -- 5. the report --------------------------------------------------------------------------
    def report(self) -> Path:
        """Write ``report/README.md``, ``report/<layout>.png`` and ``report/results.json``."""
        from kbcli.viz.layouts import plot_layout

        folder = self.out / "report"
        folder.mkdir(parents=True, exist_ok=True)
        for name, res in self.results.items():
            plot_layout(res, read_artifact(res.model_path, "model"), self.cfg,
                        folder / f"{name}.png")
        text = render(self.cfg, self.results)
        with atomic_path(folder / "README.md", suffix=".md") as tmp:
            Path(tmp).write_text(text, encoding="utf-8")
        data = {"config": self.cfg.to_dict(), "kbcli_version": __version__,
                "layouts": {name: {"learn": res.learn_rows, "adapt_model": {
                    "class": res.model_class, "file": res.model_path, **res.model_attrs},
                    "adapt": res.adapt_rows, "targets": targets(self.cfg, res)}
                    for name, res in self.results.items()}}
        with atomic_path(folder / "results.json", suffix=".json") as tmp:
            Path(tmp).write_text(json.dumps(_plain(data), indent=1), encoding="utf-8")
        return folder


def _plain(o: Any) -> Any:
    if isinstance(o, dict):
        return {str(k): _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_plain(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return None if not math.isfinite(float(o)) else float(o)
    if isinstance(o, np.integer):
        return int(o)
    return o


def _pooled_median(rows: list[dict], cells: list, label: str, section: str,
                   threshold: float, ) -> tuple[float, int]:
    """Median touches to ``threshold`` px over every category's runs of one strategy (runs that
    never get there count as T + 1), and how many never did."""
    from kbcli.core.adaptation import stats

    counts = []
    T = 0
    for c in cells:
        if c.section == section and c.label == label:
            e = adapt_bench.counted_errors(c)
            T = c.cfg.max_steps
            counts.append(stats.samples_to_threshold(e, np.array([threshold]))[:, 0])
    if not counts:
        return float("nan"), 0
    allc = np.concatenate(counts).astype(float)
    allc[allc > T] = np.inf  # never got there: counts as more than any number of touches
    return float(np.median(allc)), int(np.isinf(allc).sum())


#: The layout and model class of the target "lines: accuracy >= 99 % at 800 reaches".
LINES_TARGET = ("grid", "lines")


def targets(cfg: LayoutsConfig, res: LayoutResult) -> list[dict]:
    """Each of the issue's targets for one layout: what was asked, what was measured, met or not."""
    out = []
    active = [r for r in res.learn_rows if r["strategy"] == learn_bench.COMPARED]
    if active:
        b800 = 800 if 800 in cfg.budgets else None
        b1600 = 1600 if 1600 in cfg.budgets else None
        if b800:
            best = max(active, key=lambda r: r["accuracy"][b800])
            v = best["accuracy"][b800]
            out.append({"target": "best class, active: accuracy >= 97 % at 800 reaches",
                        "measured": f"{100 * v:.2f} % ({best['model_class']})",
                        "met": v >= TARGET_800})
        if b1600:
            best = max(active, key=lambda r: r["accuracy"][b1600])
            v = best["accuracy"][b1600]
            out.append({"target": "best class, active: accuracy >= 99 % at 1600 reaches",
                        "measured": f"{100 * v:.2f} % ({best['model_class']})",
                        "met": v >= TARGET_1600})
        if b800:
            best = max(active, key=lambda r: r["accuracy"][b800])
            for q in learn_bench.ratios(res.learn_rows, 0.97):
                if q["model_class"] != best["model_class"]:
                    continue
                a, r = q["active"], q["random"]
                met = bool(np.isfinite(a) and (not np.isfinite(r) or a <= TARGET_RATIO * r))
                shown = (f"active {a:g} vs random {r:g} reaches to 97 %" if np.isfinite(r) else
                         f"active {a:g}, random > {cfg.learn_config().max_budget} (never)")
                out.append({"target": f"active needs at most half of random's reaches to 97 % "
                                      f"({q['model_class']})", "measured": shown, "met": met})
        layout, model_class = LINES_TARGET
        if res.layout == layout and b800:
            lines = [r for r in active if r["model_class"] == model_class]
            if lines:
                v = lines[0]["accuracy"][b800]
                out.append({"target": "lines: accuracy >= 99 % at 800 reaches",
                            "measured": f"{100 * v:.2f} %", "met": v >= TARGET_GRID_LINES})
    if res.cells:
        med, never = _pooled_median(res.adapt_rows, res.cells, "infogain", "learned", TARGET_PX)
        if not math.isnan(med):
            out.append({"target": f"infogain, learned {cfg.adapt_budget}-reach model: median "
                                  f"touches to < {TARGET_PX:g} px <= {TARGET_TOUCHES:g}",
                        "measured": (f"{med:g}" if math.isfinite(med) else
                                     f"> {cfg.max_steps}") + f" (all categories; {never} runs "
                                    "never within T)",
                        "met": med <= TARGET_TOUCHES})
    return out


def _md_table(head: list[str], body: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return "\n".join(lines)


def _fmt_med(m: float, never: int) -> str:
    txt = "-" if not math.isfinite(m) else f"{m:g}"
    return txt + (f" ({never})" if never else "")


def render(cfg: LayoutsConfig, results: dict[str, LayoutResult]) -> str:
    """The report's Markdown."""
    lc = cfg.learn_config()
    md = [f"# Learning and adapting on every layout (kbcli {__version__})", "",
          f"Made by `kbcli bench layouts --config {cfg.source}`"
          + (" (`make reproduce-layouts`)" if cfg.source == "pipelines/layouts.toml" else "")
          + " with the settings at the end. Every number below is measured by that run; the "
          "targets are issue 11's.", ""]
    md += ["## Targets", ""]
    rows = []
    for name, res in results.items():
        for t in targets(cfg, res):
            rows.append([name, t["target"], t["measured"], "met" if t["met"] else "**missed**"])
    md += [_md_table(["layout", "target", "measured", "status"], rows), ""]
    md += ["## Learning the model", "",
           f"{cfg.seeds} runs per row ({cfg.mode} mode); median accuracy (%) on a 1 px grid over "
           "the working area at each budget; reaches to 97 % / 99 %: the median first curve point "
           f"(every {lc.resolution} reaches) at or above it (runs that never get there count as "
           f"more than {lc.max_budget}); boundary error (px) at {cfg.boundary_budget} reaches; "
           f"the time of one fit on {lc.max_budget} samples (shared machine).", ""]
    body = []
    for res in results.values():
        head, b = learn_bench.table(lc, res.learn_rows)
        body += b
    md += [_md_table(head, body), ""]
    for res in results.values():
        md += [f"- {line}" for line in learn_bench.ratio_lines(lc, res.learn_rows)]
    md += ["", "## Adapting with a learned model", "",
           f"Each layout's model: `kbcli learn` with active exploration, {cfg.adapt_budget} reaches, "
           f"seed {cfg.seed}, the class with the best median accuracy at {cfg.adapt_budget} reaches "
           "in the table above (or the one configured). Median touches until the error first "
           "drops below each threshold ((k): runs that never got there within "
           f"T = {cfg.max_steps}); translation: {cfg.experiments} runs per strategy and category; "
           f"rigid (angles up to 5 deg; a threshold of t px also needs the angle within t/2 deg): "
           f"{cfg.rigid_experiments} runs. RMSE (px) at the last step.", ""]
    body = []
    for name, res in results.items():
        a = res.model_attrs
        model = (f"{res.model_class}, {100 * a.get('accuracy', float('nan')):.2f} %, "
                 f"{a.get('boundary_error_px', float('nan')):.2f} px")
        for r in res.adapt_rows:
            fam = "rigid" if r["section"] == "learned-rigid" else "translation"
            body.append([name, model, fam, r["label"], r["category"],
                         *[_fmt_med(m, n) for m, n in zip(r["median"], r["never"], strict=True)],
                         f"{r['final_rmse']:.2f}"])
    head = ["layout", "model (class, accuracy, boundary error)", "family", "strategy", "category",
            *[f"< {t:g} px" for t in adapt_bench.THRESHOLDS], "final rmse"]
    md += [_md_table(head, body), ""]
    md += ["## Figures", ""]
    for name in results:
        md += [f"- [{name}]({name}.png): the layout; the {cfg.adapt_budget}-reach model's map "
               "(wrong cells red, reaches black); learning curves (median accuracy of every class "
               "and strategy); adaptation (median error per step of every strategy)."]
    md += ["", "## Settings", "", "```json", json.dumps(cfg.to_dict(), indent=1), "```", ""]
    return "\n".join(md)


__all__ = ["LayoutsConfig", "Pipeline", "render", "targets"]
