"""Stage ``evaluate``: the paper's evaluation protocol (Sect. IV-B and IV-C, Figs. 6 and 7).

Fixed displacement parametrizations are grouped in categories (small: up to 10 px, medium: up to
20 px, large: up to 40 px; keys are 50 px). Each parametrization is adapted to ``experiments``
times (the paper: 50) by each strategy (``random``, the paper's baseline; ``active``, the paper's;
``infogain``, ours) in each mode (``ideal``: the finger lands on its target; ``dynamics``: a
simulated arm reaches for it). One experiment is one call of the adapt stage's ``experiment``
(Algorithm 2 and Eq. 8 for ``max_steps`` observations), seeded by its own child of
``numpy.random.SeedSequence(seed).spawn(n)``. The child is chosen by the experiment's index in the
canonical grid (every mode of :data:`kbcli.sim.MODES` x categories x parametrizations x strategies
x repetitions), so a result depends neither on the worker that ran it nor on which modes were
selected.

This module plans the experiments (:func:`plan`), runs one in a worker (:func:`setup`,
:func:`run_experiment`) and assembles the results into the ``evaluation`` artifact
(:func:`assemble`) with :mod:`kbcli.core.stats`: RMSE against observations per category and
strategy (Fig. 7), observations to each error threshold, Wilcoxon rank-sum p-values against the
baseline, entropy per step (Fig. 6), the playing success the estimates give (Sect. IV-C: "restoring
its previous performance"), and one example run's posterior snapshots per strategy (Fig. 5).
Execution (serial, local processes or Dask) and checkpoints are :mod:`kbcli.io.runner`'s job.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np

from kbcli.core import stats, transforms
from kbcli.core.config import check_known
from kbcli.core.keyboard import Keyboard
from kbcli.errors import ConfigError
from kbcli.sim import MODES
from kbcli.stages.artifact import Artifact, ref

#: The experiment function, ``experiment(cfg, model, keyboard, true_params, *, rng) -> dict``.
EXPERIMENT = "kbcli.stages.adapt:experiment"
#: Strategies known when the adapt stage cannot be imported to ask it.
DEFAULT_STRATEGIES = ("random", "active", "infogain")
#: Adapt options the protocol sets per experiment (not in ``[evaluate.adapt]``).
PER_EXPERIMENT = ("strategy", "mode", "max_steps", "family", "reach_noise", "arm")
#: What an example run keeps beyond its per-step arrays (Fig. 5).
EXAMPLE_KEYS = ("snapshots", "snapshot_steps", "snapshot_angles", "dx", "dy", "angles")
#: Per-step outputs of an experiment kept for every run, each (T, ...).
STEP_KEYS = ("errors", "entropy", "estimates", "actions", "classes", "angle_errors")
#: Key of the wall-clock time per step; kept out of the artifact (it differs between runs).
TIME_KEY = "step_ms"


def _number(name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{name} must be a finite number, got {v!r}")
    return float(v)


def _whole(name: str, v: Any, low: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < low:
        raise ConfigError(f"{name} must be a whole number >= {low}, got {v!r}")
    return v


def _names(name: str, v: Any) -> tuple[str, ...]:
    if isinstance(v, str) or not all(isinstance(s, str) for s in v) or len(v) == 0:
        raise ConfigError(f"{name} must be a non-empty list of names, got {v!r}")
    if len(set(v)) != len(v):
        raise ConfigError(f"{name} lists a name twice: {list(v)!r}")
    return tuple(v)


@dataclass(frozen=True, kw_only=True)
class Category:
    """A group of displacement parametrizations of similar size.

    Parameters
    ----------
    name : str
    limit : float
        Largest displacement (px) in this category; each parametrization's translation is at most
        this long.
    displacements : tuple of tuples
        Transform parameters of each parametrization (``(dx, dy)`` for translation,
        ``(angle, dx, dy)`` for rigid).
    """

    name: str
    limit: float
    displacements: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        where = f"categories.{self.name}"
        lim = _number(f"{where}.limit", self.limit)
        if lim <= 0:
            raise ConfigError(f"{where}.limit must be > 0 px, got {self.limit!r}")
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
class EvaluateConfig:
    """The evaluation protocol (the ``[evaluate]`` table of ``pipelines/paper.toml``).

    Parameters
    ----------
    seed : int
        Root of every experiment's seed.
    experiments : int
        Repetitions per parametrization, strategy and mode (the paper: 50).
    strategies : tuple of str
        Adapt strategies compared (each must be known to the adapt stage).
    baseline : str
        The strategy the others are tested against (one of ``strategies``).
    modes : tuple of str
        Reaching modes (:data:`kbcli.sim.MODES`).
    family : str
        Transform family (:data:`kbcli.core.transforms.FAMILIES`).
    max_steps : int
        Observations per experiment (T).
    thresholds : tuple of float
        Error thresholds (px) for the observations-to-threshold table and the rank-sum tests.
    example : str
        Category whose first parametrization's first run, per mode and strategy, keeps its
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
    adapt : mapping
        Further adapt-stage options for every experiment (posterior, resolution, ...); the protocol
        itself sets ``strategy``, ``mode``, ``max_steps``, ``family`` and ``reach_noise``.
    """

    seed: int = 2013
    experiments: int = 50
    strategies: tuple[str, ...] = DEFAULT_STRATEGIES
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
    adapt: Any = field(default_factory=dict)

    def __post_init__(self) -> None:
        _whole("seed", self.seed, 0)
        _whole("experiments", self.experiments, 1)
        _whole("max_steps", self.max_steps, 1)
        names = transforms.check_family(self.family)
        object.__setattr__(self, "strategies", _names("strategies", self.strategies))
        object.__setattr__(self, "modes", _names("modes", self.modes))
        for m in self.modes:
            if m not in MODES:
                raise ConfigError(f"unknown mode {m!r}; valid: {', '.join(MODES)}")
        known = known_strategies()
        for s in self.strategies:
            if s not in known:
                raise ConfigError(f"unknown strategy {s!r}; valid: {', '.join(known)}")
        if self.baseline not in self.strategies:
            raise ConfigError(
                f"baseline {self.baseline!r} must be one of strategies ({', '.join(self.strategies)})"
            )
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
                shift = math.hypot(*row[-2:])
                if shift > c.limit + 1e-9:
                    raise ConfigError(
                        f"categories.{c.name}: displacement {list(row)} is {shift:.2f} px, "
                        f"beyond the category's limit of {c.limit:g} px"
                    )
        object.__setattr__(self, "categories", cats)
        if self.example not in {c.name for c in cats}:
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
        if not isinstance(self.adapt, (dict, MappingProxyType)):
            raise ConfigError("adapt must be a table of adapt-stage options")
        fixed = sorted(set(self.adapt) & set(PER_EXPERIMENT))
        if fixed:
            raise ConfigError(
                f"adapt.{fixed[0]} is set per experiment by the protocol: use strategies, modes, "
                "max_steps, family, reach_noise and arm in [evaluate] instead"
            )
        object.__setattr__(self, "adapt", MappingProxyType(dict(self.adapt)))
        for s in self.strategies:  # let the adapt stage check its own options
            for m in self.modes:
                adapt_config(self, s, m)

    @property
    def n_params(self) -> int:
        return len(transforms.FAMILIES[self.family])

    def __reduce__(self):  # the read-only mappings do not pickle; the dict form does
        return (EvaluateConfig.from_dict, (self.to_dict(),))

    def to_dict(self) -> dict:
        return {
            "seed": self.seed,
            "experiments": self.experiments,
            "strategies": list(self.strategies),
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
            "adapt": dict(self.adapt),
        }

    @classmethod
    def from_dict(cls, d: dict) -> EvaluateConfig:
        """Build from the ``[evaluate]`` table; unknown keys are rejected at every level.

        ``categories`` is a table of ``name = {limit = ..., displacements = [[...], ...]}``, kept in
        file order.
        """
        if not isinstance(d, dict):
            raise ConfigError("[evaluate] must be a table")
        check_known(cls, d, "evaluate")
        d = dict(d)
        for k in ("strategies", "modes", "thresholds", "snapshot_steps"):
            if k in d:
                if isinstance(d[k], (str, bytes)) or not isinstance(d[k], (list, tuple)):
                    raise ConfigError(f"{k} must be a list, got {d[k]!r}")
                d[k] = tuple(d[k])
        if "categories" in d:
            cats = d["categories"]
            if not isinstance(cats, dict):
                raise ConfigError("categories must be a table of name = {limit, displacements}")
            out = []
            for name, table in cats.items():
                if not isinstance(table, dict):
                    raise ConfigError(f"categories.{name} must be a table with limit and displacements")
                extra = sorted(set(table) - {"limit", "displacements"})
                if extra or "limit" not in table or "displacements" not in table:
                    raise ConfigError(
                        f"categories.{name} must have exactly limit and displacements"
                        + (f" (unknown: {', '.join(extra)})" if extra else "")
                    )
                out.append(Category(name=name, limit=table["limit"],
                                    displacements=tuple(tuple(r) for r in table["displacements"])))
            d["categories"] = tuple(out)
        return cls(**d)

    def with_overrides(self, *, experiments: int | None = None, mode: str | None = None) -> EvaluateConfig:
        """The config with ``--experiments`` and ``--mode`` applied (validated)."""
        cfg = self
        if experiments is not None:
            cfg = replace(cfg, experiments=experiments)
        if mode is not None:
            if mode not in MODES:
                raise ConfigError(f"unknown mode {mode!r}; valid: {', '.join(MODES)}")
            if mode not in cfg.modes:
                raise ConfigError(f"mode {mode!r} is not in the config's modes ({', '.join(cfg.modes)})")
            cfg = replace(cfg, modes=(mode,))
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


def adapt_config(cfg: EvaluateConfig, strategy: str, mode: str):
    """The adapt stage's config for one experiment (None when that stage is not available)."""
    adapt = _adapt_stage()
    if adapt is None:
        return None
    values = {**cfg.adapt, "strategy": strategy, "mode": mode, "max_steps": cfg.max_steps,
              "family": cfg.family, "reach_noise": cfg.reach_noise[mode],
              "arm": dict(cfg.arm[mode])}
    return adapt.AdaptConfig.from_dict(values)


