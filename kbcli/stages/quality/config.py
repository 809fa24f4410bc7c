"""The ``[quality]`` table: the sweep's models, rows, displacements and repetitions."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Annotated, Any

from pydantic import AfterValidator, Field, ValidationInfo, field_validator, model_validator

from kbcli.core.adaptation.config import SLOTS, option_names, refuse_inactive
from kbcli.core.config import (
    Config,
    Flag,
    Name,
    Names,
    NonNegativeInt,
    Whole,
    between,
    refused_option,
)
from kbcli.core.model.classes import EXACT  # the reference row's model: the exact class
from kbcli.core.options import for_part, owners
from kbcli.errors import ConfigError
from kbcli.sim.arms import arm_config
from kbcli.sim.config import ModeName, ReachNoise
from kbcli.stages.config import MAX_ADAPT_STEPS, MAX_BUDGET, MAX_EXPERIMENTS, check_total
from kbcli.stages.evaluate import Category, _paper_categories

#: Rows of the default sweep: name -> adapt options (strategy included).
DEFAULT_ROWS = {
    "random": {"strategy": "random"},
    "active": {"strategy": "active"},
    "infogain": {"strategy": "infogain"},
    "infogain-plain": {"strategy": "infogain", "robust": False},
}
#: The reference row adapted with the exact model (the keyboard's own map) when ``ideal`` is on.
IDEAL_ROW = "exact-infogain"
#: Options the sweep sets itself for every experiment (not allowed in a row or ``adapt``).
FIXED = ("mode", "arm", "reach_noise", "max_steps", "family", "stop")
#: Fewest reaches of a learned model.
MIN_BUDGET = 10
#: Most budgets of a sweep (models: budgets x explorations, each learned before any adaptation).
MAX_BUDGETS = 100

Budget = between(Whole, MIN_BUDGET, MAX_BUDGET)


def baseline_of(d: Mapping[str, Any], row: str) -> str:
    """The row ``row`` is compared with, in a sweep's config or attributes (``baselines`` when
    it names the row, else ``baseline``)."""
    return (d.get("baselines") or {}).get(row, d["baseline"])


def compared_rows(d: Mapping[str, Any]) -> list[str]:
    """The rows of a sweep's config or attributes that are compared with a baseline: every row
    that is no row's baseline."""
    bases = {d["baseline"], *(d.get("baselines") or {}).values()}
    return [r for r in d["rows"] if r not in bases]


