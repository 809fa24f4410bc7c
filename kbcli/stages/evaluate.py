"""Stage ``evaluate``: the paper's evaluation protocol (Sect. IV-B and IV-C, Figs. 5-7), run for
named *methods*.

A **method** is a named table of adapt options plus the strategies it compares
(``[evaluate.methods.NAME]`` in ``pipelines/paper.toml``):

- ``paper``: the paper's own method: the product of KDEs of Eq. 7-8 with Algorithm 2's sampling
  (``posterior = "kde"``), the maximum-likelihood hypothesis as the estimate (``estimator = "ml"``),
  the model as learned (``model_blur = 0``), strategies ``random`` (the baseline) and ``active``
  (Sect. III-E; its candidates' confusion and simulated updates use the model's
  ``p(sound | action)``, see :mod:`kbcli.core.strategies`, while the posterior it reads and the
  one that is updated are the KDE product);
- ``kbcli``: our best choice: whatever :class:`kbcli.core.adapt.AdapterConfig`'s defaults are (the
  likelihood posterior and the posterior mean today), strategies random, active and infogain. Its
  TOML table names only the strategies, so changing kbcli's defaults changes what ``kbcli`` means;
- any other name: an ablation (e.g. the paper's strategies and estimator on our posterior).

Every option a method resolves to (defaults included, per mode and strategy) is recorded in the
artifact (``attrs["methods"]``) and printed by the report.

Fixed displacement parametrizations are grouped in size categories (:mod:`kbcli.stages.perturb`'s
definition: the Euclidean norm of the translation in (0, 10], (10, 20] or (20, 40] px; keys are
50 px). Each parametrization is adapted to ``experiments`` times (the paper: 50) by each method and
strategy in each mode (``ideal``: the finger lands on its target; ``dynamics``: a simulated arm
reaches for it). One experiment is one call of the adapt stage's ``experiment`` for ``max_steps``
observations; it also replays the melody with Algorithm 1 (``play_notes`` touches) after adapting,
with the final estimate as the correction, and, once per (mode, parametrization, repetition),
before the displacement and after it without adaptation: playing success is measured, not derived.
Each experiment is seeded by ``SeedSequence(seed, spawn_key=...)`` with a key made of its mode,
category, parametrization, method, strategy and repetition, so a result depends neither on the
worker that ran it nor on which modes or methods were selected.

This module plans the experiments (:func:`plan`), runs one in a worker (:func:`setup`,
:func:`run_experiment`) and assembles the results into the ``evaluation`` artifact
(:func:`assemble`) with :mod:`kbcli.core.stats`: RMSE against observations per category, method
and strategy (Fig. 7), observations to each error threshold, tie-corrected Mann-Whitney U p-values
against the baseline strategy of the same method (and the smallest p-value the design can give),
entropy per step (Fig. 6), playing success, and one example run's posterior snapshots per method
and strategy (Fig. 5). Execution (serial, local processes or Dask) and checkpoints are
:mod:`kbcli.io.runner`'s job.
"""

from __future__ import annotations

import hashlib
import json
import math
import zlib
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np

from kbcli.core import stats, transforms
from kbcli.core.config import check_known, check_names, check_whole
from kbcli.core.estimators import ESTIMATORS
from kbcli.core.keyboard import Keyboard
from kbcli.core.melody import DEFAULT_MELODY
from kbcli.core.posteriors import POSTERIORS
from kbcli.errors import ConfigError
from kbcli.sim import MODES
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.perturb import CATEGORIES as SIZE_CATEGORIES
from kbcli.stages.perturb import displacement_size

#: The experiment function, ``experiment(cfg, model, keyboard, true_params, *, rng, ...) -> dict``.
EXPERIMENT = "kbcli.stages.adapt:experiment"
#: Strategies known when the adapt stage cannot be imported to ask it.
DEFAULT_STRATEGIES = ("random", "active", "infogain")
#: Adapt options the protocol sets per experiment (not in a method's table).
PER_EXPERIMENT = ("strategy", "mode", "max_steps", "family", "reach_noise", "arm")
#: Keys of a method's table that are not adapt options.
METHOD_KEYS = ("strategies", "modes", "categories", "description")
#: What an example run keeps beyond its per-step arrays (Fig. 5).
EXAMPLE_KEYS = ("snapshots", "snapshot_steps", "snapshot_angles", "dx", "dy", "angles")
#: Per-step outputs of an experiment kept for every run, each (T, ...): ``errors`` are those of the
#: method's estimator; ``ml_errors`` and ``mean_errors`` those of both estimates (for the
#: estimator ablation, from the same runs).
STEP_KEYS = ("errors", "ml_errors", "mean_errors", "entropy", "estimates", "actions", "classes",
             "angle_errors")
#: Playing success per experiment (floats, NaN when not measured).
PLAY_KEYS = ("play_before", "play_unadapted", "play_adapted")
#: Draws of p(action | sound) per melody class that the replays resample (drawn once per process
#: from a seed of their own, so every process resamples the same pool).
PLAY_POOL = 10000
#: Key of the wall-clock time per step; kept out of the artifact (it differs between runs).
TIME_KEY = "step_ms"

#: The paper's method (Sect. III-D, III-E): Eq. 7-8 with Algorithm 2, the maximum-likelihood
#: hypothesis, the learned model as it is, random and active.
PAPER_METHOD = {"description": "the paper's: product of KDEs (Eq. 7-8, Algorithm 2), "
                               "maximum-likelihood estimate, random and active (Sect. III-E)",
                "strategies": ["random", "active"], "posterior": "kde", "estimator": "ml",
                "model_blur": 0.0}
