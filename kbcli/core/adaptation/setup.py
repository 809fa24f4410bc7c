"""Set-up of an adaptation for one model: the rasterised model (:func:`build_table`) and the KDE
posterior's per-class samples (:func:`build_samples`), both shareable across adaptations of one
model, and the touch bookkeeping of the robust posterior (:func:`spot_count`).
"""

from __future__ import annotations

import math

import numpy as np

from kbcli.core.adaptation.config import LEARNED_BLUR, AdapterConfig, _size
from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.kde.samples import ActionSamples, beyond_source
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.core.model.table import LikelihoodTable, exact_map
from kbcli.errors import ConfigError


def spot_count(points: np.ndarray, touched: np.ndarray, radius: float) -> np.ndarray:
    """(n,) how many of ``touched`` (k, 2) lie within ``radius`` px of each of ``points`` (n, 2)
    (0 throughout when ``radius`` is 0 or nothing was touched)."""
    points = np.asarray(points, float).reshape(-1, 2)
    touched = np.asarray(touched, float).reshape(-1, 2)
    if radius <= 0 or len(touched) == 0:
        return np.zeros(len(points), np.int64)
    d2 = ((points[:, None, :] - touched[None, :, :]) ** 2).sum(axis=2)
    return (d2 <= radius * radius).sum(axis=1)


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
        fine = FAMILIES.get(cfg.family).rotates and exact_map(model) and blur == 0
        step = cfg.resolution / 2 if fine else cfg.resolution
    x0, y0, x1, y1 = area
    cells = math.ceil((x1 - x0) / step) * math.ceil((y1 - y0) / step)
    per_cell = 2 if (exact_map(model) and blur == 0) else 4 * len(
        model.class_features_)
    need = cells * per_cell
    if need > cfg.max_memory_mb * 2**20:
        raise ConfigError(f"model raster of {cells:,} cells at {step:g} px would need {_size(need)}, "
                          f"above max_memory_mb = {cfg.max_memory_mb:g} MB: raise raster_step")
    return LikelihoodTable.from_model(model, step, eps=cfg.outlier, blur=blur, area=area)


def hypothesis_grid(cfg: AdapterConfig, area: tuple[float, float, float, float],
                    centre: np.ndarray | None = None) -> HypothesisGrid:
    """The hypothesis grid of ``cfg`` for a working area (rotation centre: the area's centre
    unless given, the keyboard's centre at its reference pose)."""
    x0, y0, x1, y1 = area
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2]) if centre is None else np.asarray(centre, float)
    return HypothesisGrid.build(cfg.family, prior_halfwidth=cfg.prior_halfwidth,
                                resolution=cfg.resolution, centre=c, max_angle=cfg.max_angle,
                                angle_resolution=cfg.angle_resolution)


def build_samples(model, cfg: AdapterConfig, seed, *, table: LikelihoodTable | None = None,
                  source=None) -> ActionSamples:
    """The ``kde`` posterior's per-class samples of p(action | sound) for ``cfg`` (drawn lazily,
    once per class, from ``SeedSequence([*seed, cls])``; share it across adaptations), drawn
    from ``source`` (default: the model, as
    :func:`~kbcli.core.adaptation.posteriors.kde.samples.beyond_source` wraps it for ``cfg``;
    ``table``, the model's raster for ``cfg``, is built when not given and needed)."""
    opts = cfg.posterior
    if source is None:
        source = model
        if opts.kde_beyond == "silent":
            area = tuple(float(v) for v in model.area)
            table = build_table(model, cfg, area) if table is None else table
            source = beyond_source(model, opts, table, hypothesis_grid(cfg, area), area)
    return ActionSamples(source, opts.kde_samples, seed, bandwidth=opts.kde_bandwidth,
                         resolution=cfg.resolution)


def total_blur(model, cfg: AdapterConfig) -> float:
    """Std (px) the model's raster is blurred by: the unseen reach noise and, for the plain
    posterior, the model softening (the robust posterior blurs per touch instead)."""
    if cfg.is_robust:
        return float(cfg.blur)
    mb = cfg.model_blur
    if mb is None:
        mb = 0.0 if exact_map(model) else LEARNED_BLUR
    return float(math.hypot(cfg.blur, mb))
