"""The model, rasterised: ``p_eps(sound class | point)`` on a raster (paper Sect. III-D).

A :class:`LikelihoodTable` is the model's ``p(sound | action)`` rasterised once per adaptation (a
class map for the exact model). ``p_eps = (1 - eps) p + eps / C`` is an outlier floor: a touch
that contradicts the truth costs ``log(eps / C)`` instead of zeroing it. When the robot knows only
where it *aimed*, the raster is blurred by the reach noise. The strategies read its predictive
distributions (:meth:`LikelihoodTable.top_at`, :meth:`LikelihoodTable.entropy_at`) and its class
boundaries.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter

from kbcli.core.model.base import ExactModel, grid_points
from kbcli.core.model.sampling import RasterSampler
from kbcli.core.model.sounds import SILENCE

#: Classes kept per raster cell of a soft table for the strategies' predictive distributions (a
#: learned model mixes two sounds at an edge; a blurred exact map up to four at a key corner).
TOP_K = 4


def exact_map(model) -> bool:
    """Whether ``model`` knows its class map exactly (a cheap hard ``predict_class``, no
    probabilities): its ``exact_map`` attribute, else ``isinstance(model, ExactModel)``.
    """
    return bool(getattr(model, "exact_map", isinstance(model, ExactModel)))


@dataclass(frozen=True)
class LikelihoodTable:
    """``p_eps(sound class | point)`` on a raster, indexed in the adaptation's inner loop.

    Either ``classes`` (a hard model: one class per cell, e.g. the exact model) or ``probs`` (a soft
    model) is set. Outside the raster the sound is silence.

    Attributes
    ----------
    origin : (2,) ndarray
        Centre of cell (0, 0).
    step : float
        Cell size, px.
    n_classes : int
        C, class 0 is silence.
    eps : float
        Outlier floor: ``p_eps = (1 - eps) p + eps / C``.
    classes : (H, W) int16 ndarray or None
    probs : (H, W, C) float32 ndarray or None
    """

    origin: np.ndarray
    step: float
    n_classes: int
    eps: float
    classes: np.ndarray | None = None
    probs: np.ndarray | None = None
    _log_hit: float = field(init=False, repr=False)
    _log_miss: float = field(init=False, repr=False)
    _argmax: np.ndarray = field(init=False, repr=False)
    _cell_entropy: np.ndarray | None = field(init=False, repr=False, default=None)
    _top_classes: np.ndarray | None = field(init=False, repr=False, default=None)
    _top_probs: np.ndarray | None = field(init=False, repr=False, default=None)
    _sampler: object | None = field(init=False, repr=False, default=None, compare=False)

    def __post_init__(self) -> None:
        if (self.classes is None) == (self.probs is None):
            raise ValueError("a LikelihoodTable holds either classes or probs")
        c = self.n_classes
        object.__setattr__(self, "_log_hit", math.log(1 - self.eps + self.eps / c))
        object.__setattr__(self, "_log_miss", math.log(self.eps / c))
        top = self.classes if self.classes is not None else np.argmax(self.probs, axis=-1)
        object.__setattr__(self, "_argmax", top.astype(np.int16))
        if self.probs is not None:
            q = (1 - self.eps) * self.probs + np.float32(self.eps / c)
            object.__setattr__(self, "_cell_entropy", -(q * np.log(q)).sum(axis=-1))
            k = min(TOP_K, c)
            top_k = np.argpartition(self.probs, c - k, axis=-1)[..., c - k:]
            object.__setattr__(self, "_top_classes", top_k.astype(np.int16))
            object.__setattr__(self, "_top_probs",
                               np.take_along_axis(self.probs, top_k, axis=-1).astype(np.float32))

    @classmethod
    def from_model(cls, model, step: float, *, eps: float, blur: float = 0.0,
                   area: tuple[float, float, float, float] | None = None) -> LikelihoodTable:
        """Rasterise a model over its working area (or ``area``).

        The exact model (cheap ``predict_class``) gives a class map; any other model its
        ``raster(step)`` (one expensive ``predict_proba`` call per adaptation). ``blur`` > 0 px
        convolves the probabilities with an isotropic Gaussian (aim-only feedback with reach noise).
        """
        area = model.area if area is None else area
        n_classes = int(len(model.class_features_))
        exact = exact_map(model)
        if exact and blur == 0:
            origin, pts = grid_points(area, step)
            cl = model.predict_class(pts.reshape(-1, 2)).reshape(pts.shape[:2])
            return cls(origin, float(step), n_classes, eps, classes=cl.astype(np.int16))
        if exact:
            origin, pts = grid_points(area, step)
            cl = model.predict_class(pts.reshape(-1, 2)).reshape(pts.shape[:2])
            probs = np.eye(n_classes, dtype=np.float32)[cl]
        else:
            r = model.raster(step)
            origin, probs = np.asarray(r.origin, float), np.asarray(r.probs, np.float32)
            step = r.step
        if blur > 0:
            # pad with silence so the blur sees the silent outside of the raster
            pad = int(math.ceil(4 * blur / step))
            probs = np.pad(probs, ((pad, pad), (pad, pad), (0, 0)))
            probs[:pad, :, SILENCE] = 1
            probs[-pad:, :, SILENCE] = 1
            probs[:, :pad, SILENCE] = 1
            probs[:, -pad:, SILENCE] = 1
            probs = gaussian_filter(probs, sigma=(blur / step, blur / step, 0), mode="nearest")
            origin = origin - pad * step
        return cls(np.asarray(origin, float), float(step), n_classes, eps,
                   probs=np.ascontiguousarray(probs, dtype=np.float32))

    @property
    def hard(self) -> bool:
        return self.classes is not None

    @property
    def nbytes(self) -> int:
        return int((self.classes if self.hard else self.probs).nbytes)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.classes if self.hard else self.probs).shape[:2]

    def argmax(self) -> np.ndarray:
        """(H, W) most probable class of every cell."""
        return self._argmax

    def conditional_entropy(self) -> float | None:
        """Entropy (nats) of ``p_eps(. | x)`` for a one-hot cell: the same everywhere for a hard
        table (returned), None for a soft one (it varies)."""
        if not self.hard:
            return None
        c, e = self.n_classes, self.eps
        hit, miss = 1 - e + e / c, e / c
        return float(-(hit * math.log(hit) + (c - 1) * miss * math.log(miss)))

    # -- lookups ---------------------------------------------------------------------------------
    def _index(self, x: np.ndarray, y: np.ndarray):
        """Nearest raster cells of coordinates (broadcast), and whether they are inside."""
        h, w = self.shape
        col = np.rint((x - self.origin[0]) / self.step).astype(np.int64)
        row = np.rint((y - self.origin[1]) / self.step).astype(np.int64)
        inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        return np.clip(row, 0, h - 1), np.clip(col, 0, w - 1), inside

    def classes_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Most probable class at coordinates ``x, y`` (broadcast together); silence outside."""
        row, col, inside = self._index(x, y)
        cl = np.take(self._argmax.reshape(-1), row * self.shape[1] + col)
        return np.where(inside, cl, SILENCE)

    def log_prob(self, x: np.ndarray, y: np.ndarray, cls: int | np.ndarray) -> np.ndarray:
        """``log p_eps(cls | (x, y))`` for coordinates (and classes) broadcast together."""
        row, col, inside = self._index(x, y)
        cls = np.asarray(cls)
        if self.hard:
            hit = np.where(inside, self.classes[row, col] == cls, cls == SILENCE)
            return np.where(hit, self._log_hit, self._log_miss)
        p = np.where(inside, self.probs[row, col, cls], (cls == SILENCE).astype(np.float32))
        return np.log((1 - self.eps) * p + self.eps / self.n_classes)

    def window(self, cls: int, box: tuple[float, float, float, float]) -> tuple[np.ndarray,
                                                                               np.ndarray]:
        """``p(cls | cell)`` (no floor) over the raster cells covering ``box``, silence outside.

        Returns
        -------
        patch : (h, w) float32 ndarray
        origin : (2,) ndarray
            Centre of the patch's cell (0, 0).
        """
        x0, y0, x1, y1 = box
        c0 = int(math.floor((x0 - self.origin[0]) / self.step))
        c1 = int(math.ceil((x1 - self.origin[0]) / self.step)) + 1
        r0 = int(math.floor((y0 - self.origin[1]) / self.step))
        r1 = int(math.ceil((y1 - self.origin[1]) / self.step)) + 1
        hh, ww = self.shape
        patch = np.full((r1 - r0, c1 - c0), float(cls == SILENCE), dtype=np.float32)
        rr0, rr1, cc0, cc1 = max(r0, 0), min(r1, hh), max(c0, 0), min(c1, ww)
        if rr0 < rr1 and cc0 < cc1:
            if self.hard:
                inner = self.classes[rr0:rr1, cc0:cc1] == cls
            else:
                inner = self.probs[rr0:rr1, cc0:cc1, cls]
            patch[rr0 - r0:rr1 - r0, cc0 - c0:cc1 - c0] = inner
        return patch, self.origin + np.array([c0, r0]) * self.step

    def entropy_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Entropy (nats) of ``p_eps(. | (x, y))``, broadcast over the coordinates."""
        row, col, inside = self._index(x, y)
        if self.hard:
            return np.full(np.shape(inside), self.conditional_entropy())
        c, e = self.n_classes, self.eps
        hit, miss = 1 - e + e / c, e / c
        silent = -(hit * math.log(hit) + (c - 1) * miss * math.log(miss))
        return np.where(inside, self._cell_entropy[row, col], silent)

    def top_at(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ``TOP_K`` most probable classes at coordinates and their probabilities (no floor).

        Returns
        -------
        classes : broadcast shape + (k,) int ndarray
        probs : broadcast shape + (k,) float32 ndarray
            Silence with probability 1 outside the raster.
        """
        row, col, inside = self._index(x, y)
        if self.hard:
            cl = np.where(inside, self.classes[row, col], SILENCE)
            return cl[..., None], np.ones(cl.shape + (1,), np.float32)
        k = self._top_classes.shape[-1]
        flat = row * self.shape[1] + col
        cl = np.take(self._top_classes.reshape(-1, k), flat, axis=0)
        p = np.take(self._top_probs.reshape(-1, k), flat, axis=0)
        if not inside.all():
            k = cl.shape[-1]
            out_c = np.zeros(k, cl.dtype)
            out_p = np.zeros(k, np.float32)
            out_p[0] = 1
            cl = np.where(inside[..., None], cl, out_c)
            p = np.where(inside[..., None], p, out_p)
        return cl, p

    def confusion_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The model's confusion factor ``1 - (p1 - p2)`` at coordinates (broadcast): its own
        uncertainty over which sound a touch there gives (paper Sect. III-E; the
        ``LearnedModel.confusion`` of the raster cell, no floor). 0 where one sound is sure (a
        hard table everywhere, silence outside the raster), 1 where two are equally likely."""
        _, p = self.top_at(x, y)
        if p.shape[-1] < 2:
            return np.zeros(p.shape[:-1])
        top2 = np.sort(p, axis=-1)[..., -2:].astype(np.float64)
        return 1.0 - (top2[..., 1] - top2[..., 0])

    def sampler(self):
        """A :class:`~kbcli.core.model.sampling.RasterSampler` of this raster (built once, kept
        with the table so every adaptation sharing the table shares its per-class weights)."""
        if self._sampler is None:
            object.__setattr__(self, "_sampler", RasterSampler(self))
        return self._sampler

    def prob_all(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """``p_eps(. | (x, y))`` for all classes: shape ``broadcast(x, y).shape + (C,)``."""
        row, col, inside = self._index(x, y)
        c = self.n_classes
        if self.hard:
            cl = np.where(inside, self.classes[row, col], SILENCE)
            p = np.eye(c)[cl]
        else:
            p = self.probs[row, col]
            if not inside.all():
                p = np.where(inside[..., None], p, np.eye(c, dtype=np.float32)[SILENCE])
        return (1 - self.eps) * p + np.float32(self.eps / c)

    def boundary_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Points on the model's class boundaries, in the reference frame.

        Returns
        -------
        edges : (n, 2) ndarray
            Midpoints between horizontally or vertically adjacent cells of different classes.
        corners : (m, 2) ndarray
            Shared vertices of 2 x 2 cell blocks holding at least three classes (key corners).
        """
        cl = self.argmax()
        s = self.step
        ox, oy = self.origin
        iy, ix = np.nonzero(cl[:, 1:] != cl[:, :-1])
        e1 = np.column_stack([ox + (ix + 0.5) * s, oy + iy * s])
        iy, ix = np.nonzero(cl[1:, :] != cl[:-1, :])
        e2 = np.column_stack([ox + ix * s, oy + (iy + 0.5) * s])
        a, b, c, d = cl[:-1, :-1], cl[:-1, 1:], cl[1:, :-1], cl[1:, 1:]
        distinct = (1 + (b != a) + ((c != a) & (c != b)) + ((d != a) & (d != b) & (d != c)))
        iy, ix = np.nonzero(distinct >= 3)
        corners = np.column_stack([ox + (ix + 0.5) * s, oy + (iy + 0.5) * s])
        return np.vstack([e1, e2]), corners