#: Ours: the adapter's defaults, every strategy.
KBCLI_METHOD = {"description": "kbcli's best: the adapter's defaults", "strategies":
                ["random", "active", "infogain"]}


def _number(name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{name} must be a finite number, got {v!r}")
    return float(v)


@dataclass(frozen=True, kw_only=True)
class Category:
    """A group of displacement parametrizations of similar size.

    Parameters
    ----------
    name : str
    limit : float, optional
        Largest displacement size (px) in this category: the Euclidean norm of each
        parametrization's translation is at most this (and, for the size categories small, medium
        and large of :data:`kbcli.stages.perturb.CATEGORIES`, above the category's lower bound).
        Default (and required value) for those three: their upper bound.
    displacements : tuple of tuples
        Transform parameters of each parametrization (``(dx, dy)`` for translation,
        ``(angle, dx, dy)`` for rigid).
    """

    name: str
    limit: float | None = None
    displacements: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        where = f"categories.{self.name}"
        known = SIZE_CATEGORIES.get(self.name)
        if self.limit is None:
            if known is None:
                raise ConfigError(f"{where}.limit is needed: {self.name!r} is not one of the size "
                                  f"categories {', '.join(SIZE_CATEGORIES)}")
            object.__setattr__(self, "limit", known[1])
        lim = _number(f"{where}.limit", self.limit)
        if lim <= 0:
            raise ConfigError(f"{where}.limit must be > 0 px, got {self.limit!r}")
        if known is not None and lim != known[1]:
            raise ConfigError(f"{where}.limit is {lim:g} px but the size category {self.name} is "
                              f"({known[0]:g}, {known[1]:g}] px (kbcli.stages.perturb.CATEGORIES)")
        d = self.displacements
        if isinstance(d, (str, bytes)) or len(d) == 0:
            raise ConfigError(f"{where}.displacements must be a non-empty list of parameter lists")
        rows = []
        for row in d:
            if isinstance(row, (str, bytes, int, float)):
                raise ConfigError(f"{where}.displacements must hold lists like [dx, dy], got {row!r}")
            rows.append(tuple(_number(f"{where}.displacements", v) for v in row))
        object.__setattr__(self, "limit", lim)
        object.__setattr__(self, "displacements", tuple(rows))

    @property
    def lower(self) -> float:
        """Exclusive lower bound of the sizes (px): the size category's, else 0."""
        return SIZE_CATEGORIES.get(self.name, (0.0, self.limit))[0]

    def to_dict(self) -> dict:
        return {"limit": self.limit, "displacements": [list(r) for r in self.displacements]}


def _paper_categories() -> tuple[Category, ...]:
    return (
        Category(name="small", limit=10.0, displacements=(
            (3.76, 1.37), (-2.05, 5.64), (-7.52, -2.74), (3.42, -9.39))),
        Category(name="medium", limit=20.0, displacements=(
            (5.07, 10.88), (-13.59, 6.34), (-7.61, -16.31), (18.12, -8.45))),
        Category(name="large", limit=40.0, displacements=(
            (19.15, 16.07), (-19.28, 22.98), (-26.81, -22.5), (25.71, -30.64))),
    )


@dataclass(frozen=True, kw_only=True)
class Method:
    """A named way to adapt: adapt options and the strategies compared under them.

    Parameters
    ----------
    name : str
    strategies : tuple of str
        Strategies run with these options (the protocol's ``baseline`` must be one of them).
    options : mapping
        Adapt-stage options (:class:`kbcli.stages.adapt.AdaptConfig`: the robot's, such as
        ``posterior`` or ``estimator``, at the top level or in a ``robot`` table, and the loop's,
        such as ``feedback``); options left out take the adapt stage's defaults. ``strategy``,
        ``mode``, ``max_steps``, ``family`` and ``reach_noise`` are set by the protocol.
    modes, categories : tuple of str, optional
        Run this method only in these modes / categories (None: all of the protocol's); for
        ablations that answer one question.
    description : str
        One line for the report.
    """

    name: str
    strategies: tuple[str, ...]
    options: Any = field(default_factory=dict)
    modes: tuple[str, ...] | None = None
    categories: tuple[str, ...] | None = None
    description: str = ""

    def __post_init__(self) -> None:
        where = f"methods.{self.name}"
        object.__setattr__(self, "strategies", check_names(f"{where}.strategies", self.strategies))
        known = known_strategies()
        for st in self.strategies:
            if st not in known:
                raise ConfigError(f"{where}: unknown strategy {st!r}; valid: {', '.join(known)}")
        for k in ("modes", "categories"):
            v = getattr(self, k)
            if v is not None:
                object.__setattr__(self, k, check_names(f"{where}.{k}", v))
        if self.modes is not None:
            for m in self.modes:
                if m not in MODES:
                    raise ConfigError(f"{where}: unknown mode {m!r}; valid: {', '.join(MODES)}")
        if not isinstance(self.description, str):
            raise ConfigError(f"{where}.description must be text")
        if not isinstance(self.options, (dict, MappingProxyType)):
            raise ConfigError(f"{where} must be a table of adapt options")
        opts = dict(self.options)
        fixed = sorted(set(opts) & set(PER_EXPERIMENT))
        if isinstance(opts.get("robot"), dict):
            fixed += sorted(set(opts["robot"]) & set(PER_EXPERIMENT))
        if fixed:
            raise ConfigError(
                f"{where}.{fixed[0]} is set per experiment by the protocol: use strategies, "
                "modes, max_steps, family, reach_noise and arm of [evaluate] instead"
            )
        object.__setattr__(self, "options", MappingProxyType(opts))

    def runs_in(self, mode: str, category: str) -> bool:
        return ((self.modes is None or mode in self.modes)
                and (self.categories is None or category in self.categories))

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"strategies": list(self.strategies)}
        if self.modes is not None:
            d["modes"] = list(self.modes)
        if self.categories is not None:
            d["categories"] = list(self.categories)
        if self.description:
            d["description"] = self.description
        d.update({k: (dict(v) if isinstance(v, (dict, MappingProxyType)) else v)
                  for k, v in self.options.items()})
        return d

    @classmethod
    def from_dict(cls, name: str, d: dict) -> Method:
        if not isinstance(d, (dict, MappingProxyType)):
            raise ConfigError(f"methods.{name} must be a table (strategies and adapt options)")
        d = dict(d)
        if "strategies" not in d:
            raise ConfigError(f"methods.{name} needs strategies = [...]")
        kw = {k: d.pop(k) for k in METHOD_KEYS if k in d}
        for k in ("strategies", "modes", "categories"):
            if k in kw and isinstance(kw[k], list):
                kw[k] = tuple(kw[k])
        return cls(name=name, options=d, **kw)