# -- planning -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task:
    """One experiment: what a worker needs to run it (picklable, immutable).

    The seed is stored as the (entropy, spawn_key) of its ``SeedSequence`` child, not as the object:
    spawning from a ``SeedSequence`` mutates it, so a shared object would seed a rerun differently.
    """

    row: int
    seed_index: int
    mode: str
    category: str
    param_index: int
    params: tuple[float, ...]
    strategy: str
    rep: int
    entropy: int
    spawn_key: tuple[int, ...]
    example: bool

    @property
    def seed(self) -> np.random.SeedSequence:
        """A fresh ``SeedSequence`` for this experiment (child ``seed_index`` of the root)."""
        return np.random.SeedSequence(self.entropy, spawn_key=self.spawn_key)


def plan(cfg: EvaluateConfig) -> list[Task]:
    """The experiments of ``cfg`` in artifact row order (mode, category, parametrization, strategy,
    repetition), each with its seed.

    The seed is child ``seed_index`` of ``SeedSequence(cfg.seed).spawn(N)``, ``seed_index`` being the
    experiment's position in the canonical grid over all :data:`kbcli.sim.MODES`, so an ideal-mode
    experiment gets the same seed whether or not dynamics mode is evaluated too.
    """
    n_params = sum(len(c.displacements) for c in cfg.categories)
    per_mode = n_params * len(cfg.strategies) * cfg.experiments
    children = np.random.SeedSequence(cfg.seed).spawn(per_mode * len(MODES))
    tasks: list[Task] = []
    for mode in cfg.modes:
        canon = MODES.index(mode) * per_mode
        for cat in cfg.categories:
            for p, params in enumerate(cat.displacements):
                for strategy in cfg.strategies:
                    for rep in range(cfg.experiments):
                        tasks.append(Task(
                            row=len(tasks), seed_index=canon, mode=mode, category=cat.name,
                            param_index=p, params=params, strategy=strategy, rep=rep,
                            entropy=children[canon].entropy,
                            spawn_key=tuple(children[canon].spawn_key),
                            example=cat.name == cfg.example and p == 0 and rep == 0,
                        ))
                        canon += 1
    return tasks