class QualityConfig(Config):
    """The model-quality sweep (the ``[quality]`` table of ``pipelines/model-quality.toml``).

    ``budgets``: reaches of each learned model (stored sorted, without repeats); ``arm`` is
    stored as the resolved table; ``reach_noise``: extra landing scatter, px. ``rows``: name ->
    adapt options, each compared with ``baseline`` or its entry in ``baselines`` (row -> its
    baseline row); a row that is a baseline is not compared itself. ``experiments`` per
    displacement, model and row; ``adapt``: options shared by every row. ``ideal``: also adapt
    with the exact model, with infogain, on the same displacements and seeds (a reference for
    what a better model could buy, not a strict bound: infogain is greedy).
    """

    what = "quality"

    # validated in this order: the baseline is checked against the rows above it
    seed: NonNegativeInt = 2024
    budgets: tuple[Budget, ...] = (100, 150, 200, 300, 400, 800, 1600)
    explorations: Names = ("active", "random")
    mode: ModeName = "dynamics"
    arm: Annotated[Any, AfterValidator(lambda v: arm_config(v).to_dict())] = "realistic"
    reach_noise: ReachNoise = 0.0
    experiments: between(Whole, 1, MAX_EXPERIMENTS) = 8
    max_steps: between(Whole, 1, MAX_ADAPT_STEPS) = 30
    categories: Any = Field(default_factory=_paper_categories)
    adapt: Any = Field(default_factory=dict)
    ideal: Flag = True
    rows: Any = Field(default_factory=lambda: dict(DEFAULT_ROWS))
    baseline: Name = "random"
    baselines: Any = Field(default_factory=dict)

    @field_validator("budgets")
    @classmethod
    def _sorted_budgets(cls, v: tuple[int, ...]) -> tuple[int, ...]:
        if not v:
            raise ValueError("must list at least one budget")
        if len(set(v)) > MAX_BUDGETS:
            raise ValueError(f"must list at most {MAX_BUDGETS} budgets, got {len(set(v))}")
        if twice := sorted({b for b in v if v.count(b) > 1}):  # one model each: say so, not merge
            raise ValueError(f"must list each budget once, got {twice[0]} more than once")
        return tuple(sorted(v))

    @field_validator("explorations")
    @classmethod
    def _known_explorations(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        from kbcli.stages.learn import strategies as learn_strategies

        for e in v:
            if e not in learn_strategies() or e == EXACT:
                raise ValueError(f"unknown exploration {e!r}; valid: active, random")
        return v

    @field_validator("categories", mode="before")
    @classmethod
    def _categories(cls, v: Any) -> tuple[Category, ...]:
        return _categories(v)

    @field_validator("adapt")
    @classmethod
    def _shared_options(cls, v: Any) -> MappingProxyType:
        if not isinstance(v, Mapping):
            raise ValueError("must be a table of adapt options")
        fixed = sorted(set(v) & set(FIXED + ("strategy",)))
        if fixed:
            raise ValueError(f"{fixed[0]} is set by the sweep or its rows")
        return MappingProxyType(dict(v))

    @field_validator("rows")
    @classmethod
    def _rows(cls, v: Any) -> MappingProxyType:
        return MappingProxyType(_rows(v))

    @field_validator("baseline")
    @classmethod
    def _baseline_is_a_row(cls, v: str, info: ValidationInfo) -> str:
        rows = info.data.get("rows")
        if rows is not None and v not in rows:
            raise ValueError(f"{v!r} must name a row ({', '.join(rows)})")
        return v

    @field_validator("baselines")
    @classmethod
    def _baselines_are_rows(cls, v: Any, info: ValidationInfo) -> MappingProxyType:
        if not isinstance(v, Mapping):
            raise ValueError("must be a table of row = baseline row")
        rows = info.data.get("rows") or {}
        for row, base in v.items():
            for what, name in (("row", row), ("baseline", base)):
                if name not in rows:
                    raise ValueError(f"{what} {name!r} of {row} = {base!r} must name a row "
                                     f"({', '.join(rows)})")
            if row == base:
                raise ValueError(f"row {row!r} cannot be its own baseline")
        return MappingProxyType(dict(v))

    def baseline_of(self, row: str) -> str:
        """The row ``row`` is compared with."""
        return baseline_of(self.to_dict(), row)

    @model_validator(mode="after")
    def _rows_adapt(self) -> QualityConfig:
        """Let the adapt stage check every row's options (the shared ones and the row's); a row's
        own option its method does not read is refused (by the part that does not take it, or
        :func:`kbcli.core.adaptation.config.refuse_inactive`)."""
        configs = {}
        for name in self.rows:
            try:
                configs[name] = acfg = adapt_config(self, name)
            except ConfigError as exc:
                labels = {**{k: f"adapt.{k}" for k in self.adapt}, **{k: k for k in self.rows[name]}}
                refused = refused_option(exc, labels, f"rows.{name}")
                if refused is not exc:
                    raise refused from None
                raise ValueError(f"the adapt options of row {name!r}: {exc}") from None
            refuse_inactive(acfg.robot, [k for k in self.rows[name] if k != "strategy"],
                            f"rows.{name}")
        for option in self.adapt:  # a shared option some row reads is fine; one none reads is not
            if option not in option_names() or not configs:
                continue
            whys = {n: _unread(c.robot, option) for n, c in configs.items()}
            if all(whys.values()):
                first = next(iter(configs))
                raise ValueError(f"adapt.{option} does not apply to any row: {whys[first]} "
                                 f"(row {first!r})")
        return self

    @model_validator(mode="after")
    def _bounded(self) -> QualityConfig:
        """The sweep's experiments in all, checked when the config is made: before any model is
        learned (the plan's own check came after the learning phase)."""
        cells = sum(len(c.displacements) for c in self.categories) * self.experiments
        models = len(self.explorations) * len(self.budgets)
        check_total((models * len(self.rows) + bool(self.ideal)) * cells, "quality")
        return self

    def to_dict(self) -> dict:
        """The table as TOML would give it (arm resolved, categories as tables)."""
        return {
            "seed": self.seed, "budgets": list(self.budgets),
            "explorations": list(self.explorations), "mode": self.mode, "arm": dict(self.arm),
            "reach_noise": float(self.reach_noise),
            "rows": {k: dict(v) for k, v in self.rows.items()}, "baseline": self.baseline,
            # written only when set: a sweep's config stored before it existed reads back equal
            **({"baselines": dict(self.baselines)} if self.baselines else {}),
            "experiments": self.experiments, "max_steps": self.max_steps,
            "categories": {c.name: c.to_dict() for c in self.categories},
            "adapt": dict(self.adapt), "ideal": self.ideal,
        }

    def __reduce__(self):  # the read-only mappings do not pickle; the dict form does
        return (QualityConfig.from_dict, (self.to_dict(),))

    def __deepcopy__(self, memo: dict) -> QualityConfig:  # (pydantic's copies the mappings)
        return QualityConfig.from_dict(self.to_dict())

    def with_overrides(self, *, experiments: int | None = None,
                       budgets: tuple[int, ...] | None = None) -> QualityConfig:
        """A copy with the CLI's ``--experiments`` and ``--budgets`` applied (None: kept)."""
        changes = {k: v for k, v in (("experiments", experiments), ("budgets", budgets))
                   if v is not None}
        return self.replace(**changes) if changes else self


def _categories(v: Any) -> tuple[Category, ...]:
    """Categories from a TOML table ``name = {limit, displacements}`` (or kept as given)."""
    if isinstance(v, Mapping):
        out = []
        for name, t in v.items():
            if not isinstance(t, Mapping) or "displacements" not in t or \
                    set(t) - {"limit", "displacements"}:
                raise ValueError(f"{name} must have displacements (and may have limit)")
            out.append(Category(name=name, limit=t.get("limit"),
                                displacements=tuple(tuple(r) for r in t["displacements"])))
        v = out
    elif isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)):
        raise ValueError("must be a table of name = {limit, displacements}")
    cats = tuple(v)
    if not cats or not all(isinstance(c, Category) for c in cats):
        raise ValueError("must hold at least one category")
    return cats


