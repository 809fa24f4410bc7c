"""The adaptation loop of the action space (paper Sect. III-D and III-E), one step at a time.

Each step: the strategy decides an action (:mod:`kbcli.core.strategies`) -> the robot touches
(a callback: the World in simulation, the arm in a closed loop) -> the perceived sound is classified
with the model (``model.classify``: Eq. 2 matching; 0 silence, -1 unknown) -> the posterior is
multiplied by the observation's term (Eq. 7 ``kde`` or the ``likelihood``, Eq. 8; see
:mod:`kbcli.core.posterior`) -> estimates (maximum-likelihood cell and posterior mean), entropy and
the stopping rules are read off.

:class:`Adapter` is the robot's side: it never sees the true pose. It is driven by an ask/tell
loop (the public API, ``from kbcli import Adapter``): ``suggest() -> action``,
``observe(action, heard, felt_position=None)``, then ``estimate()``, ``posterior``, ``entropy()``,
``done()``. :func:`adapt` wraps the same calls into an iterator of :class:`Step` records (the
``adapt``, ``run`` and ``evaluate`` stages), and ``kbcli serve`` drives them from another process.
``propose`` and ``should_stop`` are the older names of ``suggest`` and of the stopping rule.

Choices
-------
- An *unknown* sound (class -1: heard something that matches no known sound) carries no usable
  information about the pose and is skipped (the posterior is unchanged); silence is an observation.
- The robot uses the landed finger position it *feels* (proprioception, ``felt_position``) as the
  point of the observation; ``action`` is where it aimed. When it only knows its aim (no
  ``felt_position``), set ``blur`` to the reach noise: the model raster is blurred by it.
- The model is not trusted blindly (``robust = True``, the default with the likelihood
  posterior): its boundary blur and an outlier rate are unknowns marginalised online on a small
  grid (:mod:`kbcli.core.robust`), so a poor model's wrong edges widen the posterior instead of
  dragging the estimate away, and the strategies plan with the map as blurred as the touches say
  it is. ``model_blur`` (px) fixes the blur instead of learning it (an override). With
  ``robust = False`` the map is read as it is, a learned model's softened by ``model_blur``
  (default 1 px) and floored at ``outlier``: the historical posterior, kept for comparison.
- The first decision on the flat prior is the most expensive (resampling the full grid); later
  ones work on the shrinking support of the posterior.
- The estimate is the posterior mean (``estimator = "mean"``, the RMSE-optimal choice) or the
  maximum-likelihood cell (``"ml"``, the paper's).
- Stopping rules (:meth:`Adapter.should_stop`): the paper's, the probability of the
  maximum-likelihood cell above ``stop_ml`` (off by default: at 0.5 px a well-pinned posterior still
  spreads over a few cells); and ours, the posterior mass within ``stop_radius`` px (and
  ``stop_angle`` degrees) of the estimate at least ``stop_mass``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass

import numpy as np

from kbcli.core import transforms
from kbcli.core.config import check_known
from kbcli.core.estimators import ESTIMATORS
from kbcli.core.model import UNKNOWN, ExactModel
from kbcli.core.posterior import (
    ActionSamples,
    HypothesisGrid,
    LikelihoodTable,
    Posterior,
    cell_sigma,
    grid_bytes,
    kde_term,
    likelihood_term,
)
from kbcli.core.posteriors import POSTERIORS
from kbcli.core.robust import (
    DEFAULT_BLURS,
    DEFAULT_OUTLIERS,
    RIGID_BLURS,
    RIGID_OUTLIERS,
    TEMPER_PX,
    Nuisance,
    RobustPosterior,
    planning_table,
    robust_terms,
)
from kbcli.core.strategies import STRATEGIES, Context, get_strategy
from kbcli.errors import ConfigError, ObservationError

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


def _num(name: str, v: object, *, lo: float = 0.0, strict: bool = True,
         hi: float = math.inf) -> None:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    ok = ok and (v > lo if strict else v >= lo) and v <= hi
    if not ok:
        rel = ">" if strict else ">="
        top = f" and <= {hi:g}" if math.isfinite(hi) else ""
        raise ConfigError(f"{name} must be a finite number {rel} {lo:g}{top}, got {v!r}")


def _int(name: str, v: object, lo: int = 1) -> None:
    if not isinstance(v, int) or isinstance(v, bool) or v < lo:
        raise ConfigError(f"{name} must be a whole number >= {lo}, got {v!r}")


@dataclass(frozen=True, kw_only=True)
class AdapterConfig:
    """How the robot adapts (robot side only: nothing about the simulated world).

    Parameters
    ----------
    strategy : str
        A name in :data:`kbcli.core.strategies.STRATEGIES` (random, active, infogain).
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
        ``robust_outliers``, uniform prior) online (:mod:`kbcli.core.robust`); likelihood posterior
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
        :mod:`kbcli.core.robust`). None: resolved with the model,
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
        :func:`kbcli.core.posterior.cell_sigma`) rather than at its centre; matters for the rigid
        family, where an angle step moves far keys by more than a raster cell.
    raster_step : float or None
        Cell of the model raster, px (None: the grid resolution; half of it for the exact model
        with the rigid family, whose cell-averaged likelihood needs a finer map).
    candidates : int
        Candidate actions per decision (active, infogain).
    hypotheses : int
        Posterior cells on which infogain evaluates its candidates.
    active_keep, active_hypotheses : int
        Most confusing candidates kept by ``active``, and the cells its simulated updates use.
    kde_samples : int
        N, actions drawn from p(action | sound) per sound class, once (kde posterior; see
        :class:`kbcli.core.posterior.ActionSamples`).
    kde_bandwidth : float or None
        Kernel std, px; None: Scott's rule (see :mod:`kbcli.core.posterior`).
    estimator : str
        ``mean`` or ``ml``: which estimate :meth:`Adapter.estimate` returns.
    stop_ml : float or None
        The paper's rule: stop when the most probable cell holds at least this probability.
    stop_mass, stop_radius, stop_angle : float
        Ours: stop when ``stop_mass`` of the posterior lies within ``stop_radius`` px (and
        ``stop_angle`` deg) of the estimate.
    max_memory_mb : float
        Refuse hypothesis grids (and model rasters) that would need more working memory.
    """

    strategy: str = "infogain"
    posterior: str = "likelihood"
    family: str = "translation"
    resolution: float = 0.5
    prior_halfwidth: float = 45.0
    max_angle: float = 5.0
    angle_resolution: float = 0.25
    outlier: float = 1e-3
    blur: float = 0.0
    robust: bool = True
    robust_blurs: tuple[float, ...] | None = None
    robust_outliers: tuple[float, ...] | None = None
    robust_eta: float | None = None
    redundancy_radius: float | None = None
    model_blur: float | None = None
    cell_average: bool = True
    raster_step: float | None = None
    candidates: int = 256
    hypotheses: int = 512
    active_keep: int = 8
    active_hypotheses: int = 2048
    kde_samples: int = 10000
    kde_bandwidth: float | None = None
    estimator: str = "mean"
    stop_ml: float | None = None
    stop_mass: float = 0.95
    stop_radius: float = 1.0
    stop_angle: float = 0.5
    max_memory_mb: float = 2048.0

    def __post_init__(self) -> None:
        get_strategy(self.strategy)
        if self.posterior not in POSTERIORS:
            raise ConfigError(f"unknown posterior {self.posterior!r}; valid: {', '.join(POSTERIORS)}")
        transforms.check_family(self.family)
        if self.estimator not in ESTIMATORS:
            raise ConfigError(f"unknown estimator {self.estimator!r}; valid: {', '.join(ESTIMATORS)}")
        _num("resolution", self.resolution)
        _num("prior_halfwidth", self.prior_halfwidth)
        _num("max_angle", self.max_angle, strict=False)
        if self.max_angle > 180:
            raise ConfigError(f"max_angle must be in [0, 180] degrees, got {self.max_angle!r}")
        _num("angle_resolution", self.angle_resolution)
        if self.prior_halfwidth < self.resolution:
            raise ConfigError("prior_halfwidth must be at least one resolution step")
        _num("blur", self.blur, strict=False, hi=MAX_BLUR)
        if self.model_blur is not None:
            _num("model_blur", self.model_blur, strict=False, hi=MAX_BLUR)
        if self.robust_eta is not None:
            _num("robust_eta", self.robust_eta)
            if self.robust_eta > 1:
                raise ConfigError(f"robust_eta must lie in (0, 1], got {self.robust_eta!r}")
        if self.redundancy_radius is not None:
            _num("redundancy_radius", self.redundancy_radius, strict=False)
        if not isinstance(self.robust, bool):
            raise ConfigError(f"robust must be true or false, got {self.robust!r}")
        rigid = self.family == "rigid"
        if self.robust_outliers is None:
            object.__setattr__(self, "robust_outliers",
                               RIGID_OUTLIERS if rigid else DEFAULT_OUTLIERS)
        for name in ("robust_blurs", "robust_outliers"):
            v = getattr(self, name)
            if v is None:  # robust_blurs: resolved with the model (robust_blurs())
                continue
            if isinstance(v, (str, bytes)) or not hasattr(v, "__len__") or len(v) == 0:
                raise ConfigError(f"{name} must be a non-empty list of numbers, got {v!r}")
            for x in v:
                _num(name, x, strict=name == "robust_outliers",
                     hi=MAX_BLUR if name == "robust_blurs" else math.inf)
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if any(e >= 1 for e in self.robust_outliers):
            raise ConfigError(f"robust_outliers must be rates in (0, 1), got {self.robust_outliers!r}")
        if not isinstance(self.cell_average, bool):
            raise ConfigError(f"cell_average must be true or false, got {self.cell_average!r}")
        _num("outlier", self.outlier)
        if self.outlier >= 1:
            raise ConfigError(f"outlier must be in (0, 1), got {self.outlier!r}")
        if self.raster_step is not None:
            _num("raster_step", self.raster_step)
        for name in ("candidates", "hypotheses", "active_keep", "active_hypotheses"):
            _int(name, getattr(self, name))
        _int("kde_samples", self.kde_samples, 10)
        if self.kde_bandwidth is not None:
            _num("kde_bandwidth", self.kde_bandwidth)
        if self.stop_ml is not None:
            _num("stop_ml", self.stop_ml)
        _num("stop_mass", self.stop_mass)
        _num("stop_radius", self.stop_radius)
        _num("stop_angle", self.stop_angle)
        _num("max_memory_mb", self.max_memory_mb)
        cells, need = grid_bytes(self.family, self.prior_halfwidth, self.resolution,
                                 self.max_angle, self.angle_resolution)
        if need > self.max_memory_mb * 2**20:
            raise ConfigError(
                f"hypothesis grid of {cells:,} cells would need {_size(need)} of working memory, "
                f"above max_memory_mb = {self.max_memory_mb:g} MB: coarsen the resolution or "
                f"narrow the prior"
            )

    @property
    def grid_cells(self) -> int:
        return grid_bytes(self.family, self.prior_halfwidth, self.resolution, self.max_angle,
                          self.angle_resolution)[0]

    @property
    def is_robust(self) -> bool:
        """Whether the robust posterior is used (asked for, with the likelihood posterior)."""
        return self.robust and POSTERIORS.get(self.posterior).robust

    def nuisance(self, model=None) -> Nuisance:
        """The blurs (:func:`robust_blurs` for ``model``) and outlier rates the robust posterior
        marginalises."""
        return Nuisance.build(robust_blurs(model, self), self.robust_outliers)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["robust_blurs"] = None if self.robust_blurs is None else list(self.robust_blurs)
        d["robust_outliers"] = list(self.robust_outliers)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> AdapterConfig:
        check_known(cls, d, "adapt")
        return cls(**d)


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
    if cfg.family == "rigid":
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


def spot_count(points: np.ndarray, touched: np.ndarray, radius: float) -> np.ndarray:
    """(n,) how many of ``touched`` (k, 2) lie within ``radius`` px of each of ``points`` (n, 2)
    (0 throughout when ``radius`` is 0 or nothing was touched)."""
    points = np.asarray(points, float).reshape(-1, 2)
    touched = np.asarray(touched, float).reshape(-1, 2)
    if radius <= 0 or len(touched) == 0:
        return np.zeros(len(points), np.int64)
    d2 = ((points[:, None, :] - touched[None, :, :]) ** 2).sum(axis=2)
    return (d2 <= radius * radius).sum(axis=1)


def _size(nbytes: float) -> str:
    for unit, scale in (("GB", 2**30), ("MB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes / 1024:.1f} kB"


def table_key(model, cfg: AdapterConfig) -> tuple:
    """What :func:`build_table` reads of ``cfg`` for ``model``: two configs with the same key share
    one table (the robust posterior's options, the strategy and the stopping rule do not count)."""
    return (total_blur(model, cfg), cfg.raster_step, cfg.resolution, cfg.family, cfg.outlier,
            cfg.max_memory_mb)


def build_table(model, cfg: AdapterConfig,
                area: tuple[float, float, float, float] | None = None) -> LikelihoodTable:
    """Rasterise ``model`` for ``cfg`` once (share it across adaptations with the same model).

    Raises
    ------
    ConfigError
        When the raster would exceed ``cfg.max_memory_mb``.
    """
    area = tuple(model.area if area is None else area)
    blur = total_blur(model, cfg)
    step = cfg.raster_step
    if step is None:  # a rigid grid cell reaches sub-cell precision only on a finer class map
        fine = cfg.family == "rigid" and isinstance(model, ExactModel) and blur == 0
        step = cfg.resolution / 2 if fine else cfg.resolution
    x0, y0, x1, y1 = area
    cells = math.ceil((x1 - x0) / step) * math.ceil((y1 - y0) / step)
    per_cell = 2 if (isinstance(model, ExactModel) and blur == 0) else 4 * len(
        model.class_features_)
    need = cells * per_cell
    if need > cfg.max_memory_mb * 2**20:
        raise ConfigError(f"model raster of {cells:,} cells at {step:g} px would need {_size(need)}, "
                          f"above max_memory_mb = {cfg.max_memory_mb:g} MB: raise raster_step")
    return LikelihoodTable.from_model(model, step, eps=cfg.outlier, blur=blur, area=area)


def build_samples(model, cfg: AdapterConfig, seed) -> ActionSamples:
    """The ``kde`` posterior's per-class samples of p(action | sound) for ``cfg`` (drawn lazily,
    once per class, from ``SeedSequence([*seed, cls])``; share it across adaptations)."""
    return ActionSamples(model, cfg.kde_samples, seed, bandwidth=cfg.kde_bandwidth,
                         resolution=cfg.resolution)


def total_blur(model, cfg: AdapterConfig) -> float:
    """Std (px) the model's raster is blurred by: the unseen reach noise and, for the plain
    posterior, the model softening (the robust posterior blurs per touch instead)."""
    if cfg.is_robust:
        return float(cfg.blur)
    mb = cfg.model_blur
    if mb is None:
        mb = 0.0 if isinstance(model, ExactModel) else LEARNED_BLUR
    return float(math.hypot(cfg.blur, mb))


@dataclass(frozen=True)
class Estimate:
    """Estimates of the transform parameters, in family order (``[angle,] dx, dy``)."""

    ml: np.ndarray
    mean: np.ndarray
    ml_prob: float


class Adapter:
    """The robot's side of the adaptation: decide, observe, estimate, stop.

    Parameters
    ----------
    model : SoundModel
        The learned (or exact) model of the instrument at its reference pose.
    cfg : AdapterConfig
    rng : numpy.random.Generator
        Drives the strategy's candidate sampling and the KDE's samples.
    area : tuple of float, optional
        Where actions may go (default: the model's working area).
    centre : (2,) ndarray, optional
        Rotation centre of the rigid family (default: the centre of ``area``, which is the
        keyboard's centre at its reference pose).
    table : LikelihoodTable, optional
        A prebuilt :func:`build_table` (saves rasterising the model again).
    samples : ActionSamples, optional
        The ``kde`` posterior's samples of p(action | sound), drawn once per class and shared (see
        :func:`build_samples`); default: a cache of this adapter's own, seeded from ``rng``.
    max_steps : int, optional
        A touch budget: :meth:`done` holds once this many touches were observed (None: only the
        stopping rule ends the adaptation).

    Examples
    --------
    The ask/tell loop, with a touch of the bundled simulator (see :meth:`from_model` for a model
    file)::

        adapter = Adapter.from_model("data/default-model.h5", strategy="infogain", seed=0)
        while not adapter.done():
            action = adapter.suggest()
            felt, heard = robot_touch(action)   # your robot: where it felt it landed, what it heard
            adapter.observe(action, heard, felt_position=felt)
        print(adapter.estimate(), adapter.entropy())
    """

    def __init__(self, model, cfg: AdapterConfig, *, rng: np.random.Generator,
                 area: tuple[float, float, float, float] | None = None,
                 centre: np.ndarray | None = None, table: LikelihoodTable | None = None,
                 samples: ActionSamples | None = None,
                 max_steps: int | None = None) -> None:
        if max_steps is not None:
            _int("max_steps", max_steps)
        self.max_steps = max_steps
        #: touches observed so far (unknown sounds included; ``posterior.n_obs`` counts updates)
        self.touches = 0
        self.model = model
        self.cfg = cfg
        self.rng = rng
        self.area = tuple(float(v) for v in (model.area if area is None else area))
        x0, y0, x1, y1 = self.area
        c = np.array([(x0 + x1) / 2, (y0 + y1) / 2]) if centre is None else np.asarray(centre, float)
        self.grid = HypothesisGrid.build(cfg.family, prior_halfwidth=cfg.prior_halfwidth,
                                         resolution=cfg.resolution, centre=c,
                                         max_angle=cfg.max_angle,
                                         angle_resolution=cfg.angle_resolution)
        self.table = build_table(model, cfg, self.area) if table is None else table
        self.posterior = Posterior.uniform(self.grid)
        #: the robust posterior (None with the plain one); ``posterior`` is then its marginal
        self.robust: RobustPosterior | None = (
            RobustPosterior(self.grid, cfg.nuisance(model), eta=learning_rate(model, cfg))
            if cfg.is_robust else None)
        self._strategy = get_strategy(cfg.strategy)
        #: px: touches this close count as one spot (robust posterior; see AdapterConfig)
        self.redundancy_radius = redundancy_radius(model, cfg) if cfg.is_robust else 0.0
        #: where each observed touch was read (felt position, or the aim)
        self.points: list[np.ndarray] = []
        self._edges: np.ndarray | None = None
        self._corners: np.ndarray | None = None
        self.bandwidths: list[float] = []
        if POSTERIORS.get(cfg.posterior).uses_samples and samples is None:
            samples = build_samples(model, cfg, [int(v) for v in rng.integers(2**32, size=2)])
        self.samples = samples

    @classmethod
    def from_model(cls, model, *, strategy: str = "infogain", family: str = "translation",
                   seed: int | None = None, rng: np.random.Generator | None = None,
                   config: AdapterConfig | None = None, max_steps: int | None = None,
                   **options) -> Adapter:
        """An adapter for a model: a model artifact file (``.h5``, kind ``model``), a loaded
        :class:`~kbcli.stages.artifact.Artifact`, or a model object.

        Parameters
        ----------
        model : str, path, Artifact or SoundModel
            A file is read with :mod:`kbcli.io` (imported only then: the core needs no h5py).
        strategy, family : str
            See :class:`AdapterConfig`.
        seed : int, optional
            Seed of the robot's generator (``numpy.random.default_rng(seed)``); or pass ``rng``.
        config : AdapterConfig, optional
            A whole config (then ``strategy``, ``family`` and ``options`` must not be given).
        max_steps : int, optional
            Touch budget after which :meth:`done` holds.
        **options
            Any other :class:`AdapterConfig` field (``posterior``, ``resolution``, ``stop_mass``...).

        Raises
        ------
        ArtifactError
            A missing or unreadable file, or an artifact that is not a model.
        ConfigError
            An unknown or invalid option.
        """
        if config is None:
            config = AdapterConfig.from_dict({"strategy": strategy, "family": family, **options})
        elif options:
            raise ConfigError(f"give either config or options, not both ({', '.join(options)})")
        if rng is None:
            rng = np.random.default_rng(seed)
        elif seed is not None:
            raise ConfigError("give either seed or rng, not both")
        if not hasattr(model, "classify"):  # a path or an artifact: the I/O layer loads it
            from kbcli.api import load_model

            model = load_model(model)
        return cls(model, config, rng=rng, max_steps=max_steps)

    # -- deciding ----------------------------------------------------------------------------------
    def planning_table(self) -> LikelihoodTable:
        """The map the strategies plan with: the model's, or with the robust posterior, blurred by
        the most probable boundary blur and floored at the most probable outlier rate."""
        if self.robust is None:
            return self.table
        i, j = self.robust.map_index()
        nz = self.robust.nuisance
        return planning_table(self.table, float(nz.blurs[i]), float(nz.outliers[j]))

    def context(self) -> Context:
        if self._edges is None:
            self._edges, self._corners = self.table.boundary_points()
        return Context(self.posterior, self.planning_table(), self.area, self._edges,
                       self._corners, self.cfg, touched=self.touched(),
                       redundancy_radius=self.redundancy_radius)

    def touched(self) -> np.ndarray:
        """(k, 2) where the observed touches were read (felt positions, or the aims)."""
        return np.asarray(self.points, float).reshape(-1, 2)

    def spot_count(self, points: np.ndarray) -> np.ndarray:
        """(n,) for each point, how many observed touches lie within ``redundancy_radius``."""
        pts = np.asarray(points, float).reshape(-1, 2)
        return spot_count(pts, self.touched(), self.redundancy_radius)

    def suggest(self) -> np.ndarray:
        """(2,) the next action (pad px) chosen by the strategy."""
        return np.asarray(self._strategy(self.context(), self.rng), float)

    def propose(self) -> np.ndarray:
        """The older name of :meth:`suggest`."""
        return self.suggest()

    # -- observing ---------------------------------------------------------------------------------
    def observe(self, action: np.ndarray, heard: np.ndarray | None,
                felt_position: np.ndarray | None = None) -> int:
        """Classify a heard sound (``model.classify``) and update the posterior with it.

        Parameters
        ----------
        action : (2,) array_like
            Where the robot aimed (pad px, inside the working area).
        heard : (D,) array_like or None
            The heard features; None (or all NaN) for silence.
        felt_position : (2,) array_like, optional
            Where the robot felt its finger land (proprioception): the point the posterior is
            updated at. None: the aim is used (set ``AdapterConfig.blur`` to the reach noise).

        Returns
        -------
        int
            The class (0 silence, -1 unknown: skipped).

        Raises
        ------
        ObservationError
            Non-numeric or wrongly sized input, an action outside the working area; the posterior
            is left unchanged.
        """
        a = self.check_action(action, "action")
        point = a if felt_position is None else _point(felt_position, "felt_position")
        h = self.check_heard(heard)
        cls = int(self.model.classify(h.reshape(1, -1))[0])
        self.observe_class(point, cls)
        self.touches += 1
        return cls

    def check_action(self, action, name: str = "action") -> np.ndarray:
        """``action`` as a (2,) array inside the working area; raises :class:`ObservationError`."""
        a = _point(action, name)
        x0, y0, x1, y1 = self.area
        tol = 1e-9 * max(1.0, abs(x1 - x0), abs(y1 - y0))
        if not (x0 - tol <= a[0] <= x1 + tol and y0 - tol <= a[1] <= y1 + tol):
            raise ObservationError(f"{name} ({a[0]:g}, {a[1]:g}) is outside the working area "
                                   f"({x0:g}, {y0:g})-({x1:g}, {y1:g})")
        return a

    def check_heard(self, heard) -> np.ndarray:
        """``heard`` as a (D,) float array (all NaN: silence); raises :class:`ObservationError`."""
        d = int(np.shape(self.model.class_features_)[1])
        if heard is None:
            return np.full(d, np.nan)
        try:
            h = np.asarray(heard, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ObservationError(f"heard features must be {d} numbers or null (silence), got "
                                   f"{heard!r}") from None
        if h.shape != (d,):
            raise ObservationError(f"heard features must be {d} numbers (or null for silence), "
                                   f"got {h.size}")
        nan = np.isnan(h)
        if (nan.any() and not nan.all()) or np.isinf(h).any():
            raise ObservationError(f"heard features must be all finite (or all missing for "
                                   f"silence), got {h.tolist()}")
        return h

    def observe_class(self, action: np.ndarray, cls: int) -> None:
        """Update the posterior with an already classified observation (Eq. 8)."""
        if cls == UNKNOWN:
            return
        a = np.asarray(action, float).reshape(2)
        if self.cfg.posterior == "kde":
            term, bw = kde_term(self.grid, self.model, a, cls, n_samples=self.cfg.kde_samples,
                                eps=self.cfg.outlier, samples=self.samples)
            self.bandwidths.append(bw)
        elif self.robust is not None:
            sigma = cell_sigma(self.grid, a) if self.cfg.cell_average and self.grid.rigid else 0.0
            terms = robust_terms(self.grid, self.table, a, cls, self.robust.nuisance, sigma)
            k = int(self.spot_count(a)[0])
            if k:  # the (k + 1)-th touch at one spot: weight 1 / (k + 1)
                terms = terms * np.float32(1.0 / (k + 1))
            self.points.append(a)
            self.robust = self.robust.update(terms)
            self.posterior = self.robust.marginal()
            return
        else:
            sigma = cell_sigma(self.grid, a) if self.cfg.cell_average else 0.0
            term = likelihood_term(self.grid, self.table, a, cls, sigma)
        self.posterior = self.posterior.update(term)

    # -- reading -----------------------------------------------------------------------------------
    def estimates(self) -> Estimate:
        post = self.posterior
        return Estimate(ml=post.ml(), mean=post.mean(), ml_prob=post.ml_prob())

    def estimate(self) -> np.ndarray:
        """(P,) the estimate the config asks for (posterior mean or maximum-likelihood cell)."""
        return ESTIMATORS.get(self.cfg.estimator).read(self.posterior)

    def entropy(self) -> float:
        """Posterior entropy, nats (over grid cells)."""
        return self.posterior.entropy()

    def mass_near_estimate(self) -> float:
        """Posterior mass within ``stop_radius`` (and ``stop_angle``) of the estimate."""
        return self.posterior.mass_within(self.estimate(), self.cfg.stop_radius, self.cfg.stop_angle)

    def should_stop(self) -> bool:
        """The paper's rule (ML probability >= ``stop_ml``, when set) or ours (mass near the
        estimate >= ``stop_mass``)."""
        if self.posterior.n_obs == 0:
            return False
        if self.cfg.stop_ml is not None and self.posterior.ml_prob() >= self.cfg.stop_ml:
            return True
        return self.mass_near_estimate() >= self.cfg.stop_mass

    def done(self) -> bool:
        """Whether to stop touching: the stopping rule (:meth:`should_stop`) holds, or the
        ``max_steps`` budget is used up."""
        return (self.max_steps is not None and self.touches >= self.max_steps) or \
            self.should_stop()


@dataclass(frozen=True)
class Step:
    """One step of :func:`adapt`."""

    t: int
    action: np.ndarray
    landed: np.ndarray
    perceived: np.ndarray
    cls: int
    ml: np.ndarray
    mean: np.ndarray
    estimate: np.ndarray
    entropy: float
    ml_prob: float
    mass: float
    stop: bool
    ms: float


Touch = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def _point(v, name: str) -> np.ndarray:
    """``v`` as a finite (2,) float array; raises :class:`ObservationError`."""
    try:
        p = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ObservationError(f"{name} must be two numbers (x, y in pad px), got {v!r}") from None
    if p.shape != (2,) or not np.isfinite(p).all():
        raise ObservationError(f"{name} must be two finite numbers (x, y in pad px), got "
                               f"{np.asarray(v).tolist() if p.size < 8 else f'{p.size} values'}")
    return p


def adapt(adapter: Adapter, touch: Touch, max_steps: int, *, use_landed: bool = True,
          stop: bool = False) -> Iterator[Step]:
    """Run the adaptation as an iterator of steps.

    Parameters
    ----------
    touch : callable
        ``touch(action (2,)) -> (landed (2,), perceived (D,))``.
    max_steps : int
        At most this many observations.
    use_landed : bool
        Observe at the landed position (proprioception) or at the aimed action.
    stop : bool
        End at the first step where :meth:`Adapter.should_stop` holds (else run all steps).

    Yields
    ------
    Step
        ``ms`` is the robot's time for the step: deciding plus updating (not the touch).
    """
    for t in range(1, max_steps + 1):
        t0 = time.perf_counter()
        action = adapter.suggest()
        t1 = time.perf_counter()
        landed, perceived = touch(action)
        landed = np.asarray(landed, float).reshape(2)
        perceived = np.asarray(perceived, float).reshape(-1)
        t2 = time.perf_counter()
        cls = adapter.observe(action, perceived, felt_position=landed if use_landed else None)
        st = step_record(adapter, t, action, landed, perceived, cls, t0=t2, extra_ms=1e3 * (t1 - t0))
        yield st
        if stop and st.stop:
            return


def step_record(adapter: Adapter, t: int, action: np.ndarray, landed: np.ndarray,
                perceived: np.ndarray, cls: int, *, t0: float, extra_ms: float = 0.0) -> Step:
    """The :class:`Step` record of the adapter's state after its ``t``-th observation.

    ``ms`` is the time from ``t0`` (``time.perf_counter()`` when the observation started) to the
    estimates being read, plus ``extra_ms`` (the decision's time).
    """
    post = adapter.posterior
    ml, mean = post.ml(), post.mean()
    ms = 1e3 * (time.perf_counter() - t0) + extra_ms
    return Step(t=t, action=np.asarray(action, float), landed=np.asarray(landed, float),
                perceived=np.asarray(perceived, float), cls=int(cls), ml=ml, mean=mean,
                estimate=ESTIMATORS.get(adapter.cfg.estimator).read(post),
                entropy=post.entropy(), ml_prob=post.ml_prob(),
                mass=adapter.mass_near_estimate(), stop=adapter.should_stop(), ms=ms)


__all__ = ["AdapterConfig", "Adapter", "Estimate", "Step", "adapt", "step_record", "build_table",
           "build_samples", "STRATEGIES", "POSTERIORS"]