def _default_methods() -> tuple[Method, ...]:
    return (Method.from_dict("paper", PAPER_METHOD), Method.from_dict("kbcli", KBCLI_METHOD))


@dataclass(frozen=True, kw_only=True)
class EvaluateConfig:
    """The evaluation protocol (the ``[evaluate]`` table of ``pipelines/paper.toml``).

    Parameters
    ----------
    seed : int
        Root of every experiment's seed (and of the KDE samples, drawn once per class).
    experiments : int
        Repetitions per parametrization, method, strategy and mode (the paper: 50).
    methods : tuple of Method
        The named methods compared (default: ``paper`` and ``kbcli``, see the module docstring).
    judged : str
        The method the paper's claims are judged on (``paper``); the others are shown beside it.
    baseline : str
        The strategy each method's others are tested against (in every method's strategies).
    modes : tuple of str
        Reaching modes (:data:`kbcli.sim.MODES`).
    family : str
        Transform family (:data:`kbcli.core.transforms.FAMILIES`).
    max_steps : int
        Observations per experiment (T).
    thresholds : tuple of float
        Error thresholds (px) for the observations-to-threshold table and the tests.
    example : str
        Category whose first parametrization's first run, per mode, method and strategy, keeps its
        posterior snapshots (Fig. 5).
    snapshot_steps : tuple of int
        Steps (observations) at which the example runs keep the posterior.
    reach_noise : mapping
        Landing scatter of the arm (px) in each mode: ``ideal`` lands exactly (0, the paper's
        idealised problem); ``dynamics`` adds motor noise to the simulated arm.
    arm : mapping
        Arm of each mode: a preset name (``ideal``, ``servo``, ``realistic``) or a table
        (:mod:`kbcli.sim.arms`); missing modes get ``ideal``.
    categories : tuple of Category
        Displacement categories, in order.
    play_notes : int
        Touches of each melody replay (Algorithm 1) measuring the playing success; 0: not measured.
    melody : str
        The melody replayed.
    """

    seed: int = 2013
    experiments: int = 50
    methods: tuple[Method, ...] = field(default_factory=_default_methods)
    judged: str = "paper"
    baseline: str = "random"
    modes: tuple[str, ...] = MODES
    family: str = "translation"
    max_steps: int = 40
    thresholds: tuple[float, ...] = (20.0, 15.0, 10.0, 8.0, 6.0, 4.0, 2.0, 1.0)
    example: str = "small"
    snapshot_steps: tuple[int, ...] = (1, 2, 3, 5, 10, 20)
    reach_noise: Any = field(default_factory=lambda: {"ideal": 0.0, "dynamics": 2.0})
    arm: Any = field(default_factory=lambda: {"ideal": "ideal", "dynamics": "ideal"})
    categories: tuple[Category, ...] = field(default_factory=_paper_categories)
    play_notes: int = 200
    melody: str = DEFAULT_MELODY

    def __post_init__(self) -> None:
        check_whole("seed", self.seed, 0)
        check_whole("experiments", self.experiments, 1)
        check_whole("max_steps", self.max_steps, 1)
        check_whole("play_notes", self.play_notes, 0)
        if not isinstance(self.melody, str) or not self.melody.split():
            raise ConfigError(f"melody must be notes like 'A:1 D:1', got {self.melody!r}")
        names = transforms.check_family(self.family)
        object.__setattr__(self, "modes", check_names("modes", self.modes))
        for m in self.modes:
            if m not in MODES:
                raise ConfigError(f"unknown mode {m!r}; valid: {', '.join(MODES)}")
        methods = tuple(self.methods)
        if not methods or not all(isinstance(m, Method) for m in methods):
            raise ConfigError("methods must hold at least one method")
        if len({m.name for m in methods}) != len(methods):
            raise ConfigError("methods: a name is used twice")
        object.__setattr__(self, "methods", methods)
        if self.judged not in {m.name for m in methods}:
            raise ConfigError(f"judged {self.judged!r} must name a method "
                              f"({', '.join(m.name for m in methods)})")
        for m in methods:
            if self.baseline not in m.strategies:
                raise ConfigError(f"baseline {self.baseline!r} must be one of the strategies of "
                                  f"method {m.name} ({', '.join(m.strategies)})")
        thr = tuple(_number("thresholds", t) for t in self.thresholds)
        if not thr or any(t <= 0 for t in thr):
            raise ConfigError(f"thresholds must be a non-empty list of px > 0, got {self.thresholds!r}")
        object.__setattr__(self, "thresholds", tuple(sorted(set(thr), reverse=True)))
        cats = tuple(self.categories)
        if not cats or not all(isinstance(c, Category) for c in cats):
            raise ConfigError("categories must hold at least one category")
        if len({c.name for c in cats}) != len(cats):
            raise ConfigError("categories: a name is used twice")
        for c in cats:
            for row in c.displacements:
                if len(row) != len(names):
                    raise ConfigError(
                        f"categories.{c.name}: a {self.family} displacement has {len(names)} "
                        f"parameters ({', '.join(names)}), got {list(row)}"
                    )
                size = float(displacement_size(np.asarray(row, float)))
                if size > c.limit + 1e-9:
                    raise ConfigError(
                        f"categories.{c.name}: displacement {list(row)} is {size:.2f} px, "
                        f"beyond the category's limit of {c.limit:g} px"
                    )
                if size <= c.lower:
                    raise ConfigError(
                        f"categories.{c.name}: displacement {list(row)} is {size:.2f} px, not "
                        f"above the category's lower bound of {c.lower:g} px (sizes are Euclidean)"
                    )
        object.__setattr__(self, "categories", cats)
        cat_names = {c.name for c in cats}
        for m in methods:
            for c in m.categories or ():
                if c not in cat_names:
                    raise ConfigError(f"methods.{m.name}: unknown category {c!r}; valid: "
                                      f"{', '.join(cat_names)}")
        if self.example not in cat_names:
            raise ConfigError(
                f"example {self.example!r} must name a category ({', '.join(c.name for c in cats)})"
            )
        snaps = self.snapshot_steps
        if isinstance(snaps, (str, bytes)) or not all(
                isinstance(v, int) and not isinstance(v, bool) and 0 <= v for v in snaps):
            raise ConfigError(f"snapshot_steps must be a list of whole numbers >= 0, got {snaps!r}")
        object.__setattr__(self, "snapshot_steps", tuple(sorted(set(snaps))))
        if not isinstance(self.reach_noise, (dict, MappingProxyType)):
            raise ConfigError("reach_noise must be a table of mode = px")
        noise = dict(self.reach_noise)
        for m, v in noise.items():
            if m not in MODES:
                raise ConfigError(f"reach_noise: unknown mode {m!r}; valid: {', '.join(MODES)}")
            if _number(f"reach_noise.{m}", v) < 0:
                raise ConfigError(f"reach_noise.{m} must be >= 0 px, got {v!r}")
        object.__setattr__(self, "reach_noise", MappingProxyType(
            {m: float(noise.get(m, 0.0)) for m in MODES}))
        if not isinstance(self.arm, (dict, MappingProxyType)):
            raise ConfigError("arm must be a table of mode = preset name (or table)")
        from kbcli.sim.arms import arm_config

        arms = dict(self.arm)
        for m in arms:
            if m not in MODES:
                raise ConfigError(f"arm: unknown mode {m!r}; valid: {', '.join(MODES)}")
        object.__setattr__(self, "arm", MappingProxyType(
            {m: arm_config(arms.get(m)).to_dict() for m in MODES}))
        for meth in methods:  # let the adapt stage check each method's options
            for s in meth.strategies:
                for m in self.modes:
                    adapt_config(self, meth.name, s, m)

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

    @classmethod
    def from_dict(cls, d: dict) -> EvaluateConfig:
        """Build from the ``[evaluate]`` table; unknown keys are rejected at every level.

        ``methods`` and ``categories`` are tables of ``name = {...}``, kept in file order. The
        layout before named methods (``strategies = [...]`` and an ``[evaluate.adapt]`` table) is
        still read, as one method ``kbcli`` that the claims are judged on.
        """
        if not isinstance(d, dict):
            raise ConfigError("[evaluate] must be a table")
        d = dict(d)
        legacy = {k: d.pop(k) for k in ("strategies", "adapt") if k in d}
        check_known(cls, d, "evaluate")
        if legacy:
            if "methods" in d:
                raise ConfigError("give methods, or the older strategies and adapt, not both")
            old = dict(legacy.get("adapt") or {})
            if not isinstance(legacy.get("adapt", {}), dict):
                raise ConfigError("adapt must be a table of adapt-stage options")
            strategies = legacy.get("strategies", list(DEFAULT_STRATEGIES))
            if isinstance(strategies, (str, bytes)) or not isinstance(strategies, (list, tuple)):
                raise ConfigError(f"strategies must be a list, got {strategies!r}")
            d["methods"] = {"kbcli": {**old, "strategies": list(strategies)}}
            d.setdefault("judged", "kbcli")
        for k in ("modes", "thresholds", "snapshot_steps"):
            if k in d:
                if isinstance(d[k], (str, bytes)) or not isinstance(d[k], (list, tuple)):
                    raise ConfigError(f"{k} must be a list, got {d[k]!r}")
                d[k] = tuple(d[k])
        if "methods" in d:
            meths = d["methods"]
            if not isinstance(meths, dict) or not meths:
                raise ConfigError("methods must be a table of name = {strategies, options}")
            d["methods"] = tuple(Method.from_dict(n, t) for n, t in meths.items())
        if "categories" in d:
            cats = d["categories"]
            if not isinstance(cats, dict):
                raise ConfigError("categories must be a table of name = {limit, displacements}")
            out = []
            for name, table in cats.items():
                if not isinstance(table, dict):
                    raise ConfigError(f"categories.{name} must be a table with displacements")
                extra = sorted(set(table) - {"limit", "displacements"})
                if extra or "displacements" not in table:
                    raise ConfigError(
                        f"categories.{name} must have displacements (and may have limit)"
                        + (f" (unknown: {', '.join(extra)})" if extra else "")
                    )
                out.append(Category(name=name, limit=table.get("limit"),
                                    displacements=tuple(tuple(r) for r in table["displacements"])))
            d["categories"] = tuple(out)
        return cls(**d)

    def with_overrides(self, *, experiments: int | None = None, mode: str | None = None,
                       methods: tuple[str, ...] | None = None) -> EvaluateConfig:
        """The config with ``--experiments``, ``--mode`` and ``--method`` applied (validated)."""
        cfg = self
        if experiments is not None:
            cfg = replace(cfg, experiments=experiments)
        if mode is not None:
            if mode not in MODES:
                raise ConfigError(f"unknown mode {mode!r}; valid: {', '.join(MODES)}")
            if mode not in cfg.modes:
                raise ConfigError(f"mode {mode!r} is not in the config's modes ({', '.join(cfg.modes)})")
            cfg = replace(cfg, modes=(mode,))
        if methods:
            keep = tuple(cfg.method(n) for n in methods)
            judged = cfg.judged if cfg.judged in methods else keep[0].name
            cfg = replace(cfg, methods=keep, judged=judged)
        return cfg


