"""The adapter's config: how the robot adapts (robot side only), and the settings it resolves
with the model (robust blur grid, learning rate, redundancy radius; paper Sect. III-D/E).

See :class:`AdapterConfig` for every option; :mod:`kbcli.core.adaptation.adapter` for how they are used.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import AfterValidator, Field, Strict, model_validator

from kbcli.core.adaptation.estimators import ESTIMATORS
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
from kbcli.core.config import (
    Config,
    Flag,
    Name,
    NonNegative,
    Positive,
    Rate,
    Whole,
    between,
)
from kbcli.core.instrument.transforms import FAMILIES

#: Upper bounds of the counts a user can type (a cost the run would pay at every touch).
MAX_CANDIDATES = 100_000
MAX_HYPOTHESES = 1_000_000
MAX_KDE_SAMPLES = 1_000_000

#: Default softening (px) of a learned model's map (``AdapterConfig.model_blur``).
LEARNED_BLUR = 1.0
#: Radius (px) within which touches count as one spot, as a multiple of the model's own
#: cross-validated boundary error (``AdapterConfig.redundancy_radius`` None).
REDUNDANCY_FACTOR = 4.0
#: A weak model's boundaries can sit further off than the default blur grid reaches: the robust
#: posterior then also weighs a blur of this many times the model's own cross-validated boundary
#: error (``AdapterConfig.robust_blurs`` None, translation family), when that exceeds the grid.
WIDE_BLUR_FACTOR = 2.0
#: Largest blur (px) any blur option accepts: a key's width. A map blurred further says nothing,
#: and its Gaussian kernel would outgrow memory (a 1000 px blur asked for 35 GiB).
MAX_BLUR = 50.0


def _blur(v: float) -> float:
    if v > MAX_BLUR:
        raise ValueError(f"must be a blur in [0, {MAX_BLUR:g}] px (<= {MAX_BLUR:g}: a key's width), "
                         f"got {v!r}")
    return v


def _angle(v: float) -> float:
    if v > 180:
        raise ValueError(f"must be in [0, 180] degrees, got {v!r}")
    return v


def _registered(registry) -> AfterValidator:
    """A field validator: the name must be registered in ``registry`` (ConfigError lists them)."""
    return AfterValidator(registry.check)


#: A blur, px: a finite number in [0, MAX_BLUR].
Blur = Annotated[float, Strict(), Field(ge=0, allow_inf_nan=False), AfterValidator(_blur)]
#: A probability in (0, 1].
Fraction = Annotated[float, Strict(), Field(gt=0, le=1, allow_inf_nan=False)]
#: A mixing weight in [0, 1).
Floor = Annotated[float, Strict(), Field(ge=0, lt=1, allow_inf_nan=False)]


def _choice(*names: str) -> AfterValidator:
    """A field validator: the value must be one of ``names``."""
    def check(v: str) -> str:
        if v not in names:
            raise ValueError(f"must be one of {', '.join(names)}, got {v!r}")
        return v
    return AfterValidator(check)


#: How the KDE posterior gets its samples of p(action | sound) (``AdapterConfig.kde_draw``).
KDE_DRAWS = ("shared", "fresh")
#: What draws those samples (``AdapterConfig.kde_sampler``).
KDE_SAMPLERS = ("model", "raster")
#: What silence's samples of p(action | silence) cover (``AdapterConfig.kde_beyond``).
KDE_BEYOND = ("silent", "unknown")
#: How ties of the maximum-likelihood cell are broken (``AdapterConfig.ml_ties``).
ML_TIES = ("first", "random")
#: Where the ``random`` strategy's actions come from (``AdapterConfig.random_actions``).
RANDOM_ACTIONS = ("area", "model")


class AdapterConfig(Config):
    """How the robot adapts (robot side only: nothing about the simulated world).

    Parameters
    ----------
    strategy : str
        A name in :data:`kbcli.core.adaptation.strategies.STRATEGIES` (random, active, infogain).
    posterior : str
        ``likelihood`` (the model's classifier) or ``kde`` (the paper's Eq. 7 from samples).
    family : str
        Transform family (translation or rigid).
    resolution : float
        Hypothesis grid step, px.
    prior_halfwidth : float
        The prior box of dx and dy, +-px.
    max_angle, angle_resolution : float
        Prior range (+-deg) and grid step (deg) of the angle (rigid family).
    outlier : float
        eps of the outlier floor (``p_eps = (1 - eps) p + eps / C``; the KDE mixes eps of the prior).
    blur : float
        Std (px) of the landing scatter the robot cannot see (0 when it knows where it landed).
    robust : bool
        Marginalise the model's error (boundary blur ``robust_blurs`` and outlier rate
        ``robust_outliers``, uniform prior) online (:mod:`kbcli.core.adaptation.posteriors.likelihood.robust`); likelihood posterior
        only. False: the plain posterior, which reads the map as the truth.
    robust_blurs : tuple of float or None
        Boundary blurs (px) the robust posterior weighs; None: 0, 1, 2.5 and 5 px (translation),
        and ``WIDE_BLUR_FACTOR`` (2) times the model's own cross-validated boundary error when that
        is wider (a weak model: its edges can sit further off than 5 px; :func:`robust_blurs`);
        0 px only (rigid, whose grid is 41 times larger: outliers only).
    robust_outliers : tuple of float or None
        Outlier rates the robust posterior weighs; None: 0.001, 0.02 and 0.1 (translation),
        0.001 and 0.05 (rigid).
    robust_eta : float or None
        Learning rate in (0, 1] the robust posterior tempers the log-likelihood with after 30
        touches (a coarsened posterior: after ``n`` touches the rate is ``alpha / (alpha + n)``,
        ``alpha = 30 eta / (1 - eta)``, so the first touches count almost in full;
        :mod:`kbcli.core.adaptation.posteriors.likelihood.robust`). None: resolved with the model,
        ``min(1, (TEMPER_PX / b)^2)`` for its own cross-validated boundary error ``b`` px
        (capped at 25 px: :func:`own_boundary_error`; ``TEMPER_PX`` 1.5; 1 for the exact model or
        a model without an estimate;
        :func:`learning_rate`). 1: untempered.
    redundancy_radius : float or None
        A learned model's errors are not independent from touch to touch: where its boundary is
        wrong, every touch there is wrong the same way. With ``robust``, touches within this
        radius (px) of earlier ones count as one spot: the ``k``-th touch at a spot enters the
        posterior with weight ``1 / k`` (a coarsened likelihood), and infogain divides a
        candidate's expected gain by the same ``k``, so it seeks new evidence instead of asking one
        doubtful spot again. None: ``REDUNDANCY_FACTOR`` (4) times the model's own cross-validated
        boundary error (its ``reliability``, capped at 25 px: :func:`own_boundary_error`; 0, no
        discount, for the exact model or a model that has no estimate). 0: off.
    model_blur : float or None
        Override: softening (px, a Gaussian) of the model's map. With ``robust``, the blur is fixed
        to it instead of being learned. Without, None means ``LEARNED_BLUR`` (1 px) for a learned
        model and 0 for the exact one. A learned model's probabilities are read as calibrated, but its edges
        can sit a pixel or two off: touches that contradict them then pull the posterior off the
        truth, and the estimate drifts as evidence piles up (benchmarked: a model with 1.1 px
        boundary error drifted to 2.1 px RMSE at step 40 unsoftened, 0.28 px with 1 px).
    cell_average : bool
        Read the likelihood of a grid cell averaged over the cell (a Gaussian of the cell's spread,
        :func:`kbcli.core.adaptation.posteriors.likelihood.term.cell_sigma`) rather than at its centre; matters for the rigid
        family, where an angle step moves far keys by more than a raster cell.
    raster_step : float or None
        Cell of the model raster, px (None: the grid resolution; half of it for the exact model
        with the rigid family, whose cell-averaged likelihood needs a finer map).
    candidates : int
        Candidate actions per decision (active, paper-active, infogain).
    hypotheses : int
        Posterior cells on which infogain evaluates its candidates.
    active_keep, active_hypotheses : int
        Most confusing candidates kept by ``active`` and ``paper-active``, and the cells
        ``active``'s simulated updates use (``paper-active`` updates the whole posterior).
    random_actions : str
        Where the ``random`` strategy touches: ``area`` (uniform over the working area, the
        historical baseline) or ``model`` (a sound uniform over the model's sounds, then an action
        from p(action | sound), drawn as ``kde_sampler`` says: the paper's "random selection of
        samples", the samples the paper's other strategy draws its candidates from).
    kde_samples : int
        N, actions drawn from p(action | sound) per KDE term (kde posterior; Algorithm 2, line 3).
    kde_draw : str
        ``shared``: each class's N actions are drawn once and reused by every touch (and, in the
        evaluation, by every experiment of a process; :class:`kbcli.core.adaptation.posteriors.kde.samples.ActionSamples`).
        ``fresh``: Algorithm 2 as written, N new actions for every observation, from the
        adapter's own generator (so from the experiment's seed;
        :class:`kbcli.core.adaptation.posteriors.kde.samples.FreshSamples`).
    simulate_draw : str or None
        How ``paper-active``'s simulated touches get their KDE samples (kde posterior). None: as
        ``kde_draw`` says (the paper's text: with ``fresh``, Algorithm 2 on every simulated sound,
        N new samples and a bandwidth for each). ``shared``: each sound's N samples (and
        bandwidth) drawn once per adaptation, from the adapter's own generator by
        ``kde_sampler``, and reused by every simulated touch, while the real touches still draw as
        ``kde_draw`` says: the same planner without its sampling, about a third of a touch's time
        (``kbcli bench speed``). ``fresh``: new samples for every simulated touch. Recorded in
        an artifact's config only when set.
    kde_sampler : str
        What draws fresh samples of p(action | sound), and the ``model`` actions of ``random``
        and ``paper-active``: ``model`` (``model.sample_actions``, the model's own rejection
        sampler: exact, ~250 ms per 10,000 draws of the default learned model) or ``raster`` (the
        model rasterised at ``resolution``: a cell drawn with weight p(sound | cell), then a point
        uniform in it; ~1 ms; :class:`kbcli.core.model.sampling.RasterSampler`). Silence is drawn
        like any sound over the working area the model was learned on; beyond it as
        ``kde_beyond`` says.
    kde_beyond : str
        What the KDE posterior knows of the pad beyond the working area (where the paper is
        silent): ``silent`` (it is silent, as the likelihood table reads it: silence's samples
        cover a ring beyond the working area as wide as the hypotheses can move a touch back,
        :class:`kbcli.core.adaptation.posteriors.kde.samples.SilentBeyond`, so a silent touch never rules out a
        hypothesis because the samples stop at the area's edge) or ``unknown`` (no samples there:
        without a floor such a hypothesis is ruled out; before issue 39 the only behaviour).
    kde_floor : float or None
        Weight of the uniform floor mixed into each KDE term (``(1 - w) KDE + w / |prior|``);
        0: none (Eq. 7 as written: a hypothesis that no sample supports is ruled out by that
        touch); None: ``outlier`` (the historical 1e-3).
    kde_bandwidth : float or None
        Kernel std, px; None: Scott's rule (see :mod:`kbcli.core.adaptation.posteriors.posterior`).
    estimator : str
        ``mean`` or ``ml``: which estimate :meth:`Adapter.estimate` returns.
    ml_ties : str
        Which of several equally probable cells is the maximum-likelihood one: ``first`` (the
        lowest grid index: the corner of the prior box on a flat posterior, historical) or
        ``random`` (uniformly among the tied cells, seeded from the adapter's generator: no
        positional bias).
    stop_ml : float or None
        The paper's rule: stop when the most probable cell holds at least this probability.
    stop_mass, stop_radius, stop_angle : float
        Ours: stop when ``stop_mass`` of the posterior lies within ``stop_radius`` px (and
        ``stop_angle`` deg) of the estimate; ``stop_mass`` 0 (or None): ours is off (the paper's alone).
    max_memory_mb : float
        Refuse hypothesis grids (and model rasters) that would need more working memory.
    repair : bool
        Adapt with the model repaired by the touches (:mod:`kbcli.core.adaptation.repair`): a joint belief
        over the shift and the model's map, each hypothesis scored by the map its own touches
        repaired, the model's local uncertainty in place of one global blur, and infogain planning
        under the same belief (the translation family and the likelihood posterior, robust). Off
        by default; recorded in an artifact's config only when on.
    repair_kernel : float or None
        Width (px) of the kernel a touch's (and a training sample's) sound is counted with on the
        repaired map (None: ``kbcli.core.adaptation.repair.DEFAULT_KERNEL``, 10 px).
    repair_scale : float or None
        Scale ``s`` of the model's local blur ``s d(x)``, ``d`` the distance to its nearest
        training sample (None: ``DEFAULT_SCALE``, 0.6, about ``1 / sqrt(3)``).
    repair_blur : float or None
        Blur (px) under the local one everywhere (None: the model's own landing scatter,
        ``reach_sd_``).
    """

    what: ClassVar[str] = "adapt"

    strategy: Annotated[Name, _registered(STRATEGIES)] = "infogain"
    posterior: Annotated[Name, _registered(POSTERIORS)] = "likelihood"
    family: Annotated[Name, _registered(FAMILIES)] = "translation"
    resolution: Positive = 0.5
    prior_halfwidth: Positive = 45.0
    max_angle: Annotated[NonNegative, AfterValidator(_angle)] = 5.0
    angle_resolution: Positive = 0.25
    outlier: Rate = 1e-3
    blur: Blur = 0.0
    robust: Flag = True
    robust_blurs: Annotated[tuple[Blur, ...], Field(min_length=1)] | None = None
    robust_outliers: Annotated[tuple[Rate, ...], Field(min_length=1)] | None = None
    robust_eta: Fraction | None = None
    redundancy_radius: NonNegative | None = None
    model_blur: Blur | None = None
    cell_average: Flag = True
    raster_step: Positive | None = None
    candidates: between(Whole, 1, MAX_CANDIDATES) = 256
    hypotheses: between(Whole, 1, MAX_HYPOTHESES) = 512
    active_keep: between(Whole, 1, MAX_CANDIDATES) = 8
    active_hypotheses: between(Whole, 1, MAX_HYPOTHESES) = 2048
    random_actions: Annotated[Name, _choice(*RANDOM_ACTIONS)] = "area"
    kde_samples: between(Whole, 10, MAX_KDE_SAMPLES) = 10000
    kde_draw: Annotated[Name, _choice(*KDE_DRAWS)] = "shared"
    # written to artifacts only when set (None is the behaviour of every artifact stored before
    # the option existed: their configs read back to the same dict)
    simulate_draw: Annotated[Annotated[Name, _choice(*KDE_DRAWS)] | None,
                             Field(exclude_if=lambda v: v is None)] = None
    kde_sampler: Annotated[Name, _choice(*KDE_SAMPLERS)] = "model"
    kde_beyond: Annotated[Name, _choice(*KDE_BEYOND)] = "silent"
    kde_floor: Floor | None = None
    kde_bandwidth: Positive | None = None
    estimator: Annotated[Name, _registered(ESTIMATORS)] = "mean"
    ml_ties: Annotated[Name, _choice(*ML_TIES)] = "first"
    stop_ml: Positive | None = None
    stop_mass: Annotated[float, Strict(), Field(ge=0, le=1, allow_inf_nan=False)] | None = 0.95
    stop_radius: Positive = 1.0
    stop_angle: Positive = 0.5
    max_memory_mb: Positive = 2048.0
    # the repair's options are written to artifacts only when set: configs stored before they
    # existed read back to the same dict
    repair: Annotated[Flag, Field(exclude_if=lambda v: not v)] = False
    repair_kernel: Annotated[Positive | None, Field(exclude_if=lambda v: v is None)] = None
    repair_scale: Annotated[NonNegative | None, Field(exclude_if=lambda v: v is None)] = None
    repair_blur: Annotated[Blur | None, Field(exclude_if=lambda v: v is None)] = None

    @model_validator(mode="before")
    @classmethod
    def _family_outliers(cls, data: Any) -> Any:
        """``robust_outliers`` None: the family's default (fewer for a rotating, larger grid)."""
        if isinstance(data, dict) and data.get("robust_outliers") is None:
            fam = data.get("family", "translation")
            rotates = fam in FAMILIES and FAMILIES.get(fam).rotates
            data = {**data, "robust_outliers": RIGID_OUTLIERS if rotates else DEFAULT_OUTLIERS}
        return data

    @model_validator(mode="after")
    def _repairable(self) -> AdapterConfig:
        """``repair`` needs a translation grid and the robust likelihood posterior."""
        if self.repair and (FAMILIES.get(self.family).rotates or not self.is_robust):
            raise ValueError("repair works with the translation family and the robust likelihood "
                             f"posterior (got family {self.family!r}, posterior "
                             f"{self.posterior!r}, robust = {str(self.robust).lower()})")
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


    @property
    def grid_cells(self) -> int:
        return grid_bytes(self.family, self.prior_halfwidth, self.resolution, self.max_angle,
                          self.angle_resolution)[0]

    @property
    def kde_eps(self) -> float:
        """The KDE term's floor weight: ``kde_floor``, or ``outlier`` when it is None."""
        return float(self.outlier if self.kde_floor is None else self.kde_floor)

    @property
    def is_robust(self) -> bool:
        """Whether the robust posterior is used (asked for, with the likelihood posterior)."""
        return self.robust and POSTERIORS.get(self.posterior).robust

    def nuisance(self, model=None) -> Nuisance:
        """The blurs (:func:`robust_blurs` for ``model``) and outlier rates the robust posterior
        marginalises."""
        return Nuisance.build(robust_blurs(model, self), self.robust_outliers)