def context(cfg: EvaluateConfig, model_art: Artifact, experiment: str = EXPERIMENT) -> dict:
    """What every worker shares: the model artifact, the adapt options and the experiment's name."""
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
    }


def run_experiment(state: dict, task: Task) -> dict[str, np.ndarray]:
    """Run one experiment; returns its per-step arrays (padded to ``max_steps``), its wall time
    per step, and (for the example runs only) everything else it returned (posterior snapshots)."""
    cfg: EvaluateConfig = state["cfg"]
    acfg = adapt_config(cfg, task.strategy, task.mode)
    rng = np.random.default_rng(task.seed)
    out = state["experiment"](acfg, state["model"], state["keyboard"],
                              np.asarray(task.params, float), rng=rng,
                              table=_table(state, acfg),
                              snapshot_steps=cfg.snapshot_steps if task.example else ())
    mean = getattr(acfg, "estimator", "mean") == "mean" and "means" in out
    if mean:  # "errors" are those of the posterior mean: keep the estimate they measure
        out = {**out, "estimates": out["means"]}
    return _normalise(out, cfg.max_steps, cfg.n_params, keep_extra=task.example)


def _table(state: dict, acfg):
    """The model raster for ``acfg``, built once per process and shared by every experiment that
    rasterises the same way (it depends on the robot's settings, not on the strategy)."""
    adapt = _adapt_stage()
    if acfg is None or adapt is None:
        return None
    key = replace(acfg.adapter_config(), strategy="random")
    if key not in state["tables"]:
        state["tables"][key] = adapt.build_shared_table(acfg, state["model"])
    return state["tables"][key]


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
    shapes = {"errors": (), "entropy": (), "estimates": (n_params,), "actions": (2,), "classes": (),
              "angle_errors": ()}
    for k in STEP_KEYS:
        if k in out:
            a = np.asarray(out[k])
            a = a.astype(np.int64) if k == "classes" else a.astype(np.float64)
            res[k] = _pad(a.reshape((len(a),) + shapes[k]), steps)
        elif k == "angle_errors":
            res[k] = np.zeros(steps)
        else:
            raise KeyError(f"the experiment returned no {k!r}")
    res[TIME_KEY] = np.asarray(out.get(TIME_KEY, np.zeros(taken)), np.float64)
    if keep_extra:
        extra = {k: np.asarray(v) for k, v in out.items() if k in EXAMPLE_KEYS}
        if extra:
            res["extra"] = extra
    return res