def _adapt_stage():
    """The adapt stage module, or None while it is not available."""
    import importlib

    try:
        return importlib.import_module("kbcli.stages.adapt")
    except ModuleNotFoundError as exc:
        if exc.name != "kbcli.stages.adapt":
            raise
        return None


def known_strategies() -> tuple[str, ...]:
    """Strategy names the adapt stage offers (its registry), or :data:`DEFAULT_STRATEGIES`."""
    adapt = _adapt_stage()
    if adapt is None:
        return DEFAULT_STRATEGIES
    reg = getattr(adapt, "STRATEGIES", None)
    return tuple(reg) if reg else DEFAULT_STRATEGIES


def adapt_config(cfg: EvaluateConfig, method: str, strategy: str, mode: str):
    """The adapt stage's config for one experiment (None when that stage is not available)."""
    adapt = _adapt_stage()
    if adapt is None:
        return None
    values = {**cfg.method(method).options, "strategy": strategy, "mode": mode,
              "max_steps": cfg.max_steps, "family": cfg.family,
              "reach_noise": cfg.reach_noise[mode], "arm": dict(cfg.arm[mode])}
    if isinstance(values.get("robot"), (dict, MappingProxyType)):
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
    from kbcli.core.adapt import learning_rate, redundancy_radius, robust_blurs

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


