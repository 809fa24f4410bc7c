"""The posterior over the keyboard's displacement: Eq. 7 (one KDE per observation) and Eq. 8 (their
product), on a hypothesis grid, in log space (paper Sect. III-D, Algorithm 2).

Representation
--------------
The transform parameters live on a regular **hypothesis grid** (:class:`HypothesisGrid`):
``dx, dy`` in ``[-prior_halfwidth, +prior_halfwidth]`` at ``resolution`` px (default +-45 px at
0.5 px: 181 x 181 = 32,761 cells), and for the ``rigid`` family an extra angle axis in
``[-max_angle, +max_angle]`` at ``angle_resolution`` degrees (default +-5 deg at 0.25 deg: 41 angles,
1,343,201 cells; 0.5 deg, 21 angles, is twice as fast and reached the 0.5 deg target slightly less
often in our trials). Array layout is ``[angle,] dy, dx`` (image order: row = dy, column = dx). The prior is
uniform over the grid. The posterior (:class:`Posterior`, immutable: ``update`` returns a new one)
holds the normalised log-probability of every cell; the product of Eq. 8 is a sum of per-observation
log terms, exact on the grid (no resampling, no product sampling), normalised with ``logsumexp``.

Two per-observation terms, one code path for both families
----------------------------------------------------------
- ``likelihood`` (ours, the default): ``log p_eps(s_t | T_h^-1(a_t))`` for every cell h, read from a
  :class:`LikelihoodTable` (the model's ``p(sound | action)`` rasterised once per adaptation; for the
  exact model a class map, for a learned model its probability raster). The points ``T_h^-1(a_t)``
  over a translation grid form a flipped window of the raster, so the update is one vectorised
  gather (< 1 ms for 32k cells). ``p_eps = (1 - eps) p + eps / C`` is an outlier floor: a touch that
  contradicts the truth (a grid cell a quarter pixel off, a mislabelled learned region, an unknown
  landing) costs ``log(eps / C)`` instead of zeroing the truth. When the robot knows only where it
  *aimed* (not where it landed), the table is the raster blurred by the reach noise, which is exactly
  ``p(s | aim, h) = int N(x; aim, sigma^2) p(s | T_h^-1 x) dx``.
  A grid cell stands for a box of hypotheses, not a point: read at its centre, a thin feasible
  region between cell centres would leave every cell "violating" some touch and the posterior
  would settle confidently on a wrong cell. For the rigid family, where one angle step moves a far
  key by more than a raster cell, the term is therefore *cell-averaged*: the model's map of the
  heard class is blurred (in a window around the touched region) by the spread of ``T_h^-1(a_t)``
  within one cell (:func:`cell_sigma`) and read on a raster of half the grid step. For translation
  at 0.5 px that spread (0.14 px) is below the raster cell and the map is read as it is.
- ``kde`` (the paper's Eq. 7, Algorithm 2): draw ``N`` actions ``a_i ~ p(action | s_t)`` from the
  model, map each onto ``a_t`` with ``computeTransform`` (:func:`kbcli.core.transforms.
  translation_mapping`; for the rigid family, once per grid angle), bin the hypotheses linearly onto
  the grid and convolve with a Gaussian kernel by FFT (:func:`binned_kde`, ``scipy.fft``, O(G log G),
  the binned-KDE trick of fast KDE libraries; checked against the direct sum in the tests), then mix
  with the same outlier floor (a uniform density over the prior with weight ``eps``) and take the
  log. The samples of ``p(action | s)`` do not depend on the posterior, so they are drawn once per
  sound class and reused (:class:`ActionSamples`; per run, or per model in the evaluation): a KDE
  step then costs a binning and two FFTs (a few ms) instead of thousands of model evaluations.
  Bandwidth rule: Scott's ``sigma_hat * N^(-1/6)``
  (d = 2) with Silverman's robust spread ``sigma_hat = min(std, IQR / 1.349)`` averaged over both axes
  of the sampled actions, clipped to ``[resolution, max_bandwidth]`` (default 4 px: the rule
  over-smooths multi-modal samples such as silence, a ring around the keyboard). The angle axis is
  not smoothed: each angle slice is its own 2-D KDE. With a uniform prior over actions, ``KDE_t`` is
  a sampled and smoothed version of the likelihood term above, which the benchmark compares. One
  limitation is inherited from Algorithm 2: actions for a silence are drawn from the model's
  working area only, so hypotheses that put the touch beyond it get the floor, not the silence
  they would in fact give (the likelihood term knows the outside is silent).

Estimates: the maximum-likelihood (maximum a posteriori under the flat prior) cell, the posterior
mean (from the per-axis marginals), the entropy of the cell distribution in nats (``log G`` for the
prior: it depends on the resolution, compare at equal grids), the mass within a radius.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sfft
from scipy.ndimage import gaussian_filter

from kbcli.core import transforms
from kbcli.core.model import SILENCE, ExactModel, grid_points

#: Classes kept per raster cell of a soft table for the strategies' predictive distributions (a
#: learned model mixes two sounds at an edge; a blurred exact map up to four at a key corner).
TOP_K = 4

#: Working bytes per hypothesis cell: posterior log-probabilities and probabilities (float64), one
#: update term, and the float / int index temporaries of a gather.
BYTES_PER_CELL = 56


# ---------------------------------------------------------------------------------------------
# The hypothesis grid
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HypothesisGrid:
    """A regular grid over the transform parameters of ``family`` (the uniform prior's support).

    Attributes
    ----------
    family : str
        ``translation`` or ``rigid``.
    dx, dy : (n,) ndarray
        Translation values, px (the same for both axes).
    angles : (A,) ndarray
        Angle values, degrees (``[0.0]`` for translation).
    centre : (2,) ndarray
        Rotation centre of the family (the keyboard centre at its reference pose).
    """

    family: str
    dx: np.ndarray
    dy: np.ndarray
    angles: np.ndarray
    centre: np.ndarray

    @classmethod
    def build(
        cls,
        family: str,
        *,
        prior_halfwidth: float,
        resolution: float,
        centre: np.ndarray,
        max_angle: float = 0.0,
        angle_resolution: float = 0.5,
    ) -> HypothesisGrid:
        """A grid of ``+-prior_halfwidth`` px at ``resolution`` (and ``+-max_angle`` degrees)."""
        transforms.check_family(family)
        n = grid_cells_per_axis(prior_halfwidth, resolution)
        t = (np.arange(n) - (n - 1) / 2) * resolution
        if family == "rigid":
            na = grid_cells_per_axis(max_angle, angle_resolution)
            angles = (np.arange(na) - (na - 1) / 2) * angle_resolution
        else:
            angles = np.zeros(1)
        return cls(family, t, t.copy(), angles, np.asarray(centre, float))

    @property
    def resolution(self) -> float:
        return float(self.dx[1] - self.dx[0]) if len(self.dx) > 1 else 1.0

    @property
    def rigid(self) -> bool:
        return self.family == "rigid"

    @property
    def shape(self) -> tuple[int, ...]:
        """``(dy, dx)`` or ``(angle, dy, dx)``."""
        s = (len(self.dy), len(self.dx))
        return (len(self.angles),) + s if self.rigid else s

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def n_params(self) -> int:
        return 3 if self.rigid else 2

    def params(self, index: np.ndarray) -> np.ndarray:
        """Parameters of flat cell indices, (k,) -> (k, P) in family order (``[angle,] dx, dy``)."""
        idx = np.unravel_index(np.asarray(index, dtype=np.int64), self.shape)
        if self.rigid:
            return np.column_stack([self.angles[idx[0]], self.dx[idx[2]], self.dy[idx[1]]])
        return np.column_stack([self.dx[idx[1]], self.dy[idx[0]]])

    def index_of(self, params: np.ndarray) -> int:
        """Flat index of the cell nearest to ``params`` (P,) (clipped into the grid)."""
        p = np.asarray(params, float)
        res = self.resolution

        def near(values: np.ndarray, v: float, step: float) -> int:
            return int(np.clip(np.rint((v - values[0]) / step), 0, len(values) - 1))

        ix = near(self.dx, p[-2], res)
        iy = near(self.dy, p[-1], res)
        if self.rigid:
            step = float(self.angles[1] - self.angles[0]) if len(self.angles) > 1 else 1.0
            ia = near(self.angles, p[0], step)
            return int(np.ravel_multi_index((ia, iy, ix), self.shape))
        return int(np.ravel_multi_index((iy, ix), self.shape))


def grid_cells_per_axis(halfwidth: float, step: float) -> int:
    """Cells of a symmetric axis ``[-halfwidth, +halfwidth]`` at ``step`` (odd, centred on 0)."""
    return 2 * int(math.floor(halfwidth / step + 1e-9)) + 1


def grid_bytes(family: str, prior_halfwidth: float, resolution: float, max_angle: float,
               angle_resolution: float) -> tuple[int, int]:
    """(cells, working bytes) of the hypothesis grid a config asks for."""
    n = grid_cells_per_axis(prior_halfwidth, resolution)
    cells = n * n
    if family == "rigid":
        cells *= grid_cells_per_axis(max_angle, angle_resolution)
    return cells, cells * BYTES_PER_CELL


# ---------------------------------------------------------------------------------------------
# The model, rasterised
# ---------------------------------------------------------------------------------------------
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
        if isinstance(model, ExactModel) and blur == 0:
            origin, pts = grid_points(area, step)
            cl = model.predict_class(pts.reshape(-1, 2)).reshape(pts.shape[:2])
            return cls(origin, float(step), n_classes, eps, classes=cl.astype(np.int16))
        if isinstance(model, ExactModel):
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


# ---------------------------------------------------------------------------------------------
# Per-observation terms (Eq. 7 and the likelihood)
# ---------------------------------------------------------------------------------------------
def _inverse_coords(grid: HypothesisGrid, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of ``T_h^-1(action)`` for every cell, each broadcastable to ``grid.shape``."""
    a = np.asarray(action, float)
    if not grid.rigid:
        return (a[0] - grid.dx)[None, :], (a[1] - grid.dy)[:, None]
    th = np.deg2rad(grid.angles)[:, None, None]
    c, s = np.cos(th), np.sin(th)
    u = a - grid.centre  # T^-1(a) = R(-th)(a - centre - d) + centre
    dx = grid.dx[None, None, :]
    dy = grid.dy[None, :, None]
    ex = (u[0] - dx).astype(np.float32)
    ey = (u[1] - dy).astype(np.float32)
    c32, s32 = c.astype(np.float32), s.astype(np.float32)
    x = c32 * ex + s32 * ey
    x += np.float32(grid.centre[0])
    y = c32 * ey - s32 * ex
    y += np.float32(grid.centre[1])
    return x, y


def cell_sigma(grid: HypothesisGrid, action: np.ndarray) -> float:
    """Std (px) of ``T_h^-1(action)`` over one grid cell (uniform within the cell).

    A cell stands for a box of hypotheses, not a point: its translation spans ``resolution`` px on
    each axis (std ``resolution / sqrt(12)``) and, for the rigid family, its angle spans
    ``angle_resolution``, which moves the point by ``r * dtheta`` tangentially, with ``r`` the
    distance of the action from the rotation centre.
    """
    var = grid.resolution**2 / 12
    if grid.rigid and len(grid.angles) > 1:
        r = float(np.hypot(*(np.asarray(action, float) - grid.centre)))
        var += (r * np.deg2rad(grid.angles[1] - grid.angles[0])) ** 2 / 12
    return math.sqrt(var)


def likelihood_term(grid: HypothesisGrid, table: LikelihoodTable, action: np.ndarray,
                    cls: int, sigma: float = 0.0) -> np.ndarray:
    """``log p_eps(cls | T_h^-1(action))`` for every cell h: an array of ``grid.shape``.

    Parameters
    ----------
    sigma : float
        Std (px) of an isotropic Gaussian the model's map is blurred by before it is read (the
        cell-averaged likelihood, see :func:`cell_sigma`). Below half a raster cell it is ignored
        and the raster is read as it is.
    """
    x, y = _inverse_coords(grid, action)
    if sigma < 0.5 * table.step:
        return np.broadcast_to(table.log_prob(x, y, cls), grid.shape)
    pad = 4 * sigma
    x0, x1 = float(np.min(x)) - pad, float(np.max(x)) + pad
    y0, y1 = float(np.min(y)) - pad, float(np.max(y)) + pad
    patch, org = table.window(cls, (x0, y0, x1, y1))
    patch = gaussian_filter(patch, sigma / table.step, mode="nearest", truncate=4.0)
    logpatch = np.log((1 - table.eps) * patch + table.eps / table.n_classes)
    h, w = patch.shape
    col = _cell_index(x, org[0], table.step, w)
    row = _cell_index(y, org[1], table.step, h)
    return np.broadcast_to(logpatch[row, col], grid.shape)


def _cell_index(v: np.ndarray, origin: float, step: float, n: int) -> np.ndarray:
    """Nearest cell index of coordinates ``v`` on an axis of ``n`` cells, clipped into range."""
    u = np.subtract(v, origin, dtype=np.float32 if v.size > 4096 else float)
    u /= step
    np.rint(u, out=u)
    idx = u.astype(np.intp)
    np.clip(idx, 0, n - 1, out=idx)
    return idx


def scott_bandwidth(samples: np.ndarray) -> float:
    """Scott's rule for a 2-D sample, ``sigma_hat * n^(-1/6)``, with Silverman's robust spread."""
    n = len(samples)
    std = samples.std(axis=0)
    q75, q25 = np.percentile(samples, [75, 25], axis=0)
    sig = np.minimum(std, (q75 - q25) / 1.349)
    sig = np.where(sig > 0, sig, std)
    return float(np.mean(sig) * n ** (-1 / 6))


class ActionSamples:
    """Samples of ``p(action | sound)`` per sound class, drawn once and reused (Algorithm 2, line 3).

    The actions that produce a sound do not depend on the posterior, so Algorithm 2's
    ``sampleFrom(p(a | s_t, M_INST))`` needs no fresh draw at every touch: each class's ``n_samples``
    actions (and their bandwidth) are drawn the first time the class is heard and kept. Each class
    draws from its own generator, ``default_rng(SeedSequence([seed, cls]))``, so the samples do not
    depend on the order in which classes are heard: one cache can serve every run of a model (as the
    evaluation does, per process) and still give the same numbers on any worker.

    Parameters
    ----------
    model : SoundModel
        ``sample_actions(cls, n, rng)`` draws from p(action | sound).
    n_samples : int
        N, actions per class.
    seed : int or sequence of int
        Root of the per-class generators.
    bandwidth : float, optional
        Kernel std in px for every class; None: the rule of the module docstring per class.
    resolution : float
        The hypothesis grid step (the bandwidth rule's lower clip).
    max_bandwidth : float
        The bandwidth rule's upper clip, px.
    """

    def __init__(self, model, n_samples: int, seed, *, bandwidth: float | None = None,
                 resolution: float = 0.5, max_bandwidth: float = 4.0) -> None:
        self.model = model
        self.n_samples = int(n_samples)
        self.seed = [int(v) for v in np.atleast_1d(seed)]
        self.bandwidth = bandwidth
        self.resolution = float(resolution)
        self.max_bandwidth = float(max_bandwidth)
        self._cache: dict[int, tuple[np.ndarray, float]] = {}

    def get(self, cls: int) -> tuple[np.ndarray, float]:
        """``(samples (N, 2), bandwidth px)`` of class ``cls`` (drawn on first use)."""
        cls = int(cls)
        if cls not in self._cache:
            rng = np.random.default_rng(np.random.SeedSequence([*self.seed, cls]))
            s = np.asarray(self.model.sample_actions(cls, self.n_samples, rng), float)
            bw = self.bandwidth
            if bw is None:
                res = self.resolution
                bw = float(np.clip(scott_bandwidth(s), res, max(res, self.max_bandwidth)))
            self._cache[cls] = (s, float(bw))
        return self._cache[cls]

    def __len__(self) -> int:
        return len(self._cache)

    def draw(self, cls: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) actions resampled (with replacement) from class ``cls``'s samples: draws from
        the empirical p(action | sound) of N model samples, without calling the model again."""
        s, _ = self.get(cls)
        return s[rng.integers(len(s), size=int(n))]


@functools.lru_cache(maxsize=64)
def _kernel_fft(sig: float, pad: int, size: int) -> np.ndarray:
    """rFFT of the Gaussian kernel of std ``sig`` cells, truncated to ``|offset| <= pad`` taps and
    laid out circularly on a ``size x size`` grid (offset 0 at index 0), as a density per cell
    (the caller divides by ``res^2``)."""
    k1 = np.zeros(size)
    off = np.arange(-pad, pad + 1)
    k1[off % size] = np.exp(-0.5 * (off / sig) ** 2) / (math.sqrt(2 * math.pi) * sig)
    return sfft.rfft2(np.outer(k1, k1).astype(np.float32))


def binned_kde(points: np.ndarray, x0: float, y0: float, res: float, n: int,
               bandwidth: float) -> np.ndarray:
    """Gaussian KDE of 2-D points on an ``n x n`` grid by linear binning and FFT convolution.

    ``density[..., i, j] ~= mean_k N((x0 + j res, y0 + i res); points[..., k, :], bandwidth^2 I)``,
    the direct sum of the paper's Eq. 7 (with a Gaussian ``K``). Points are linearly binned onto the
    grid widened by the kernel's reach (``4 bandwidth``, so points just outside the grid still count)
    and convolved with the kernel by ``scipy.fft`` (O(G log G); the kernel's transform is cached per
    bandwidth). The kernel is truncated at 4 standard deviations.

    Parameters
    ----------
    points : (..., N, 2) ndarray
        One or more (leading axes) sets of points, px.
    x0, y0 : float
        Coordinates of grid cell (0, 0) (column 0 is ``x0``, row 0 is ``y0``).
    res : float
        Grid step, px.
    n : int
        Cells per axis.
    bandwidth : float
        Kernel std, px.

    Returns
    -------
    (..., n, n) ndarray
        Density per px^2 (rows y, columns x).
    """
    pts = np.asarray(points, float)
    lead = pts.shape[:-2]
    pts = pts.reshape((-1,) + pts.shape[-2:])
    b, npts = pts.shape[0], pts.shape[1]
    sig = bandwidth / res
    pad = int(math.ceil(4 * sig))
    m = n + 2 * pad  # widened grid
    # a circular convolution of period >= m gives the inner n x n cells without wrap-around
    size = sfft.next_fast_len(m, real=True)
    u = (pts[..., 0] - x0) / res + pad
    v = (pts[..., 1] - y0) / res + pad
    iu = np.floor(u).astype(np.int64)
    iv = np.floor(v).astype(np.int64)
    fu = u - iu
    fv = v - iv
    ok = (iu >= 0) & (iu < m - 1) & (iv >= 0) & (iv < m - 1)
    base = (np.arange(b)[:, None] * m + iv) * m + iu
    base, fu, fv = base[ok], fu[ok], fv[ok]
    nb = b * m * m
    idx = np.concatenate([base, base + 1, base + m, base + m + 1])
    w = np.concatenate([(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv])
    counts = np.bincount(idx, w, nb).reshape(b, m, m).astype(np.float32)
    # single precision: the density's rounding (~1e-7 of its peak) is far below the outlier floor
    spec = sfft.rfft2(counts, s=(size, size), axes=(1, 2))
    spec *= _kernel_fft(float(sig), pad, size)[None]
    full = sfft.irfft2(spec, s=(size, size), axes=(1, 2))
    dens = full[:, pad:pad + n, pad:pad + n]
    dens = np.maximum(dens, 0.0, dtype=np.float64) / (npts * res * res)
    return dens.reshape(lead + (n, n))


def kde_term(grid: HypothesisGrid, model, action: np.ndarray, cls: int,
             rng: np.random.Generator | None = None, *, n_samples: int, eps: float,
             bandwidth: float | None = None, max_bandwidth: float = 4.0,
             samples: ActionSamples | None = None) -> tuple[np.ndarray, float]:
    """``log KDE_t(h)`` of Algorithm 2 / Eq. 7 on the grid, with the outlier floor.

    Parameters
    ----------
    model : SoundModel
        ``sample_actions(cls, n, rng)`` draws from p(action | sound).
    action : (2,) ndarray
        Where the finger touched.
    cls : int
        The perceived sound class (0: silence, itself an observation).
    rng : numpy.random.Generator, optional
        Draws fresh samples when no ``samples`` cache is given.
    n_samples : int
        N, actions drawn from the model (ignored with ``samples``: the cache's N).
    bandwidth : float, optional
        Kernel std in px; None: the rule in the module docstring.
    samples : ActionSamples, optional
        Per-class samples drawn once (:class:`ActionSamples`); the fast path.

    Returns
    -------
    logkde : ndarray of ``grid.shape``
    bandwidth : float
        The bandwidth used, px.
    """
    res = grid.resolution
    if samples is not None:
        drawn, bw = samples.get(int(cls))
        bandwidth = bw if bandwidth is None else bandwidth
    else:
        if rng is None:
            raise ValueError("kde_term needs an rng or an ActionSamples cache")
        drawn = np.asarray(model.sample_actions(int(cls), int(n_samples), rng), float)
        if bandwidth is None:
            bandwidth = float(np.clip(scott_bandwidth(drawn), res, max(res, max_bandwidth)))
    a = np.asarray(action, float)
    # computeTransform(a_i, a_t) for every grid angle: (A, N, 2)
    if grid.rigid:
        hyp = np.stack([transforms.translation_mapping(grid.family, float(th), drawn, a,
                                                       grid.centre) for th in grid.angles])
    else:
        hyp = (a - drawn)[None]
    dens = binned_kde(hyp, float(grid.dx[0]), float(grid.dy[0]), res, len(grid.dx),
                      float(bandwidth))
    prior_density = 1.0 / (float(grid.dx[-1] - grid.dx[0]) + res) ** 2
    out = np.log((1 - eps) * dens + eps * prior_density)
    return out.reshape(grid.shape), float(bandwidth)


# ---------------------------------------------------------------------------------------------
# The posterior (Eq. 8)
# ---------------------------------------------------------------------------------------------
class Posterior:
    """A normalised log-posterior on a :class:`HypothesisGrid`; immutable, ``update`` returns a new one.

    Attributes
    ----------
    grid : HypothesisGrid
    logp : ndarray of ``grid.shape``
        Normalised log-probability of every cell (``logsumexp(logp) == 0``).
    probs : ndarray of ``grid.shape``
        ``exp(logp)``.
    """

    __slots__ = ("grid", "logp", "probs", "_entropy", "n_obs", "_ml", "_marg")

    def __init__(self, grid: HypothesisGrid, logp: np.ndarray, n_obs: int = 0) -> None:
        logp = np.asarray(logp, float).reshape(grid.shape)
        m = float(np.max(logp))
        if not np.isfinite(m):
            raise ValueError("a posterior needs at least one cell of finite log-probability")
        p = np.exp(logp - m)
        total = float(p.sum())
        logp = logp - (m + math.log(total))
        p /= total
        logp.setflags(write=False)
        p.setflags(write=False)
        self.grid = grid
        self.logp = logp
        self.probs = p
        self.n_obs = n_obs
        # logp is finite everywhere (the outlier floor), so underflowed cells add 0 * finite
        self._entropy = float(-np.einsum("i,i->", p.reshape(-1), logp.reshape(-1)))
        self._ml: int | None = None
        self._marg: tuple | None = None

    @classmethod
    def uniform(cls, grid: HypothesisGrid) -> Posterior:
        """The flat prior over the grid."""
        return cls(grid, np.zeros(grid.shape))

    def update(self, term: np.ndarray) -> Posterior:
        """Multiply in one observation's term (Eq. 8: add its log)."""
        return Posterior(self.grid, self.logp + term, self.n_obs + 1)

    # -- summaries -------------------------------------------------------------------------------
    def entropy(self) -> float:
        """Entropy of the cell distribution, nats."""
        return self._entropy

    def ml_index(self) -> int:
        """Flat index of the most probable cell."""
        if self._ml is None:
            self._ml = int(np.argmax(self.probs))
        return self._ml

    def ml(self) -> np.ndarray:
        """(P,) parameters of the most probable cell (the paper's maximum-likelihood hypothesis)."""
        return self.grid.params(np.array([self.ml_index()]))[0]

    def ml_prob(self) -> float:
        """Probability of the most probable cell."""
        return float(self.probs.reshape(-1)[self.ml_index()])

    def marginals(self) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
        """Marginals over angle (or None), dx and dy."""
        if self._marg is None:
            p = self.probs
            if self.grid.rigid:
                t = p.sum(axis=0)
                self._marg = (p.sum(axis=(1, 2)), t.sum(axis=0), t.sum(axis=1))
            else:
                self._marg = (None, p.sum(axis=0), p.sum(axis=1))
        return self._marg

    def translation_marginal(self) -> np.ndarray:
        """(n_dy, n_dx) posterior of the translation, summed over angles."""
        return self.probs.sum(axis=0) if self.grid.rigid else self.probs

    def mean(self) -> np.ndarray:
        """(P,) posterior mean."""
        pa, px, py = self.marginals()
        m = [float((px * self.grid.dx).sum()), float((py * self.grid.dy).sum())]
        if pa is not None:
            m.insert(0, float((pa * self.grid.angles).sum()))
        return np.array(m)

    def mass_within(self, centre: np.ndarray, radius: float, angle_radius: float = np.inf) -> float:
        """Posterior mass within ``radius`` px of ``centre``'s translation (and ``angle_radius``
        degrees of its angle, rigid family)."""
        c = np.asarray(centre, float)
        g = self.grid
        near = ((g.dx[None, :] - c[-2]) ** 2 + (g.dy[:, None] - c[-1]) ** 2) <= radius**2
        if not g.rigid:
            return float(self.probs[near].sum())
        ang = np.abs(g.angles - c[0]) <= angle_radius
        return float(self.probs[ang][:, near].sum())

    # -- hypotheses for the strategies -----------------------------------------------------------
    def support(self, tol: float = 1e-6) -> np.ndarray:
        """Flat indices of the cells that hold all but at most ``tol`` of the mass.

        Cells below ``tol / G`` are dropped (together at most ``tol``): O(G), no sort.
        """
        return np.flatnonzero(self.probs.reshape(-1) > tol / self.grid.size)

    def sample_hypotheses(self, k: int, rng: np.random.Generator,
                          tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
        """A weighted set of at most ``k`` cells standing for the posterior.

        The support itself (exact weights) when it has at most ``k`` cells; otherwise ``k``
        systematic-resampling draws from it, merged into distinct cells weighted by their counts.

        Returns
        -------
        index : (m,) int ndarray
            Flat cell indices, m <= k.
        weights : (m,) ndarray
            Summing to one.
        """
        sup = self.support(tol)
        p = self.probs.reshape(-1)[sup]
        if len(sup) <= k:
            return sup, p / p.sum()
        c = np.cumsum(p)
        pos = (rng.random() + np.arange(k)) / k * c[-1]
        pick = np.minimum(np.searchsorted(c, pos, side="right"), len(sup) - 1)
        idx, counts = np.unique(pick, return_counts=True)
        return sup[idx], counts / counts.sum()