# -- assembling the artifact ----------------------------------------------------------------------
def play_success(keyboard: Keyboard, family: str, true_params: np.ndarray, estimates: np.ndarray,
                 per_key: int = 8) -> np.ndarray:
    """Fraction of touches that play the intended key when aiming with an estimated displacement.

    The robot aims at an even ``per_key x per_key`` grid of points inside each key of its reference
    map, moved by the estimated transform; a touch succeeds when the key under it, on the keyboard at
    its true pose, is the intended one. Without a displacement and with a perfect estimate it is 1.

    Parameters
    ----------
    true_params, estimates : (n, P) ndarrays

    Returns
    -------
    (n,) ndarray
    """
    s = keyboard.config.key_size
    u = (np.arange(per_key) + 0.5) / per_key - 0.5
    gx, gy = np.meshgrid(u * s, u * s)
    offs = np.column_stack([gx.ravel(), gy.ravel()])  # (g, 2)
    centres = keyboard.key_centres()
    pts = (centres[:, None, :] + offs[None]).reshape(-1, 2)  # (K * g, 2)
    intended = np.repeat(np.arange(keyboard.n_keys), len(offs))
    est = np.asarray(estimates, float).reshape(-1, len(transforms.FAMILIES[family]))
    true = np.asarray(true_params, float).reshape(est.shape)
    out = np.empty(len(est))
    chunk = max(1, 2_000_000 // len(pts))
    for lo in range(0, len(est), chunk):
        aim = transforms.apply_many(family, est[lo:lo + chunk], pts, keyboard.centre)
        ref_pts = transforms.inverse_many(family, true[lo:lo + chunk], aim, keyboard.centre)
        keys = keyboard.key_at(ref_pts.reshape(-1, 2)).reshape(len(aim), -1)
        out[lo:lo + chunk] = np.mean(keys == intended[None], axis=1)
    return out


def _stack(results: dict[int, dict], n: int, key: str) -> np.ndarray:
    return np.stack([results[i][key] for i in range(n)])


def assemble(cfg: EvaluateConfig, tasks: list[Task], results: dict[int, dict],
             model_art: Artifact, keyboard: Keyboard) -> Artifact:
    """The ``evaluation`` artifact from every experiment's result (``results[row]``).

    Layout (``M``/``C``/``S`` are mode, category and strategy names; ``k`` thresholds; ``T`` steps):

    - ``experiments/``: the experiment table: ``mode``, ``category``, ``strategy`` (n,) str;
      ``param_index``, ``rep``, ``seed_index``, ``steps_taken`` (n,) int; ``params`` (n, P);
      ``play_unadapted``, ``play_adapted`` (n,): playing success without and with the final estimate;
    - ``steps/``: ``errors``, ``entropy``, ``angle_errors`` (n, T); ``estimates`` (n, T, P);
      ``actions`` (n, T, 2); ``classes`` (n, T);
    - ``thresholds`` (k,) px;
    - ``curves/M/C/S/``: ``rmse``, ``mean``, ``std``, ``q25``, ``median``, ``q75`` (T,) of the error;
      ``rmse_by_param`` (G, T); ``entropy_mean``, ``entropy_q25``, ``entropy_median``,
      ``entropy_q75`` (T,); ``samples_to_threshold`` (n_MCS, k); ``median_samples``, ``reached`` (k,);
      ``play_adapted`` (n_MCS,);
    - ``pvalues/M/C/S/``: ``pvalue`` and ``statistic`` (k,) of the rank-sum test of S against the
      baseline (for each S other than the baseline);
    - ``entropy/M/S/``: ``mean``, ``q25``, ``median``, ``q75`` (T,) over every category (Fig. 6);
    - ``examples/M/S/``: what the example run returned beyond its per-step arrays (posterior
      snapshots, Fig. 5), and ``row`` (its experiment row).
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
    strategy = np.array([t.strategy for t in tasks])
    param_index = np.array([t.param_index for t in tasks], np.int64)
    final = steps["estimates"][:, -1, :]
    play_unadapted = play_success(keyboard, cfg.family, params, np.zeros_like(params))
    play_adapted = play_success(keyboard, cfg.family, params, np.nan_to_num(final, nan=0.0))
    thr = np.asarray(cfg.thresholds, float)

    curves: dict[str, Any] = {}
    pvalues: dict[str, Any] = {}
    entropy: dict[str, Any] = {}
    examples: dict[str, Any] = {}
    for m in cfg.modes:
        curves[m], pvalues[m], entropy[m], examples[m] = {}, {}, {}, {}
        for s in cfg.strategies:
            sel = (mode == m) & (strategy == s)
            entropy[m][s] = stats.entropy_curves(steps["entropy"][sel])
        for c in cfg.categories:
            curves[m][c.name], pvalues[m][c.name] = {}, {}
            counts = {}
            for s in cfg.strategies:
                sel = (mode == m) & (category == c.name) & (strategy == s)
                e = steps["errors"][sel]
                cur = stats.curves(e, param_index[sel])
                cur["rmse_by_param"] = cur.pop("rmse_by_group")
                ent = stats.entropy_curves(steps["entropy"][sel])
                cur.update({f"entropy_{k}": v for k, v in ent.items()})
                counts[s] = stats.samples_to_threshold(e, thr)
                cur["samples_to_threshold"] = counts[s]
                cur["median_samples"] = stats.median_samples(counts[s], T)
                cur["reached"] = stats.reached(counts[s], T)
                cur["play_adapted"] = play_adapted[sel]
                curves[m][c.name][s] = cur
            for s in cfg.strategies:
                if s == cfg.baseline:
                    continue
                stat, p = stats.ranksum_pvalues(counts[s], counts[cfg.baseline])
                pvalues[m][c.name][s] = {"statistic": stat, "pvalue": p}
        for t in tasks:
            if t.example and t.mode == m:
                extra = results[t.row].get("extra", {})
                examples[m][t.strategy] = {"row": np.int64(t.row), **extra}

    # Wall times (TIME_KEY) stay out of the artifact: they differ between identical runs.
    data = {
        "experiments": {
            "mode": mode, "category": category, "strategy": strategy, "param_index": param_index,
            "rep": np.array([t.rep for t in tasks], np.int64),
            "seed_index": np.array([t.seed_index for t in tasks], np.int64),
            "steps_taken": np.array([results[i]["steps_taken"] for i in range(n)], np.int64),
            "params": params, "play_unadapted": play_unadapted, "play_adapted": play_adapted,
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
        "strategies": list(cfg.strategies),
        "baseline": cfg.baseline,
        "max_steps": T,
        "model_strategy": model_art.config.get("strategy"),
    }
    return Artifact(kind="evaluation", config=cfg.to_dict(), seed=cfg.seed, data=data, attrs=attrs,
                    inputs={"model": ref(model_art)})


def timing(results: dict[int, dict]) -> np.ndarray:
    """All per-step wall times (ms) of ``results``, for the CLI's summary."""
    parts = [np.ravel(r[TIME_KEY]) for r in results.values() if TIME_KEY in r]
    return np.concatenate(parts) if parts else np.zeros(0)


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