def own_boundary_error(reliability: dict | None) -> float | None:
    """The boundary error (px) a model's own estimate (its ``reliability`` table) gives the robust
    posterior: the cross-validated one, at most ``MAX_BLUR / WIDE_BLUR_FACTOR`` (25 px; a model
    that could not place its edges at all says inf), or None when it has no estimate. Every
    setting resolved from it (blur grid, learning rate, redundancy radius) uses this value."""
    berr = reliability.get("boundary_error") if isinstance(reliability, dict) else None
    if berr is None or np.isnan(berr):
        return None
    return min(float(berr), MAX_BLUR / WIDE_BLUR_FACTOR)


def _boundary_error(model) -> float | None:
    return own_boundary_error(getattr(model, "reliability_", None))


def robust_blurs(model, cfg: AdapterConfig) -> tuple[float, ...]:
    """The boundary blurs (px) the robust posterior weighs for ``model`` (see
    :class:`AdapterConfig`): ``cfg.model_blur`` alone when set, ``cfg.robust_blurs`` when given,
    else the family's grid, widened for a translation by ``WIDE_BLUR_FACTOR`` times the model's
    own boundary error when that lies beyond it."""
    if cfg.model_blur is not None:
        return (float(cfg.model_blur),)
    if cfg.robust_blurs is not None:
        return tuple(cfg.robust_blurs)
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
    if cfg.robust_eta is not None:
        return float(cfg.robust_eta)
    return temper(_boundary_error(model))


def temper(boundary_error: float | None) -> float:
    """``min(1, (TEMPER_PX / boundary_error)^2)`` (1 for None or 0), rounded to 3 decimals."""
    if boundary_error is None or boundary_error <= TEMPER_PX:
        return 1.0
    return round((TEMPER_PX / float(boundary_error)) ** 2, 3)


def redundancy_radius(model, cfg: AdapterConfig) -> float:
    """The resolved ``cfg.redundancy_radius`` (px) for ``model`` (see :class:`AdapterConfig`)."""
    if cfg.redundancy_radius is not None:
        return float(cfg.redundancy_radius)
    berr = _boundary_error(model)
    return 0.0 if berr is None else REDUNDANCY_FACTOR * berr


def _size(nbytes: float) -> str:
    for unit, scale in (("GB", 2**30), ("MB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes / 1024:.1f} kB"
