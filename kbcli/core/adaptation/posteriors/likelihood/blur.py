"""The model's map blurred: a Gaussian of ``sigma`` px convolved with p(sound | point), the robust
posterior's boundary blur (:mod:`~kbcli.core.adaptation.posteriors.likelihood.robust`) and the map
the strategies plan with (:func:`planning_table`).

A whole map is blurred once per level and cached on its table (:func:`blurred_map`); a window
around a touch is blurred on demand (:func:`blurred_read`). Wide blurs are computed on coarser
cells, so a blur's cost does not grow with its width.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import correlate1d

from kbcli.core.model.sounds import SILENCE
from kbcli.core.model.table import LikelihoodTable


def _kernel(sig: float) -> np.ndarray:
    """A normalised Gaussian kernel of std ``sig`` cells, truncated at 4 std (float32)."""
    half = max(1, int(math.ceil(4 * sig)))
    k = np.exp(-0.5 * (np.arange(-half, half + 1) / sig) ** 2)
    return (k / k.sum()).astype(np.float32)


def blurred_read(patch: np.ndarray, row: np.ndarray, col: np.ndarray, sig: float) -> np.ndarray:
    """``patch`` blurred by a Gaussian of ``sig`` cells, read at cells (row, col).

    Only the part of the patch the reads need (plus 4 std) is blurred, by two 1-D correlations.
    Wide blurs are computed on a coarser copy (``k x k`` block means, ``k = floor(sig / 2)``: at
    least two coarse cells per std), which keeps a blur's cost independent of its width; the
    reading error this adds, under half a coarse cell, is at most a quarter of the blur.
    """
    if sig < 0.5:
        return patch[row, col]
    k = max(1, int(sig // 2))
    half = int(math.ceil(4 * sig)) + k
    r0, r1 = max(int(row.min()) - half, 0), min(int(row.max()) + half + 1, patch.shape[0])
    c0, c1 = max(int(col.min()) - half, 0), min(int(col.max()) + half + 1, patch.shape[1])
    sub = patch[r0:r1, c0:c1]
    rr, cc = row - r0, col - c0
    if k > 1:
        h, w = (sub.shape[0] // k) * k, (sub.shape[1] // k) * k
        if h >= k and w >= k:
            sub = sub[:h, :w].reshape(h // k, k, w // k, k).mean(axis=(1, 3))
            rr, cc = np.minimum(rr // k, h // k - 1), np.minimum(cc // k, w // k - 1)
            sig = sig / k
    kern = _kernel(sig)
    out = correlate1d(sub, kern, axis=0, mode="nearest")
    out = correlate1d(out, kern, axis=1, mode="nearest")
    return out[rr, cc]


def _cache(table: LikelihoodTable) -> dict:
    cache = getattr(table, "_robust_cache", None)
    if cache is None:
        cache = {}
        object.__setattr__(table, "_robust_cache", cache)
    return cache


def _planes(table: LikelihoodTable) -> np.ndarray | None:
    """(C, H, W) class-major copy of a soft table's map (a class's map is then contiguous);
    None for a hard table. Cached on ``table``."""
    if table.hard:
        return None
    cache = _cache(table)
    if "planes" not in cache:
        cache["planes"] = np.ascontiguousarray(np.moveaxis(table.probs, -1, 0))
    return cache["planes"]


@dataclass(frozen=True)
class BlurredMap:
    """A model's map convolved with a Gaussian: class-major probabilities on the table's cells.

    Attributes
    ----------
    planes : (C, H, W) float32 ndarray
        ``planes[c]`` is p(c | cell), silence beyond the original raster.
    origin : (2,) ndarray
        Centre of cell (0, 0).
    step : float
        Cell size, px.
    """

    planes: np.ndarray
    origin: np.ndarray
    step: float

    def _index(self, x: np.ndarray, y: np.ndarray):
        h, w = self.planes.shape[1:]
        col = np.rint((x - self.origin[0]) / self.step).astype(np.int64)
        row = np.rint((y - self.origin[1]) / self.step).astype(np.int64)
        inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        return np.clip(row, 0, h - 1), np.clip(col, 0, w - 1), inside


def blurred_map(table: LikelihoodTable, blur: float) -> BlurredMap | LikelihoodTable:
    """``table``'s map convolved with an isotropic Gaussian of ``blur`` px (padded with silence
    beyond the raster); ``table`` itself for a blur under half a cell.

    Cached on ``table``, so every adapter sharing a table (an evaluation's worker) blurs each level
    once. Memory: one float32 map per class and blur level.
    """
    if blur < 0.5 * table.step:
        return table
    cache = _cache(table)
    key = ("blur", round(float(blur), 6))
    if key not in cache:
        c = table.n_classes
        pad = int(math.ceil(4 * blur / table.step))
        h, w = table.shape
        planes = np.zeros((c, h + 2 * pad, w + 2 * pad), np.float32)
        planes[SILENCE] = 1.0  # silence beyond the raster
        inner = planes[:, pad:pad + h, pad:pad + w]
        if table.hard:
            inner[SILENCE] = 0.0
            for k in np.unique(table.classes):
                inner[k] = table.classes == k
        else:
            inner[...] = np.moveaxis(table.probs, -1, 0)
        # at least three cells per std: wide blurs are computed (and stored) on coarser cells,
        # block means of k x k; a read is then off by under half a coarse cell (<= blur / 6)
        k = max(1, int(blur / (3 * table.step)))
        if k > 1:
            hh, ww = (planes.shape[1] // k) * k, (planes.shape[2] // k) * k
            planes = planes[:, :hh, :ww].reshape(c, hh // k, k, ww // k, k).mean(axis=(2, 4))
        kern = _kernel(blur / (table.step * k))
        for j in range(c):  # one class map at a time keeps the temporaries small
            if planes[j].any():
                tmp = correlate1d(planes[j], kern, axis=0, mode="nearest")
                planes[j] = correlate1d(tmp, kern, axis=1, mode="nearest")
        origin = table.origin - pad * table.step + (k - 1) / 2 * table.step
        cache[key] = BlurredMap(np.ascontiguousarray(planes, np.float32),
                                np.asarray(origin, float), float(table.step * k))
    return cache[key]


def planning_table(table: LikelihoodTable, blur: float, eps: float) -> LikelihoodTable:
    """The model's map as the strategies should plan with it: blurred by ``blur`` px (on top of any
    blur already in ``table``) and floored at ``eps``. Cached on ``table``.

    A map blurred by 2 px or more is planned on cells of at least 1 px (planning needs no finer
    map there; it is 4x smaller and quicker to prepare).
    """
    cache = _cache(table)
    key = ("plan", round(float(blur), 6), round(float(eps), 9))
    if key not in cache:
        b = blurred_map(table, blur)
        if isinstance(b, LikelihoodTable):
            out = LikelihoodTable(b.origin, b.step, b.n_classes, float(eps), classes=b.classes,
                                  probs=b.probs)
        else:
            k = max(1, int(round(1.0 / b.step))) if blur >= 2.0 and b.step < 1.0 else 1
            probs = np.ascontiguousarray(np.moveaxis(b.planes[:, ::k, ::k], 0, -1))
            out = LikelihoodTable(b.origin, b.step * k, table.n_classes, float(eps), probs=probs)
        cache[key] = out
    return cache[key]


def raw_prob(table: LikelihoodTable | BlurredMap, x: np.ndarray, y: np.ndarray,
             cls: int) -> np.ndarray:
    """``p(cls | (x, y))`` from the map, without the table's floor; silence outside the raster.

    For a translation grid (``x`` a row, ``y`` a column) the class's map is read as two ``take``
    calls on its contiguous plane.
    """
    row, col, inside = table._index(x, y)
    if isinstance(table, LikelihoodTable) and table.hard:
        p = (table.classes[row, col] == cls).astype(np.float32)
    else:
        plane = table.planes[cls] if isinstance(table, BlurredMap) else _planes(table)[cls]
        if row.ndim == 2 and col.ndim == 2 and row.shape[1] == 1 and col.shape[0] == 1:
            p = np.take(np.take(plane, row[:, 0], axis=0), col[0], axis=1)
        else:
            p = plane[row, col]
    if not inside.all():
        p = np.where(inside, p, np.float32(cls == SILENCE))
    return p
