"""The layouts pipeline, stage by stage (:class:`Pipeline`): keyboards, the learning benchmark,
the adaptation models, the adaptation benchmark and the report."""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from kbcli import __version__
from kbcli.bench import adapt as adapt_bench
from kbcli.bench import learn as learn_bench
from kbcli.bench.layouts.config import LayoutResult, LayoutsConfig
from kbcli.bench.layouts.report import render, targets
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.atomic import atomic_path
from kbcli.io.config import load_toml
from kbcli.sim import SimConfig
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage


class Pipeline:
    """The layouts pipeline, stage by stage; each long stage is an iterator (for progress bars).
    ``keyboards/``, ``models/``, ``cache/`` and ``report/`` are made in the folder ``out``."""

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