# -- planning -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task:
    """One experiment: what a worker needs to run it (picklable, immutable).

    The seed is stored as the (entropy, spawn_key) of its ``SeedSequence``, not as the object:
    spawning from a ``SeedSequence`` mutates it, so a shared object would seed a rerun differently.
    ``play_reference``: this experiment also replays the melody before the displacement and after it
    without adaptation (once per mode, parametrization and repetition: the first method and strategy
    that runs there).
    """

    row: int
    seed_index: int
    mode: str
    category: str
    param_index: int
    params: tuple[float, ...]
    method: str
    strategy: str
    rep: int
    entropy: int
    spawn_key: tuple[int, ...]
    example: bool
    play_reference: bool = False

    @property
    def seed(self) -> np.random.SeedSequence:
        """A fresh ``SeedSequence`` for this experiment."""
        return np.random.SeedSequence(self.entropy, spawn_key=self.spawn_key)


def _key(name: str) -> int:
    return zlib.crc32(name.encode())


def plan(cfg: EvaluateConfig) -> list[Task]:
    """The experiments of ``cfg`` in artifact row order (mode, category, parametrization, method,
    strategy, repetition), each with its seed.

    The seed is ``SeedSequence(cfg.seed, spawn_key=(mode, category, parametrization, method,
    strategy, repetition))`` (names as CRC-32 numbers), so an experiment gets the same seed whatever
    else is selected. ``seed_index`` numbers the experiments in that order.
    """
    tasks: list[Task] = []
    seen: set = set()
    for mode in cfg.modes:
        for cat in cfg.categories:
            for p, params in enumerate(cat.displacements):
                for meth in cfg.methods:
                    if not meth.runs_in(mode, cat.name):
                        continue
                    for strategy in meth.strategies:
                        for rep in range(cfg.experiments):
                            key = (_key(mode), _key(cat.name), p, _key(meth.name), _key(strategy),
                                   rep)
                            ref_key = (mode, cat.name, p, rep)
                            tasks.append(Task(
                                row=len(tasks), seed_index=len(tasks), mode=mode,
                                category=cat.name, param_index=p, params=params,
                                method=meth.name, strategy=strategy, rep=rep, entropy=cfg.seed,
                                spawn_key=key,
                                example=cat.name == cfg.example and p == 0 and rep == 0,
                                play_reference=cfg.play_notes > 0 and ref_key not in seen,
                            ))
                            seen.add(ref_key)
    return tasks