def _rows(v: Any) -> dict[str, dict]:
    """The rows' tables, checked: each names a strategy and sets no option the sweep sets."""
    if not isinstance(v, Mapping) or not v:
        raise ValueError("must be a table of name = {strategy = ..., ...}")
    rows = {}
    for name, opts in v.items():
        if not isinstance(opts, Mapping) or "strategy" not in opts:
            raise ValueError(f"{name} must be a table with a strategy")
        fixed = sorted(set(opts) & set(FIXED))
        if fixed:
            raise ValueError(f"{name}.{fixed[0]} is set by the sweep itself")
        if name == IDEAL_ROW:
            raise ValueError(f"{name}: the name is kept for the exact model's reference "
                             "(quality.ideal)")
        rows[str(name)] = dict(opts)
    return rows


def adapt_config(cfg: QualityConfig, row: str):
    """The adapt stage's config of one row (or of :data:`IDEAL_ROW`: infogain)."""
    from kbcli.stages.adapt import AdaptConfig

    opts = {"strategy": "infogain"} if row == IDEAL_ROW else dict(cfg.rows[row])
    shared = dict(cfg.adapt)
    for slot, (registry, default) in SLOTS.items():  # the shared options the row's parts take
        part = opts.get(slot, shared.get(slot, default))
        shared = for_part(registry, part if isinstance(part, str) else part["name"], shared)
    values = {**shared, **opts, "mode": cfg.mode, "arm": dict(cfg.arm),
              "reach_noise": float(cfg.reach_noise), "max_steps": cfg.max_steps,
              "family": "translation", "stop": False}
    return AdaptConfig.from_dict(values)


def model_names(cfg: QualityConfig) -> list[tuple[str, str, int]]:
    """(name, exploration, budget) of every model of the sweep, in artifact order."""
    return [(f"{e}-{b}", e, b) for e in cfg.explorations for b in cfg.budgets]


def _unread(robot, option: str) -> str:
    """Why a row's robot config does not read ``option`` ('' when it does)."""
    if option in robot.flat():
        return robot.inactive().get(option, "")
    for slot, (registry, _) in SLOTS.items():
        who = owners(registry, option)
        if who:
            return (f"it is an option of {registry.kind} {' and '.join(who)}; here the {slot} is "
                    f"{getattr(robot, slot).name}")
    return "no part of the row takes it"
