"""The evaluation protocol's config: :class:`EvaluateConfig` (the ``[evaluate]`` table) with its
displacement categories (:mod:`.categories`) and its named methods (:mod:`.methods`), and the adapt
stage's config each experiment runs with (:func:`adapt_config`)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Annotated, Any, ClassVar

from pydantic import AfterValidator, Field, InstanceOf, field_validator, model_validator

from kbcli.core.adaptation.config import refuse_inactive
from kbcli.core.config import Name, Names, NonNegativeInt, Positive, Whole, between, refused_option
from kbcli.core.instrument import transforms
from kbcli.core.instrument.melody import DEFAULT_MELODY
from kbcli.errors import ConfigError
from kbcli.sim import MODES
from kbcli.sim.config import ReachNoise
from kbcli.stages.config import MAX_ADAPT_STEPS, MAX_EXPERIMENTS, StageConfig
from kbcli.stages.evaluate.categories import Category, _paper_categories
from kbcli.stages.evaluate.methods import (
    DEFAULT_STRATEGIES,
    Method,
    adapt_stage,
    check_modes,
    default_methods,
)


def _tables(v: Any, build: Any, what: str) -> Any:
    """``name = {...}`` tables as a tuple of ``build(name, table)``, in file order (anything else
    is left to the field's type)."""
    if not isinstance(v, Mapping):
        return v
    if not v:
        raise ConfigError(f"evaluate.{what} must hold at least one table")
    return tuple(build(name, table) for name, table in v.items())


def _descending(v: tuple) -> tuple:
    return tuple(sorted(set(v), reverse=True))


def _ascending(v: tuple) -> tuple:
    return tuple(sorted(set(v)))


def _unique(items: tuple, what: str) -> tuple:
    if len({x.name for x in items}) != len(items):
        raise ValueError(f"a name is used twice in {what}")
    return items


def _legacy_layout(d: dict) -> dict:
    """The layout before named methods (``strategies = [...]`` and an ``[evaluate.adapt]`` table):
    one method ``kbcli``, the one the claims are judged on."""
    legacy = {k: d.pop(k) for k in ("strategies", "adapt") if k in d}
    if not legacy:
        return d
    if "methods" in d:
        raise ConfigError("evaluate: give methods, or the older strategies and adapt, not both")
    old = legacy.get("adapt") or {}
    if not isinstance(old, Mapping):
        raise ConfigError("evaluate.adapt must be a table of adapt-stage options")
    strategies = legacy.get("strategies", list(DEFAULT_STRATEGIES))
    if isinstance(strategies, (str, bytes)) or not isinstance(strategies, (list, tuple)):
        raise ConfigError(f"evaluate.strategies must be a list, got {strategies!r}")
    d["methods"] = {"kbcli": {**old, "strategies": list(strategies)}}
    d.setdefault("judged", "kbcli")
    return d


class EvaluateConfig(StageConfig):
    """The evaluation protocol (the ``[evaluate]`` table of ``pipelines/paper.toml``).

    ``seed`` roots every experiment's seed and the KDE samples; ``experiments`` repetitions per
    parametrization, method, strategy and mode. ``methods`` (in TOML, a table of ``name =
    {strategies, adapt options}``, in file order) are compared; the paper's claims are judged on
    ``judged``, each method's strategies tested against ``baseline``. ``max_steps`` is T;
    ``thresholds`` (px) are kept largest first. The first run of ``example``'s first
    parametrization keeps the posterior at ``snapshot_steps`` (Fig. 5). ``reach_noise`` (px) and
    ``arm`` (a preset name or a table; missing modes get ``ideal``) are per mode. ``categories``:
    in TOML, a table of ``name = {limit, displacements}``. ``play_notes`` touches of each replay
    of ``melody`` (Algorithm 1) measure the playing success (0: not measured).

    The older layout (``strategies = [...]`` and an ``[evaluate.adapt]`` table) is read as one
    method ``kbcli`` that the claims are judged on.
    """

    what: ClassVar[str] = "evaluate"

    seed: NonNegativeInt = 2013
    experiments: between(Whole, 1, MAX_EXPERIMENTS) = 50
    methods: tuple[InstanceOf[Method], ...] = Field(default_factory=default_methods, min_length=1)
    judged: Name = "paper"
    baseline: Name = "random"
    modes: Annotated[Names, AfterValidator(check_modes)] = MODES.names()
    family: Annotated[Name, AfterValidator(transforms.FAMILIES.check)] = "translation"
    max_steps: between(Whole, 1, MAX_ADAPT_STEPS) = 40
    thresholds: Annotated[tuple[Positive, ...], AfterValidator(_descending)] = Field(
        (20.0, 15.0, 10.0, 8.0, 6.0, 4.0, 2.0, 1.0), min_length=1)
    example: Name = "small"
    snapshot_steps: Annotated[tuple[NonNegativeInt, ...], AfterValidator(_ascending)] = (
        1, 2, 3, 5, 10, 20)
    reach_noise: Mapping[str, ReachNoise] = Field(
        default_factory=lambda: {"ideal": 0.0, "dynamics": 2.0})
    arm: Mapping[str, Any] = Field(default_factory=lambda: {"ideal": "ideal", "dynamics": "ideal"})
    categories: tuple[InstanceOf[Category], ...] = Field(default_factory=_paper_categories,
                                                         min_length=1)
    play_notes: NonNegativeInt = 200
    melody: Name = DEFAULT_MELODY

    @model_validator(mode="before")
    @classmethod
    def _layout(cls, data: Any) -> Any:
        return _legacy_layout(dict(data)) if isinstance(data, Mapping) else data

    @field_validator("methods", mode="before")
    @classmethod
    def _method_tables(cls, v: Any) -> Any:
        return _tables(v, Method.from_table, "methods")

    @field_validator("categories", mode="before")
    @classmethod
    def _category_tables(cls, v: Any) -> Any:
        return _tables(v, Category.from_table, "categories")

    @field_validator("methods", "categories")
    @classmethod
    def _distinct(cls, v: tuple, info) -> tuple:
        return _unique(v, info.field_name)

    @field_validator("reach_noise")
    @classmethod
    def _reach_noise(cls, v: Mapping[str, float]) -> Mapping[str, float]:
        check_modes(tuple(v))
        return MappingProxyType({m: float(v.get(m, 0.0)) for m in MODES})

    @field_validator("arm")
    @classmethod
    def _arm(cls, v: Mapping[str, Any]) -> Mapping[str, Any]:
        from kbcli.sim.arms import arm_config

        check_modes(tuple(v))
        return MappingProxyType({m: arm_config(v.get(m)).to_dict() for m in MODES})

    @field_validator("melody")
    @classmethod
    def _melody(cls, v: str) -> str:
        if not v.split():
            raise ValueError(f"must be notes like 'A:1 D:1', got {v!r}")
        return v

    @model_validator(mode="after")
    def _across(self) -> EvaluateConfig:
        """What one table cannot check alone: names that point at other tables, displacements
        against the family, and each method's adapt options (by the adapt stage)."""
        self._check_names()
        for c in self.categories:
            c.check_rows(self.family)
        cats = [c.name for c in self.categories]
        if self.example not in cats:
            raise ConfigError(f"example {self.example!r} must name a category ({', '.join(cats)})")
        for meth in self.methods:
            for s in meth.strategies:
                for m in self.modes:
                    try:
                        acfg = adapt_config(self, meth.name, s, m)
                    except ConfigError as exc:  # a part refused an option: name the method's
                        raise refused_option(exc, {k: k for k in meth.given()},
                                             f"methods.{meth.name}") from None
            if acfg is not None:  # options the method's parts do not read are refused
                refuse_inactive(acfg.robot, meth.given(), f"methods.{meth.name}", meth.strategies)
        return self

    def _check_names(self) -> None:
        names = [m.name for m in self.methods]
        if self.judged not in names:
            raise ConfigError(f"judged {self.judged!r} must name a method ({', '.join(names)})")
        cats = [c.name for c in self.categories]
        for m in self.methods:
            if self.baseline not in m.strategies:
                raise ConfigError(f"baseline {self.baseline!r} must be one of the strategies of "
                                  f"method {m.name} ({', '.join(m.strategies)})")
            for c in m.categories or ():
                if c not in cats:
                    raise ConfigError(f"methods.{m.name}: unknown category {c!r}; valid: "
                                      f"{', '.join(cats)}")

    @property
    def n_params(self) -> int:
        return len(transforms.FAMILIES.get(self.family).params)

    @property
    def strategies(self) -> tuple[str, ...]:
        """Every strategy of any method, in first-seen order."""
        return tuple(dict.fromkeys(s for m in self.methods for s in m.strategies))

    def method(self, name: str) -> Method:
        for m in self.methods:
            if m.name == name:
                return m
        raise ConfigError(f"no method {name!r}; valid: {', '.join(m.name for m in self.methods)}")

    def __reduce__(self):  # the read-only mappings do not pickle; the dict form does
        return (EvaluateConfig.from_dict, (self.to_dict(),))

    def to_dict(self) -> dict:
        return {
            "seed": self.seed,
            "experiments": self.experiments,
            "methods": {m.name: m.to_dict() for m in self.methods},
            "judged": self.judged,
            "baseline": self.baseline,
            "modes": list(self.modes),
            "family": self.family,
            "max_steps": self.max_steps,
            "thresholds": list(self.thresholds),
            "example": self.example,
            "snapshot_steps": list(self.snapshot_steps),
            "reach_noise": dict(self.reach_noise),
            "arm": {m: dict(v) for m, v in self.arm.items()},
            "categories": {c.name: c.to_dict() for c in self.categories},
            "play_notes": self.play_notes,
            "melody": self.melody,
        }

    def with_overrides(self, *, experiments: int | None = None, mode: str | None = None,
                       methods: tuple[str, ...] | None = None) -> EvaluateConfig:
        """The config with ``--experiments``, ``--mode`` and ``--method`` applied (validated)."""
        cfg = self
        if experiments is not None:
            cfg = cfg.replace(experiments=experiments)
        if mode is not None:
            if mode not in MODES:
                raise ConfigError(f"unknown mode {mode!r}; valid: {', '.join(MODES.names())}")
            if mode not in cfg.modes:
                raise ConfigError(f"mode {mode!r} is not in the config's modes "
                                  f"({', '.join(cfg.modes)})")
            cfg = cfg.replace(modes=(mode,))
        if methods:
            keep = tuple(cfg.method(n) for n in methods)
            judged = cfg.judged if cfg.judged in methods else keep[0].name
            cfg = cfg.replace(methods=keep, judged=judged)
        return cfg


def adapt_config(cfg: EvaluateConfig, method: str, strategy: str, mode: str):
    """The adapt stage's config for one experiment (None when that stage is not available)."""
    adapt = adapt_stage()
    if adapt is None:
        return None
    values = {**cfg.method(method).options_for(strategy), "strategy": strategy, "mode": mode,
              "max_steps": cfg.max_steps, "family": cfg.family,
              "reach_noise": cfg.reach_noise[mode], "arm": dict(cfg.arm[mode])}
    if isinstance(values.get("robot"), Mapping):
        values["robot"] = dict(values["robot"])
    return adapt.AdaptConfig.from_dict(values)


def resolved_methods(cfg: EvaluateConfig, model=None) -> dict:
    """Every option each method resolves to, defaults included: ``{method: {"strategies": [...],
    "description": str, "modes": [...], "categories": [...], "options": {mode: {strategy:
    AdaptConfig.to_dict()}}, "from_model": {...}}}`` (for the artifact and the report).

    ``from_model``: the options a config leaves to the model (None there), as resolved for
    ``model``: the robust posterior's ``redundancy_radius`` (px), ``robust_blurs`` (px) and
    ``robust_eta`` (its learning rate); 0, [] and 1 with the plain or KDE posterior. Empty without a model.
    """
    from kbcli.core.adaptation.config import learning_rate, redundancy_radius, robust_blurs

    out = {}
    for m in cfg.methods:
        opts = {}
        from_model: dict = {}
        for mode in cfg.modes:
            if m.modes is not None and mode not in m.modes:
                continue
            opts[mode] = {}
            for s in m.strategies:
                acfg = adapt_config(cfg, m.name, s, mode)
                opts[mode][s] = acfg.to_dict() if acfg is not None else {}
                if acfg is not None and model is not None and not from_model:
                    r = acfg.adapter_config()
                    from_model = {
                        "redundancy_radius": redundancy_radius(model, r) if r.is_robust else 0.0,
                        "robust_blurs": list(robust_blurs(model, r)) if r.is_robust else [],
                        "robust_eta": learning_rate(model, r) if r.is_robust else 1.0}
        out[m.name] = {"strategies": list(m.strategies), "description": m.description,
                       "modes": [x for x in cfg.modes if m.modes is None or x in m.modes],
                       "categories": [c.name for c in cfg.categories
                                      if m.categories is None or c.name in m.categories],
                       "options": opts, "from_model": from_model}
    return out

