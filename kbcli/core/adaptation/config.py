"""The adapter's config: how the robot adapts (robot side only), and the settings it resolves
with the model (robust blur grid, learning rate, redundancy radius; paper Sect. III-D/E).

See :class:`AdapterConfig` for every option; :mod:`kbcli.core.adaptation.adapter` for how they are used.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import AfterValidator, Field, Strict, model_validator

from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.fields import MAX_BLUR, Blur, choice
from kbcli.core.adaptation.grid import grid_bytes
from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.core.adaptation.posteriors.likelihood.robust import (
    DEFAULT_BLURS,
    DEFAULT_OUTLIERS,
    RIGID_BLURS,
    RIGID_OUTLIERS,
    TEMPER_PX,
    Nuisance,
)
from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.core.config import Config, Name, NonNegative, Positive, Rate
from kbcli.core.instrument.transforms import DEFAULT_FAMILY, FAMILIES
from kbcli.core.options import declared, flat_view, for_part, options_of, part_field, route
from kbcli.errors import ConfigError

#: Default softening (px) of a learned model's map (``AdapterConfig.model_blur``).
LEARNED_BLUR = 1.0
#: Radius (px) within which touches count as one spot, as a multiple of the model's own
#: cross-validated boundary error (``redundancy_radius`` None).
REDUNDANCY_FACTOR = 4.0
#: A weak model's boundaries can sit further off than the default blur grid reaches: the robust
#: posterior then also weighs a blur of this many times the model's own cross-validated boundary
#: error (``robust_blurs`` None, translation family), when that exceeds the grid.
WIDE_BLUR_FACTOR = 2.0


def _angle(v: float) -> float:
    if v > 180:
        raise ValueError(f"must be in [0, 180] degrees, got {v!r}")
    return v


#: What draws the samples of p(action | sound) (``AdapterConfig.kde_sampler``).
KDE_SAMPLERS = ("model", "raster")
#: How ties of the maximum-likelihood cell are broken (``AdapterConfig.ml_ties``).
ML_TIES = ("first", "random")

#: The fields of :class:`AdapterConfig` that choose a part and carry its options: slot ->
#: (registry, default part).
SLOTS = {"strategy": (STRATEGIES, "infogain"), "posterior": (POSTERIORS, "likelihood"),
         "estimator": (ESTIMATORS, "mean")}


class AdapterConfig(Config):
    """How the robot adapts (robot side only: nothing about the simulated world).

    The strategy, the posterior and the estimator are parts with options of their own: a name, a
    table ``{name, options...}``, or the part's options given flat beside it
    (``AdapterConfig(posterior="kde", kde_samples=1000)``). An option the chosen part does not take
    is refused by the part.

    Parameters
    ----------
    strategy : Options
        Where to touch next: a part of :data:`kbcli.core.adaptation.strategies.STRATEGIES`.
    posterior : Options
        The kind of posterior: a part of :data:`kbcli.core.adaptation.posteriors.POSTERIORS`
        (``likelihood``, robust or not, ours; ``kde``, the paper's Eq. 7).
    family : str
        Transform family (translation or rigid).
    resolution : float
        Hypothesis grid step, px.
    prior_halfwidth : float
        The prior box of dx and dy, +-px.
    max_angle, angle_resolution : float
        Prior range (+-deg) and grid step (deg) of the angle (a rotating family).
    outlier : float
        eps of the outlier floor (``p_eps = (1 - eps) p + eps / C``; the KDE mixes eps of the prior).
    blur : float
        Std (px) of the landing scatter the robot cannot see (0 when it knows where it landed).
    model_blur : float or None
        Softening (px, a Gaussian) of the model's map, fixed instead of learned with the robust
        posterior. None: ``LEARNED_BLUR`` for a learned model, 0 for the exact one.
    raster_step : float or None
        Cell of the model raster, px (None: the grid resolution; half of it for the exact model
        with a rotating family).
    kde_sampler : str
        What draws fresh samples of p(action | sound): ``model`` (its rejection sampler) or
        ``raster`` (:class:`kbcli.core.model.sampling.RasterSampler`).
    estimator : Options
        Which estimate :meth:`Adapter.estimate` returns: a part of
        :data:`kbcli.core.adaptation.estimators.ESTIMATORS` (``mean`` or ``ml``; written as its
        name when it takes no option).
    ml_ties : str
        Which of equally probable cells is the maximum-likelihood one: ``first`` (the lowest grid
        index) or ``random`` (seeded from the adapter's generator).
    stop_ml : float or None
        The paper's rule: stop when the most probable cell holds at least this probability.
    stop_mass, stop_radius, stop_angle : float
        Ours: stop when ``stop_mass`` of the posterior lies within ``stop_radius`` px (and
        ``stop_angle`` deg) of the estimate; ``stop_mass`` 0 (or None): ours is off.
    max_memory_mb : float
        Refuse hypothesis grids (and model rasters) that would need more working memory.
    """

    what: ClassVar[str] = "adapt"

    strategy: part_field(STRATEGIES, "infogain") = "infogain"
    posterior: part_field(POSTERIORS, "likelihood") = "likelihood"
    family: Annotated[Name, AfterValidator(FAMILIES.check)] = DEFAULT_FAMILY
    resolution: Positive = 0.5
    prior_halfwidth: Positive = 45.0
    max_angle: Annotated[NonNegative, AfterValidator(_angle)] = 5.0
    angle_resolution: Positive = 0.25
    outlier: Rate = 1e-3
    blur: Blur = 0.0
    model_blur: Blur | None = None
    raster_step: Positive | None = None
    kde_sampler: Annotated[Name, choice(*KDE_SAMPLERS)] = "model"
    estimator: part_field(ESTIMATORS, "mean", named=True) = "mean"
    ml_ties: Annotated[Name, choice(*ML_TIES)] = "first"
    stop_ml: Positive | None = None
    stop_mass: Annotated[float, Strict(), Field(ge=0, le=1, allow_inf_nan=False)] | None = 0.95
    stop_radius: Positive = 1.0
    stop_angle: Positive = 0.5
    max_memory_mb: Positive = 2048.0

    @model_validator(mode="before")
    @classmethod
    def _parts(cls, data: Any) -> Any:
        """The parts' options given flat go to the parts (:func:`kbcli.core.options.route`); a
        likelihood posterior's ``robust_outliers`` None is the family's (fewer for a rotating,
        larger grid)."""
        if not isinstance(data, dict):
            return data
        data = route(data, SLOTS, cls.model_fields)
        post = data["posterior"]
        if "robust_outliers" in _declared(POSTERIORS, post["name"]) and \
                post.get("robust_outliers") is None:
            fam = data.get("family", DEFAULT_FAMILY)
            rotates = fam in FAMILIES and FAMILIES.get(fam).rotates
            data["posterior"] = {**post, "robust_outliers": RIGID_OUTLIERS if rotates
                                 else DEFAULT_OUTLIERS}
        return data

    @model_validator(mode="after")
    def _repairable(self) -> AdapterConfig:
        """``repair`` needs a translation grid."""
        if self.repairs and FAMILIES.get(self.family).rotates:
            raise ValueError(f"repair works with the translation family (got family "
                             f"{self.family!r})")
        return self

    @model_validator(mode="after")
    def _fits(self) -> AdapterConfig:
        """The prior holds at least one step, and the grid fits in ``max_memory_mb``."""
        if self.prior_halfwidth < self.resolution:
            raise ValueError("prior_halfwidth must be at least one resolution step")
        cells, need = grid_bytes(self.family, self.prior_halfwidth, self.resolution,
                                 self.max_angle, self.angle_resolution)
        if need > self.max_memory_mb * 2**20:
            raise ValueError(
                f"hypothesis grid of {cells:,} cells would need {_size(need)} of working memory, "
                f"above max_memory_mb = {self.max_memory_mb:g} MB: coarsen the resolution or "
                f"narrow the prior"
            )
        return self

    def replace(self, **changes: Any) -> AdapterConfig:
        """A copy with ``changes`` (own options, a part's name, its options given flat) applied; a
        new part keeps the options of the old one that it takes too."""
        base = self.to_dict()
        for slot in SLOTS:
            if isinstance(changes.get(slot), str):  # a new part: carry over what it takes
                registry = SLOTS[slot][0]
                kept = {k: v for k, v in getattr(self, slot).own().items()
                        if k in _declared(registry, changes[slot])}
                changes = {**changes, slot: {**kept, "name": changes[slot]}}
        return type(self)(**{**base, **changes})

    @classmethod
    def shared(cls, options: Mapping[str, Any]) -> AdapterConfig:
        """A config from options a method shares between its strategies (``options["strategy"]``
        the one to build): the options of strategies that this one does not take left out."""
        strategy = options.get("strategy", SLOTS["strategy"][1])
        name = strategy if isinstance(strategy, str) else dict(strategy)["name"]
        return cls.from_dict(for_part(STRATEGIES, name, options))

    def flat(self) -> dict[str, Any]:
        """Every option in the flat layout (each part by its name, its options beside it)."""
        return flat_view(self.to_dict(), SLOTS)

    def inactive(self) -> dict[str, str]:
        """Options that are set but not read under the others, each with why: the parts' own
        (:meth:`kbcli.core.options.Options.inactive`) and the adapter's (the angle's without a
        rotating family, the radius of ours without it, the ML ties where no ML cell is read)."""
        rotates = FAMILIES.get(self.family).rotates
        out = {**self.posterior.inactive(), **self.strategy.inactive(),
               **self.estimator.inactive()}
        if not rotates:
            out.update({o: "the family does not rotate" for o in ("max_angle",
                                                                   "angle_resolution")})
        if not self.stop_mass:
            out.update({o: "stop_mass = 0" for o in ("stop_radius", "stop_angle")})
        elif not rotates:
            out["stop_angle"] = "the family does not rotate"
        reads_ml = (ESTIMATORS.trait(self.estimator.name, "ties", False)
                    or self.stop_ml is not None
                    or STRATEGIES.trait(self.strategy.name, "paper", False))
        if not reads_ml:
            out["ml_ties"] = (f"no maximum-likelihood cell is read (the estimator is "
                              f"{self.estimator.name}, stop_ml is not set, strategy "
                              f"{self.strategy.name} simulates at none)")
        if self.is_robust and not rotates and "cell_average" in type(self.posterior).model_fields:
            out["cell_average"] = "the robust posterior cell-averages a rotating grid only"
        if not (self.posterior.samples_actions() or self.strategy.samples_actions()):
            out["kde_sampler"] = ('nothing here draws from p(action | sound) (kde_draw = "fresh", '
                                  'random_actions = "model" or paper-active would)')
        if not STRATEGIES.trait(self.strategy.name, "simulates", False):
            out["simulate_draw"] = f"strategy {self.strategy.name} simulates no touch"
        return out

    @property
    def grid_cells(self) -> int:
        return grid_bytes(self.family, self.prior_halfwidth, self.resolution, self.max_angle,
                          self.angle_resolution)[0]

    @property
    def kind(self):
        """The kind of posterior (:class:`kbcli.core.adaptation.posteriors.PosteriorKind`)."""
        return POSTERIORS.get(self.posterior.name)

    @property
    def is_robust(self) -> bool:
        """Whether the robust posterior is used (a kind it applies to, asked for)."""
        return self.kind.robust and bool(getattr(self.posterior, "robust", False))

    @property
    def repairs(self) -> bool:
        """Whether the adaptation repairs the model (the likelihood posterior's ``repair``)."""
        return bool(getattr(self.posterior, "repair", False))

    def nuisance(self, model=None) -> Nuisance:
        """The blurs (:func:`robust_blurs` for ``model``) and outlier rates the robust posterior
        marginalises."""
        return Nuisance.build(robust_blurs(model, self), self.posterior.robust_outliers)


def recorded(robot: Mapping[str, Any]) -> AdapterConfig:
    """A recorded robot config as a config: the nested layout, or the flat one of an older kbcli
    (which recorded every option, the chosen parts' and the others'; the others are dropped)."""
    return AdapterConfig.from_dict(route(dict(robot), SLOTS, AdapterConfig.model_fields,
                                         strict=False))


def shown(robot: Mapping[str, Any], strategies: Iterable[str] | None = None) -> dict[str, Any]:
    """The options of a recorded robot config its method reads, in the flat layout (with
    ``strategies``, a method comparing several: those any of them reads)."""
    cfg = recorded(robot)
    out: dict[str, Any] = {}
    skip: set[str] | None = None
    for s in strategies or (cfg.strategy.name,):
        one = cfg.replace(strategy=s)
        out.update(one.flat())
        inactive = set(one.inactive())
        skip = inactive if skip is None else skip & inactive
    if strategies:
        out.pop("strategy", None)
    return {k: v for k, v in out.items() if k not in (skip or set())}


def refuse_inactive(cfg: AdapterConfig, given: Mapping[str, str] | Iterable[str], where: str,
                    strategies: Iterable[str] | None = None) -> None:
    """ConfigError naming the first option a user set (``given``: names, or a mapping to the
    label the message uses, ``{"robust_eta": "--robust-eta"}``) that the method does not read
    (:meth:`AdapterConfig.inactive`; with ``strategies``, under none of them)."""
    labels = dict(given) if isinstance(given, Mapping) else {o: o for o in given}
    why: dict[str, str] | None = None
    for s in strategies or (cfg.strategy.name,):
        inactive = cfg.replace(strategy=s).inactive()
        why = inactive if why is None else {k: v for k, v in why.items() if k in inactive}
    for option, label in labels.items():
        if option in (why or {}):
            raise ConfigError(f"{where}: {label} does not apply to this method: {why[option]}")


def option_names() -> tuple[str, ...]:
    """Every option an adapter config reads in the flat layout: its own, then each registered
    part's (a plug-in's included), each once."""
    out = dict.fromkeys(AdapterConfig.model_fields)
    for registry, _ in SLOTS.values():
        for name in registry.names():
            out.update(dict.fromkeys(declared(registry, name)))
    return tuple(out)


def option_default(option: str) -> Any:
    """The default of ``option``: the adapter's own, or that of the first part declaring it."""
    if option in AdapterConfig.model_fields:
        return AdapterConfig.model_fields[option].default
    for registry, _ in SLOTS.values():
        for name in registry.names():
            fields = options_of(registry, name).model_fields
            if option in fields:
                return fields[option].default
    raise KeyError(option)


def _declared(registry, name: str) -> tuple[str, ...]:
    return declared(registry, name) if name in registry else ()


def own_boundary_error(reliability: dict | None) -> float | None:
    """The boundary error (px) a model's ``reliability`` table gives the robust posterior: the
    cross-validated one, at most ``MAX_BLUR / WIDE_BLUR_FACTOR``, or None without an estimate."""
    berr = reliability.get("boundary_error") if isinstance(reliability, dict) else None
    if berr is None or np.isnan(berr):
        return None
    return min(float(berr), MAX_BLUR / WIDE_BLUR_FACTOR)


def _boundary_error(model) -> float | None:
    return own_boundary_error(getattr(model, "reliability_", None))


def robust_blurs(model, cfg: AdapterConfig) -> tuple[float, ...]:
    """The boundary blurs (px) the robust posterior weighs for ``model``: ``cfg.model_blur``
    alone when set, ``cfg.robust_blurs`` when given, else the family's grid
    (:func:`blur_grid` for a translation)."""
    if cfg.model_blur is not None:
        return (float(cfg.model_blur),)
    if cfg.posterior.robust_blurs is not None:
        return tuple(cfg.posterior.robust_blurs)
    if FAMILIES.get(cfg.family).rotates:
        return RIGID_BLURS
    return blur_grid(_boundary_error(model))


def blur_grid(boundary_error: float | None) -> tuple[float, ...]:
    """The translation family's default blur grid for a model whose own cross-validated boundary
    error is ``boundary_error`` px (None: no estimate): ``DEFAULT_BLURS``, and
    ``WIDE_BLUR_FACTOR * boundary_error`` (at most ``MAX_BLUR``) when that lies beyond them."""
    wide = WIDE_BLUR_FACTOR * boundary_error if boundary_error is not None else 0.0
    wide = min(wide, MAX_BLUR)
    if wide > max(DEFAULT_BLURS):
        return (*DEFAULT_BLURS, round(wide, 2))
    return DEFAULT_BLURS


def learning_rate(model, cfg: AdapterConfig) -> float:
    """The resolved ``cfg.robust_eta`` for ``model``: ``min(1, (TEMPER_PX / b)^2)`` for its own
    cross-validated boundary error ``b`` px, 1 without an estimate (see :class:`AdapterConfig`)."""
    if cfg.posterior.robust_eta is not None:
        return float(cfg.posterior.robust_eta)
    return temper(_boundary_error(model))


def temper(boundary_error: float | None) -> float:
    """``min(1, (TEMPER_PX / boundary_error)^2)`` (1 for None or 0), rounded to 3 decimals."""
    if boundary_error is None or boundary_error <= TEMPER_PX:
        return 1.0
    return round((TEMPER_PX / float(boundary_error)) ** 2, 3)


def redundancy_radius(model, cfg: AdapterConfig) -> float:
    """The resolved ``cfg.redundancy_radius`` (px) for ``model`` (see :class:`AdapterConfig`)."""
    if cfg.posterior.redundancy_radius is not None:
        return float(cfg.posterior.redundancy_radius)
    berr = _boundary_error(model)
    return 0.0 if berr is None else REDUNDANCY_FACTOR * berr


def _size(nbytes: float) -> str:
    for unit, scale in (("GB", 2**30), ("MB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes / 1024:.1f} kB"