def context(cfg: EvaluateConfig, model_art: Artifact, experiment: str = EXPERIMENT) -> dict:
    """What every worker shares: the model artifact, the config and the experiment's name."""
    return {"model": model_art, "evaluate": cfg.to_dict(), "experiment": experiment}


def context_key(ctx: dict) -> str:
    """A digest identifying a context (model file hash, config and experiment function)."""
    art = ctx["model"]
    ident = {"model": art.sha256 or json.dumps(art.config, sort_keys=True, default=str),
             "evaluate": ctx["evaluate"], "experiment": ctx["experiment"]}
    return hashlib.sha256(json.dumps(ident, sort_keys=True, default=str).encode()).hexdigest()


# -- the worker side ------------------------------------------------------------------------------
def resolve(name: str) -> Any:
    """The module-level object named ``"package.module:attribute"`` (picklable by reference)."""
    import importlib

    module, _, attr = name.partition(":")
    if not module or not attr:
        raise ConfigError(f"function name {name!r} must look like 'package.module:function'")
    return getattr(importlib.import_module(module), attr)


def setup(ctx: dict) -> dict:
    """Per-process state: the model, the keyboard, the config and the experiment function."""
    from kbcli.stages import keyboard as keyboard_stage
    from kbcli.stages.models import load_model

    art = ctx["model"]
    return {
        "model": load_model(art),
        "keyboard": keyboard_stage.load(art),
        "cfg": EvaluateConfig.from_dict(ctx["evaluate"]),
        "experiment": resolve(ctx["experiment"]),
        "tables": {},
        "samples": {},
    }


def run_experiment(state: dict, task: Task) -> dict[str, np.ndarray]:
    """Run one experiment; returns its per-step arrays (padded to ``max_steps``), its playing
    success, its wall time per step, and (for the example runs only) everything else it returned
    (posterior snapshots)."""
    cfg: EvaluateConfig = state["cfg"]
    acfg = adapt_config(cfg, task.method, task.strategy, task.mode)
    rng = np.random.default_rng(task.seed)
    kw: dict[str, Any] = {
        "table": _table(state, acfg),
        "snapshot_steps": cfg.snapshot_steps if task.example else (),
    }
    samples = _samples(state, acfg, cfg.seed)
    if samples is not None:
        kw["samples"] = samples
    adapt = _adapt_stage()
    if cfg.play_notes > 0 and adapt is not None and hasattr(adapt, "PlayCheck"):
        kw["play"] = adapt.PlayCheck(melody=cfg.melody, notes=cfg.play_notes,
                                     reference=task.play_reference)
        if "play_pool" not in state:  # Algorithm 1's actions: a pool per class, resampled
            from kbcli.core.posterior import ActionSamples

            state["play_pool"] = ActionSamples(state["model"], PLAY_POOL, [cfg.seed, _key("play")])
        kw["play_pool"] = state["play_pool"]
    truth = np.asarray(task.params, float)
    out = state["experiment"](acfg, state["model"], state["keyboard"], truth, rng=rng, **kw)
    out = dict(out)
    if "means" in out:  # both estimates' errors, whichever the method reports
        out["mean_errors"] = np.hypot(*(np.asarray(out["means"])[:, -2:] - truth[-2:]).T)
        est = ESTIMATORS.get(getattr(acfg, "estimator", "mean"))
        out["estimates"] = out[est.record]  # "errors" are those of the method's estimator
    return _normalise(out, cfg.max_steps, cfg.n_params, keep_extra=task.example)


def _table(state: dict, acfg):
    """The model raster for ``acfg``, built once per process and shared by every experiment that
    rasterises the same way (it depends on the robot's settings, not on the strategy)."""
    adapt = _adapt_stage()
    if acfg is None or adapt is None:
        return None
    key = acfg.adapter_config().replace(strategy="random")
    if key not in state["tables"]:
        state["tables"][key] = adapt.build_shared_table(acfg, state["model"])
    return state["tables"][key]


def _samples(state: dict, acfg, seed: int):
    """The KDE posterior's per-class samples, shared by every experiment of the process with the
    same sampling settings; drawn from ``SeedSequence([seed, cls])`` once per class, so every
    process draws the same ones (None for other posteriors)."""
    adapt = _adapt_stage()
    if acfg is None or adapt is None or not POSTERIORS.get(getattr(acfg, "posterior", "likelihood")).uses_samples:
        return None
    r = acfg.adapter_config()
    key = (r.kde_samples, r.kde_bandwidth, r.resolution)
    if key not in state["samples"]:
        state["samples"][key] = adapt.build_shared_samples(acfg, state["model"], [seed])
    return state["samples"][key]


def _pad(a: np.ndarray, length: int) -> np.ndarray:
    if len(a) >= length:
        return a[:length]
    if len(a) == 0:
        return np.full((length,) + a.shape[1:], np.nan)
    return np.concatenate([a, np.repeat(a[-1:], length - len(a), axis=0)])


