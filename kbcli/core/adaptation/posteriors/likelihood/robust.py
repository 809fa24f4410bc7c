"""A posterior that learns how far to trust the model: Eq. 8 with model error marginalised.

The plain likelihood posterior (:mod:`kbcli.core.adaptation.posteriors.posterior`) reads ``p(s_t | T_h^-1(a_t))`` from
the model as if the model were the instrument. A learned model is not: its boundaries can sit a few
px off, a region can carry the wrong sound, and an arm that feels its landing imperfectly blurs
both. Trusting such a model, the posterior multiplies in touches that contradict it, becomes
overconfident and locks onto a wrong displacement; infogain makes it worse by seeking exactly the
boundaries the model has wrong.

Here the observation model has two unknowns, treated like the displacement itself:

- a **boundary blur** ``sigma`` (px): the instrument is the model's map convolved with an isotropic
  Gaussian of std ``sigma`` (its edges are known only to about ``sigma``);
- an **outlier rate** ``eps``: a touch's sound is, with probability ``eps``, unrelated to the map
  (uniform over the C sounds).

``p(s | a, h, sigma, eps) = (1 - eps) [p_model * N(0, sigma^2)](s | T_h^-1 a) + eps / C``.

Both live on a small grid (default ``sigma`` in {0, 1, 2.5, 5} px, ``eps`` in {0.001, 0.02, 0.1}),
with a uniform prior, and are marginalised exactly, online: for every nuisance value ``k`` the
posterior keeps the log-likelihood ``L_k(h) = sum_t log p(s_t | a_t, h, k)`` of every hypothesis
(K arrays of the hypothesis grid), so

``p(h | D) = sum_k pi_k exp(L_k(h)) / Z`` and ``p(k | D) = pi_k sum_h exp(L_k(h)) / Z``.

No knob is set by hand: the evidence picks the blur and the outlier rate. A sharp, correct model
keeps its sharp component (a sharper likelihood earns more evidence when the touches agree with
it, Occam's razor); when touches contradict the map, the weight moves to the blurred and
outlier-tolerant components, and the posterior widens instead of locking on. The strategies plan
with the model as the posterior currently believes it (:func:`planning_table`: the map blurred by
the most probable ``sigma``, floored at the most probable ``eps``), so infogain stops chasing
boundaries the touches say the model does not know.

**A learning rate for a weak model (a coarsened, tempered posterior).** The blur and the outlier
rate treat each touch's error as independent of the next one's. A learned model's is not: where its
boundary sits 5 px off it is wrong for every touch there, and a weak model (100-200 reaches) is
wrong in many places at once. Multiplied in at full weight, its touches make the posterior lock onto
a wrong displacement, and infogain, planning with that posterior, drills at the spots where the
model is wrong (measured on the model-quality sweep's 100- to 200-reach models: infogain ended
6-24 px off, worse than random touches). After ``n`` touches the log-likelihood is therefore
multiplied by a learning rate ``zeta_n = alpha / (alpha + n)`` (the *coarsened posterior* of Miller
and Dunson 2019, "Robust Bayesian inference via coarsening"; Grünwald and van Ommen 2017 on why a
rate below 1 repairs Bayes under misspecification): the first touches count almost in full, and
however many follow, the posterior is never sharper than about ``alpha`` touches' worth, which a
wrong model cannot turn into certainty. ``alpha`` is resolved from the model's own cross-validated
boundary error ``b`` (:func:`kbcli.core.adaptation.loop.learning_rate`) through the rate ``eta`` reached at
``HORIZON`` (30) touches, ``eta = min(1, (TEMPER_PX / b)^2)`` — the share of a ``b``-wide patch of
the model that a ``TEMPER_PX``-wide one is, as if touches within ``b`` of each other repeated one
observation — so ``alpha = HORIZON eta / (1 - eta)``. A model that knows its edges to 1.5 px or
better (the embedded default model: 1.06 px) keeps ``eta = 1``: plain Bayes, untempered. (A fixed
rate ``eta`` for every touch ends as close but takes longer to get there: on the sweep's active-200
model, infogain's median touches to twice its boundary error on large moves 8 instead of 3.)

Cost: one window of the model's map around the touched region is blurred once per ``sigma`` level
(``scipy.ndimage.gaussian_filter``) and gathered for the whole hypothesis grid; each ``eps`` level
is one ``log``. With the default 12 nuisance values a translation step costs a few ms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import correlate1d

from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.likelihood.term import cell_index, inverse_coords
from kbcli.core.adaptation.posteriors.posterior import Posterior
from kbcli.core.model.sounds import SILENCE
from kbcli.core.model.table import LikelihoodTable

#: The adapter's options only the robust posterior reads (``AdapterConfig``).
ROBUST_OPTIONS = ("robust_blurs", "robust_outliers", "robust_eta", "redundancy_radius")
#: Default nuisance grids: boundary blur (px) and outlier rate.
DEFAULT_BLURS = (0.0, 1.0, 2.5, 5.0)
DEFAULT_OUTLIERS = (0.001, 0.02, 0.1)
#: ... for the rigid family, whose hypothesis grid is 41 times larger: outliers only.
RIGID_BLURS = (0.0,)
RIGID_OUTLIERS = (0.001, 0.05)
#: A model whose own boundary error is at most this (px) keeps the untempered posterior.
TEMPER_PX = 1.5
#: Touches at which the coarsened posterior's learning rate has fallen to ``eta``.
HORIZON = 30.0
#: Cells this many nats below the most probable one are negligible (exp(-50) ~ 2e-22).
NEGLIGIBLE = 50.0


@dataclass(frozen=True)
class Nuisance:
    """The grid of model-error values marginalised over, and their prior.

    Attributes
    ----------
    blurs : (S,) ndarray
        Boundary blurs, px.
    outliers : (E,) ndarray
        Outlier rates in (0, 1).
    log_prior : (S, E) ndarray
        Normalised log prior of each pair (uniform by default).
    """

    blurs: np.ndarray
    outliers: np.ndarray
    log_prior: np.ndarray

    @classmethod
    def build(cls, blurs=DEFAULT_BLURS, outliers=DEFAULT_OUTLIERS) -> Nuisance:
        b = np.asarray(sorted(set(float(v) for v in blurs)), float)
        e = np.asarray(sorted(set(float(v) for v in outliers)), float)
        if len(b) == 0 or len(e) == 0 or (b < 0).any() or not np.isfinite(b).all():
            raise ValueError("blurs must be a non-empty list of finite px >= 0")
        if ((e <= 0) | (e >= 1)).any():
            raise ValueError("outliers must be rates in (0, 1)")
        lp = np.full((len(b), len(e)), -math.log(len(b) * len(e)))
        return cls(b, e, lp)

    @property
    def size(self) -> int:
        return len(self.blurs) * len(self.outliers)


def robust_terms(grid: HypothesisGrid, table: LikelihoodTable, action: np.ndarray, cls: int,
                 nuisance: Nuisance, cell_sigma: float = 0.0) -> np.ndarray:
    """``log p(cls | action, h, sigma, eps)`` for every hypothesis cell and nuisance value.

    Parameters
    ----------
    table : LikelihoodTable
        The model's map (its own ``eps`` is not used: the outlier rates are ``nuisance``'s).
    cell_sigma : float
        Extra blur (px) standing for the spread of a grid cell (rigid family).

    Returns
    -------
    (S * E, *grid.shape) float32 ndarray
        Nuisance values in row-major (blur, outlier) order.
    """
    x, y = inverse_coords(grid, action)
    c = table.n_classes
    s_n, e_n = len(nuisance.blurs), len(nuisance.outliers)
    out = np.empty((s_n, e_n) + grid.shape, np.float32)
    reads: list[np.ndarray] = []
    patch = None
    for s in nuisance.blurs:
        s = float(s)
        if cell_sigma < 0.5 * table.step or s >= 2 * cell_sigma:
            # a precomputed blurred map (a grid cell's own spread, if any, is lost in the blur:
            # hypot(s, cell_sigma) <= 1.12 s)
            reads.append(raw_prob(blurred_map(table, s), x, y, cls))
            continue
        if patch is None:  # blur a window around the touched region (rigid: varies per touch)
            step = table.step
            pad = 4 * math.hypot(s, cell_sigma) + 2 * step
            x0, x1 = float(np.min(x)) - pad, float(np.max(x)) + pad
            y0, y1 = float(np.min(y)) - pad, float(np.max(y)) + pad
            patch, org = table.window(cls, (x0, y0, x1, y1))
            h, w = patch.shape
            col = cell_index(x, org[0], step, w)
            row = cell_index(y, org[1], step, h)
        reads.append(_blurred_read(patch, row, col, math.hypot(s, cell_sigma) / table.step))
    for i, v in enumerate(reads):
        v = np.broadcast_to(v, grid.shape)
        for j, e in enumerate(nuisance.outliers):
            out[i, j] = v
            out[i, j] *= np.float32(1 - e)
            out[i, j] += np.float32(e / c)
    np.log(out, out=out)
    return out.reshape((s_n * e_n,) + grid.shape)


def _kernel(sig: float) -> np.ndarray:
    """A normalised Gaussian kernel of std ``sig`` cells, truncated at 4 std (float32)."""
    half = max(1, int(math.ceil(4 * sig)))
    k = np.exp(-0.5 * (np.arange(-half, half + 1) / sig) ** 2)
    return (k / k.sum()).astype(np.float32)


def _blurred_read(patch: np.ndarray, row: np.ndarray, col: np.ndarray, sig: float) -> np.ndarray:
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


class RobustPosterior:
    """The posterior over the transform with the model's error marginalised (module docstring).

    Immutable: :meth:`update` returns a new one.

    Attributes
    ----------
    grid : HypothesisGrid
    nuisance : Nuisance
    loglik : (K, *grid.shape) float32 ndarray
        Accumulated log-likelihood of every hypothesis under each nuisance value.
    n_obs : int
    eta : float
        Learning rate in (0, 1] the log-likelihood is tempered with after ``HORIZON`` touches (1:
        plain Bayes); after ``n`` touches, ``zeta = alpha / (alpha + n)`` with ``alpha = HORIZON
        eta / (1 - eta)`` (:attr:`rate`). ``loglik`` is kept untempered.
    """

    __slots__ = ("grid", "nuisance", "loglik", "n_obs", "eta", "_marginal", "_weights")

    def __init__(self, grid: HypothesisGrid, nuisance: Nuisance, loglik: np.ndarray | None = None,
                 n_obs: int = 0, eta: float = 1.0) -> None:
        if not (0.0 < float(eta) <= 1.0):
            raise ValueError(f"eta must lie in (0, 1], got {eta!r}")
        self.eta = float(eta)
        self.grid = grid
        self.nuisance = nuisance
        if loglik is None:
            loglik = np.zeros((nuisance.size,) + grid.shape, np.float32)
        loglik.setflags(write=False)
        self.loglik = loglik
        self.n_obs = n_obs
        self._marginal: Posterior | None = None
        self._weights: np.ndarray | None = None

    def update(self, terms: np.ndarray) -> RobustPosterior:
        """Add one observation's terms ((K, *grid.shape), from :func:`robust_terms`)."""
        return RobustPosterior(self.grid, self.nuisance, self.loglik + terms, self.n_obs + 1,
                               self.eta)

    @property
    def rate(self) -> float:
        """The learning rate the posterior now tempers ``loglik`` with: ``alpha / (alpha + n)``,
        ``alpha = HORIZON eta / (1 - eta)`` (1 when ``eta`` is 1)."""
        if self.eta >= 1.0:
            return 1.0
        alpha = HORIZON * self.eta / (1.0 - self.eta)
        return alpha / (alpha + self.n_obs)

    def _summarise(self) -> None:
        """One pass over ``exp(zeta L_k(h) + log pi_k)`` (``zeta``: :attr:`rate`): the marginal over
        h and the weights of k.

        Only cells within ``NEGLIGIBLE`` nats of the most probable one are summed exactly; the
        others (together less than ``G exp(-NEGLIGIBLE)`` of the mass) keep their largest term,
        which is within ``log K`` of the sum. This is what keeps a step cheap once the posterior
        has narrowed.
        """
        k = self.nuisance.size
        lp = self.nuisance.log_prior.reshape(-1, 1).astype(np.float32)
        zeta = self.rate
        ll = self.loglik.reshape(k, -1)
        a = (ll if zeta == 1.0 else np.float32(zeta) * ll) + lp
        m = a.max(axis=0)
        top = float(m.max())
        keep = m > top - NEGLIGIBLE
        if keep.all():
            live, sub = slice(None), a - m
        else:
            live = np.flatnonzero(keep)
            sub = a[:, live] - m[live]
        np.exp(sub, out=sub)
        logp = m.astype(np.float64)
        logp[live] += np.log(sub.sum(axis=0, dtype=np.float64))
        self._marginal = Posterior(self.grid, logp.reshape(self.grid.shape), self.n_obs)
        ev = (sub @ np.exp(m[live] - np.float32(top))).astype(np.float64)
        self._weights = (ev / ev.sum()).reshape(self.nuisance.log_prior.shape)

    def marginal(self) -> Posterior:
        """The posterior over the transform alone, ``sum_k pi_k exp(L_k(h))`` normalised."""
        if self._marginal is None:
            self._summarise()
        return self._marginal

    def weights(self) -> np.ndarray:
        """(S, E) posterior of the nuisance values, ``p(sigma, eps | D)``."""
        if self._weights is None:
            self._summarise()
        return self._weights

    def blur_mean(self) -> float:
        """Posterior mean of the boundary blur, px."""
        return float(self.weights().sum(axis=1) @ self.nuisance.blurs)

    def outlier_mean(self) -> float:
        """Posterior mean of the outlier rate."""
        return float(self.weights().sum(axis=0) @ self.nuisance.outliers)

    def map_index(self) -> tuple[int, int]:
        """(blur index, outlier index) of the most probable nuisance value."""
        i = int(np.argmax(self.weights()))
        return divmod(i, len(self.nuisance.outliers))


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


__all__ = ["Nuisance", "RobustPosterior", "robust_terms", "planning_table", "blurred_map", "DEFAULT_BLURS",
           "DEFAULT_OUTLIERS"]
