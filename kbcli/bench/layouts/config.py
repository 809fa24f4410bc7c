"""The layouts pipeline's config (:class:`LayoutsConfig`, ``pipelines/layouts.toml``) and what it
finds for one layout (:class:`LayoutResult`)."""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar

from pydantic import AfterValidator, Field, model_validator

from kbcli.bench import adapt as adapt_bench
from kbcli.bench import learn as learn_bench
from kbcli.core.config import Config, Count, Name, Names, NonNegativeInt, Whole, each
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.instrument.layouts import LAYOUTS
from kbcli.core.model.classes import check_learned
from kbcli.errors import ConfigError
from kbcli.io.config import load_toml


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
        _known("layouts", d, {"layouts", "keyboards", "seed"}, shown=("learn", "adapt"))
        _known("layouts.learn", learn, {"model_classes", "strategies", "seeds", "budgets",
                                        "boundary_budget", "mode"})
        amap = {"budget": "adapt_budget", "model_class": "adapt_class",
                "experiments": "experiments", "strategies": "adapt_strategies",
                "rigid_experiments": "rigid_experiments", "rigid_strategies": "rigid_strategies",
                "max_steps": "max_steps"}
        _known("layouts.adapt", adapt, set(amap))
        kw: dict[str, Any] = dict(d)
        kw.update(learn)
        kw.update({amap[k]: v for k, v in adapt.items()})
        return cls(**kw, source=str(path))


def _known(table: str, given: Iterable[str], valid: set[str], shown: tuple[str, ...] = ()) -> None:
    """ConfigError naming the options of ``given`` that ``[table]`` does not take, and the valid
    ones (``valid`` and its sub-tables, ``shown``)."""
    bad = sorted(set(given) - valid)
    if bad:
        raise ConfigError(f"unknown [{table}] option(s) {', '.join(bad)}; valid: "
                          f"{', '.join(sorted(valid | set(shown)))}")


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