def _normalise(out: dict, steps: int, n_params: int, keep_extra: bool) -> dict[str, np.ndarray]:
    res: dict[str, Any] = {}
    taken = len(np.asarray(out["errors"]))
    res["steps_taken"] = np.int64(taken)
    shapes = {"errors": (), "ml_errors": (), "mean_errors": (), "entropy": (),
              "estimates": (n_params,), "actions": (2,), "classes": (), "angle_errors": ()}
    for k in STEP_KEYS:
        if k in out:
            a = np.asarray(out[k])
            a = a.astype(np.int64) if k == "classes" else a.astype(np.float64)
            res[k] = _pad(a.reshape((len(a),) + shapes[k]), steps)
        elif k == "angle_errors":
            res[k] = np.zeros(steps)
        elif k in ("ml_errors", "mean_errors"):
            res[k] = np.full(steps, np.nan)
        else:
            raise KeyError(f"the experiment returned no {k!r}")
    for k in PLAY_KEYS:
        res[k] = np.float64(out.get(k, np.nan))
    res[TIME_KEY] = np.asarray(out.get(TIME_KEY, np.zeros(taken)), np.float64)
    if keep_extra:
        extra = {k: np.asarray(v) for k, v in out.items() if k in EXAMPLE_KEYS}
        if extra:
            res["extra"] = extra
    return res


# -- assembling the artifact ----------------------------------------------------------------------
def _stack(results: dict[int, dict], n: int, key: str) -> np.ndarray:
    return np.stack([results[i][key] for i in range(n)])


def _tests(counts: dict[str, np.ndarray], baseline: str) -> dict[str, dict]:
    """Tie-corrected Mann-Whitney U of each strategy's counts against the baseline's."""
    out = {}
    for s, c in counts.items():
        if s == baseline:
            continue
        eff, p = stats.mannwhitney_pvalues(c, counts[baseline])
        out[s] = {"statistic": eff, "pvalue": p,
                  "min_pvalue": np.float64(stats.min_pvalue_unpaired(len(c), len(counts[baseline])))}
    return out


