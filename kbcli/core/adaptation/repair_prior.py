"""The model's map as the repaired belief reads it: local confidence and local blur.

For a learned model (rasterised as a :class:`~kbcli.core.model.table.LikelihoodTable`) with its
training samples, a :class:`RepairMap` holds what :mod:`kbcli.core.adaptation.repair` needs at
every raster cell: the **local confidence** ``kappa(x)``, the training samples counted with the
kernel ``k(x - x_s) = exp(-|x - x_s|^2 / (2 w^2))`` (a sample at ``x`` is worth one touch there)
plus a small floor, and the distance ``d(x)`` to the nearest sample, which sets the **local blur**
``sigma(x) = hypot(g, s d(x))`` of the model's probabilities (``g``: the model's own landing
scatter). A model without samples (the exact model) is trusted fully everywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

from kbcli.core.adaptation.posteriors.likelihood.robust import blurred_map, raw_prob
from kbcli.core.model.table import LikelihoodTable

#: Default scale ``s`` of the local blur ``sigma(x) = s d(x)``: about ``1 / sqrt(3)``, the std of an
#: edge uniform in the gap between two samples of different sounds, read at the gap's middle.
DEFAULT_SCALE = 0.6
#: Blur levels (px) the local blur interpolates between; wider local blurs are clipped to the last.
LEVELS = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
#: Kernel width ``w`` (px) of a touch's (and a training sample's) count.
DEFAULT_KERNEL = 10.0
#: Confidence floor: the weight of the model's prior where it has no sample nearby.
KAPPA_FLOOR = 0.2
#: A model without training samples (the exact model) is trusted with this weight everywhere.
KAPPA_EXACT = 1e9
#: Cell of the planning maps, px.
PLAN_STEP = 1.0


def kernel(d2: np.ndarray, width: float) -> np.ndarray:
    """The count kernel ``exp(-d^2 / (2 w^2))`` of squared distances ``d2`` (px^2)."""
    return np.exp(-0.5 * np.asarray(d2, float) / (width * width))


@dataclass(frozen=True)
class RepairMap:
    """What the repaired belief reads of a model, built once per model raster.

    Attributes
    ----------
    table : LikelihoodTable
        The model's raster (reference frame).
    distance : (H, W) float32 ndarray
        Distance (px) of every raster cell to the model's nearest training sample (inf: none).
    kappa : (H, W) float32 ndarray
        The local confidence ``kappa(x)``: training samples counted with the kernel, plus the
        floor.
    width : float
        Kernel width ``w``, px.
    """

    table: LikelihoodTable
    distance: np.ndarray
    kappa: np.ndarray
    width: float
    floor_blur: float = 0.0
    _plans: dict = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def build(cls, table: LikelihoodTable, samples: np.ndarray | None,
              width: float = DEFAULT_KERNEL, floor: float = KAPPA_FLOOR,
              floor_blur: float = 0.0) -> RepairMap:
        """The repair map of ``table`` for a model whose training samples are at ``samples``
        ((n, 2) px, reference frame; None or empty: a model without samples, trusted fully)."""
        h, w = table.shape
        if samples is None or len(samples) == 0:
            dist = np.zeros((h, w), np.float32)
            kappa = np.full((h, w), KAPPA_EXACT, np.float32)
            return cls(table, dist, kappa, float(width), float(floor_blur))
        pts = np.asarray(samples, float).reshape(-1, 2)
        ys = table.origin[1] + table.step * np.arange(h)
        xs = table.origin[0] + table.step * np.arange(w)
        gx, gy = np.meshgrid(xs, ys)
        dist, _ = cKDTree(pts).query(np.column_stack([gx.ravel(), gy.ravel()]))
        dist = dist.reshape(h, w).astype(np.float32)
        # the samples splatted on the raster and smoothed: a Gaussian filter of a unit impulse
        # peaks at 1 / (2 pi sig^2) (sig in cells), so scaling by that counts a sample as 1 at its
        # own cell
        counts = np.zeros((h, w))
        col = np.clip(np.rint((pts[:, 0] - table.origin[0]) / table.step).astype(int), 0, w - 1)
        row = np.clip(np.rint((pts[:, 1] - table.origin[1]) / table.step).astype(int), 0, h - 1)
        np.add.at(counts, (row, col), 1.0)
        sig = width / table.step
        kappa = gaussian_filter(counts, sig, mode="constant", truncate=4.0) * (2 * math.pi * sig**2)
        return cls(table, dist, (kappa + floor).astype(np.float32), float(width),
                   float(floor_blur))

    def _read(self, grid_x: np.ndarray, grid_y: np.ndarray, raster: np.ndarray,
              outside: float) -> np.ndarray:
        row, col, inside = self.table._index(grid_x, grid_y)
        v = raster[row, col]
        return np.where(inside, v, np.float32(outside)) if not inside.all() else v

    def confidence(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """``kappa`` at coordinates (broadcast); outside the raster the model's silence is sure."""
        return self._read(x, y, self.kappa, KAPPA_EXACT)

    def local_sigma(self, x: np.ndarray, y: np.ndarray, scale: float) -> np.ndarray:
        """``sigma(x) = hypot(g, scale d(x))`` (px) at coordinates (``g``: ``floor_blur``),
        clipped to the widest level."""
        g = np.float32(self.floor_blur)
        if scale == 0.0:
            return np.full(np.broadcast(x, y).shape, g, np.float32)
        d = self._read(x, y, self.distance, 0.0)
        return np.minimum(np.hypot(np.float32(scale) * d, g), np.float32(LEVELS[-1]))

    def prob(self, x: np.ndarray, y: np.ndarray, cls: int, scale: float) -> np.ndarray:
        """``q_s(cls | x)``: the model's map locally blurred by ``sigma(x) = scale d(x)``, read at
        coordinates (broadcast), linearly interpolated between the blur levels ``LEVELS``."""
        sig = self.local_sigma(x, y, scale)
        shape = np.broadcast(x, y).shape
        if not sig.any():
            return np.broadcast_to(raw_prob(self.table, x, y, cls), shape)
        lv = np.asarray(LEVELS, np.float32)
        j = np.clip(np.searchsorted(lv, sig, side="right") - 1, 0, len(lv) - 2)
        frac = (sig - lv[j]) / (lv[j + 1] - lv[j])
        out = np.zeros(shape, np.float32)
        xb, yb = np.broadcast_arrays(x, y)
        for k in np.unique(j):
            for level, wt in ((k, 1.0 - frac), (k + 1, frac)):
                sel = j == k
                m = blurred_map(self.table, float(lv[level]))
                out[sel] += (wt[sel] * raw_prob(m, xb[sel], yb[sel], cls)).astype(np.float32)
        return out

    def planning_table(self, scale: float, eps: float) -> LikelihoodTable:
        """The model's map locally blurred at ``scale``, floored at ``eps``, on ``PLAN_STEP`` px
        cells: what the strategies read a hypothesis' prior predictive from. Cached."""
        key = (round(float(scale), 6), round(float(eps), 9))
        if key not in self._plans:
            t = self.table
            x0 = t.origin[0]
            y0 = t.origin[1]
            h, w = t.shape
            k = max(1, int(round(PLAN_STEP / t.step)))
            xs = x0 + t.step * np.arange(0, w, k)
            ys = y0 + t.step * np.arange(0, h, k)
            gx, gy = np.meshgrid(xs, ys)
            probs = np.stack([self.prob(gx, gy, c, scale) for c in range(t.n_classes)], axis=-1)
            probs /= np.maximum(probs.sum(axis=-1, keepdims=True), 1e-12)
            self._plans[key] = LikelihoodTable(np.array([x0, y0]), t.step * k, t.n_classes,
                                               float(eps), probs=probs.astype(np.float32))
        return self._plans[key]


def repair_map(table: LikelihoodTable, samples: np.ndarray | None, width: float,
               floor_blur: float) -> RepairMap:
    """:meth:`RepairMap.build` for ``table``, cached on it (every adaptation sharing a table
    shares its repair map)."""
    cache = getattr(table, "_repair_cache", None)
    if cache is None:
        cache = {}
        object.__setattr__(table, "_repair_cache", cache)
    key = (round(float(width), 6), round(float(floor_blur), 6),
           None if samples is None else len(samples))
    if key not in cache:
        cache[key] = RepairMap.build(table, samples, width, floor_blur=floor_blur)
    return cache[key]