def assemble(cfg: EvaluateConfig, tasks: list[Task], results: dict[int, dict],
             model_art: Artifact, keyboard: Keyboard) -> Artifact:
    """The ``evaluation`` artifact from every experiment's result (``results[row]``).

    Layout (``M``/``X``/``C``/``S`` are mode, method, category and strategy names; ``k``
    thresholds; ``T`` steps):

    - ``experiments/``: the experiment table: ``mode``, ``category``, ``method``, ``strategy`` (n,)
      str; ``param_index``, ``rep``, ``seed_index``, ``steps_taken`` (n,) int; ``params`` (n, P);
      ``play_before``, ``play_unadapted``, ``play_adapted`` (n,): measured playing success (share
      of MATCH in ``play_notes`` touches of Algorithm 1) before the displacement, after it without
      adaptation (both measured once per mode, parametrization and repetition, and repeated on
      every row that shares them) and after adaptation with the final estimate; NaN when not
      measured;
    - ``steps/``: ``errors`` (of the method's estimator), ``ml_errors``, ``mean_errors``,
      ``entropy``, ``angle_errors`` (n, T); ``estimates`` (n, T, P); ``actions`` (n, T, 2);
      ``classes`` (n, T);
    - ``thresholds`` (k,) px;
    - ``curves/M/X/C/S/``: ``rmse``, ``mean``, ``std``, ``q25``, ``median``, ``q75`` (T,) of the
      error; ``rmse_by_param`` (G, T); ``rmse_ml``, ``rmse_mean`` (T,) of each estimator;
      ``entropy_mean``, ``entropy_q25``, ``entropy_median``, ``entropy_q75`` (T,);
      ``samples_to_threshold`` (n_MXCS, k); ``median_samples``, ``reached`` (k,) and the same for
      each estimator (``median_samples_ml``, ``reached_ml``, ...);
    - ``pvalues/M/X/C/S/``: ``pvalue``, ``statistic`` (k,) of the tie-corrected Mann-Whitney U test
      of S against the baseline strategy of method X (``statistic``: ``P(S slower) - 1/2``, < 0 when
      S needed fewer observations), the same per estimator (``pvalue_ml``, ``statistic_ml``, ...),
      and ``min_pvalue``, the smallest p-value these sample sizes can give;
    - ``entropy/M/X/S/``: ``mean``, ``q25``, ``median``, ``q75`` (T,) over every category (Fig. 6);
    - ``examples/M/X/S/``: the example run's posterior snapshots (Fig. 5) and ``row``.

    ``attrs["methods"]`` holds every option each method resolved to (:func:`resolved_methods`).
    """
    n = len(tasks)
    missing = [i for i in range(n) if i not in results]
    if missing:
        raise ConfigError(f"{len(missing)} experiment(s) have no result (first: row {missing[0]})")
    T = cfg.max_steps
    params = np.array([t.params for t in tasks], float).reshape(n, cfg.n_params)
    steps = {k: _stack(results, n, k) for k in STEP_KEYS}
    mode = np.array([t.mode for t in tasks])
    category = np.array([t.category for t in tasks])
    method = np.array([t.method for t in tasks])
    strategy = np.array([t.strategy for t in tasks])
    param_index = np.array([t.param_index for t in tasks], np.int64)
    play = {k: np.array([float(results[i].get(k, np.nan)) for i in range(n)]) for k in PLAY_KEYS}
    refs = {(t.mode, t.category, t.param_index, t.rep): t.row for t in tasks if t.play_reference}
    for k in ("play_before", "play_unadapted"):
        src = play[k].copy()
        play[k] = np.array([src[refs[(t.mode, t.category, t.param_index, t.rep)]]
                            if (t.mode, t.category, t.param_index, t.rep) in refs else np.nan
                            for t in tasks])
    thr = np.asarray(cfg.thresholds, float)
    err_by = {"": steps["errors"], "_ml": steps["ml_errors"], "_mean": steps["mean_errors"]}

    curves: dict[str, Any] = {}
    pvalues: dict[str, Any] = {}
    entropy: dict[str, Any] = {}
    examples: dict[str, Any] = {}
    for m in cfg.modes:
        curves[m], pvalues[m], entropy[m], examples[m] = {}, {}, {}, {}
        for meth in cfg.methods:
            x = meth.name
            if not any(meth.runs_in(m, c.name) for c in cfg.categories):
                continue
            curves[m][x], pvalues[m][x], entropy[m][x], examples[m][x] = {}, {}, {}, {}
            for s in meth.strategies:
                sel = (mode == m) & (method == x) & (strategy == s)
                entropy[m][x][s] = stats.entropy_curves(steps["entropy"][sel])
            for c in cfg.categories:
                if not meth.runs_in(m, c.name):
                    continue
                curves[m][x][c.name], pvalues[m][x][c.name] = {}, {}
                counts: dict[str, dict[str, np.ndarray]] = {sfx: {} for sfx in err_by}
                for s in meth.strategies:
                    sel = (mode == m) & (category == c.name) & (method == x) & (strategy == s)
                    cur = stats.curves(steps["errors"][sel], param_index[sel])
                    cur["rmse_by_param"] = cur.pop("rmse_by_group")
                    ent = stats.entropy_curves(steps["entropy"][sel])
                    cur.update({f"entropy_{k}": v for k, v in ent.items()})
                    for sfx, e in err_by.items():
                        e = e[sel]
                        if sfx:
                            cur[f"rmse{sfx}"] = stats.rmse_curve(e)
                        cnt = stats.samples_to_threshold(np.nan_to_num(e, nan=np.inf), thr)
                        counts[sfx][s] = cnt
                        cur[f"median_samples{sfx}"] = stats.median_samples(cnt, T)
                        cur[f"reached{sfx}"] = stats.reached(cnt, T)
                    cur["samples_to_threshold"] = counts[""][s]
                    cur["play_adapted"] = play["play_adapted"][sel]
                    curves[m][x][c.name][s] = cur
                for sfx in err_by:
                    for s, res in _tests(counts[sfx], cfg.baseline).items():
                        entry = pvalues[m][x][c.name].setdefault(s, {})
                        if sfx:
                            entry[f"pvalue{sfx}"] = res["pvalue"]
                            entry[f"statistic{sfx}"] = res["statistic"]
                        else:
                            entry.update(res)
            for t in tasks:
                if t.example and t.mode == m and t.method == x:
                    extra = results[t.row].get("extra", {})
                    examples[m][x][t.strategy] = {"row": np.int64(t.row), **extra}

    # Wall times (TIME_KEY) stay out of the artifact: they differ between identical runs.
    data = {
        "experiments": {
            "mode": mode, "category": category, "method": method, "strategy": strategy,
            "param_index": param_index,
            "rep": np.array([t.rep for t in tasks], np.int64),
            "seed_index": np.array([t.seed_index for t in tasks], np.int64),
            "steps_taken": np.array([results[i]["steps_taken"] for i in range(n)], np.int64),
            "params": params, **play,
        },
        "steps": steps,
        "thresholds": thr,
        "curves": curves,
        "pvalues": pvalues,
        "entropy": entropy,
        "examples": examples,
    }
    attrs = {
        "n_experiments": n,
        "modes": list(cfg.modes),
        "categories": [c.name for c in cfg.categories],
        "methods": resolved_methods(cfg, _load_model(model_art)),
        "method_order": [m.name for m in cfg.methods],
        "judged": cfg.judged,
        "strategies": list(cfg.strategies),
        "baseline": cfg.baseline,
        "max_steps": T,
        "play_notes": cfg.play_notes,
        "melody": cfg.melody,
        "model_strategy": model_art.config.get("strategy"),
    }
    return Artifact(kind="evaluation", config=cfg.to_dict(), seed=cfg.seed, data=data, attrs=attrs,
                    inputs={"model": ref(model_art)})


def timing(results: dict[int, dict]) -> np.ndarray:
    """All per-step wall times (ms) of ``results``, for the CLI's summary."""
    parts = [np.ravel(r[TIME_KEY]) for r in results.values() if TIME_KEY in r]
    return np.concatenate(parts) if parts else np.zeros(0)


def _load_model(model_art: Artifact):
    """The model stored in ``model_art``."""
    from kbcli.stages.models import load_model

    return load_model(model_art)


def fingerprint(cfg: EvaluateConfig, model_art: Artifact, experiment: str = EXPERIMENT) -> dict:
    """What a checkpoint must match to be resumed: the config, the model and the code version."""
    from kbcli import __version__

    return {
        "evaluate": cfg.to_dict(),
        "model_sha256": model_art.sha256,
        "experiment": experiment,
        "kbcli_version": __version__,
        "n_experiments": len(plan(cfg)),
    }


def run(cfg: EvaluateConfig, model_art: Artifact, experiment: str = EXPERIMENT) -> Artifact:
    """Run the whole protocol in this process, one experiment after another, and return the
    artifact (the CLI runs the same functions through :mod:`kbcli.io.runner` instead, for parallel
    backends and checkpoints)."""
    tasks = plan(cfg)
    state = setup(context(cfg, model_art, experiment))
    results = {t.row: run_experiment(state, t) for t in tasks}
    return assemble(cfg, tasks, results, model_art, state["keyboard"])
