"""A posterior that learns how far to trust the model: Eq. 8 with model error marginalised.

A learned model's boundaries can sit a few px off; trusting it, the plain posterior locks onto a
wrong displacement. Here the observation model has two more unknowns, a **boundary blur**
``sigma`` (px) and an **outlier rate** ``eps``:

``p(s | a, h, sigma, eps) = (1 - eps) [p_model * N(0, sigma^2)](s | T_h^-1 a) + eps / C``.

Both live on a small grid (:data:`DEFAULT_BLURS`, :data:`DEFAULT_OUTLIERS`) with a uniform prior
and are marginalised exactly, online: for every nuisance value ``k`` the posterior keeps ``L_k(h)
= sum_t log p(s_t | a_t, h, k)``. After ``n`` touches the log-likelihood is multiplied by
``zeta_n = alpha / (alpha + n)`` (the coarsened posterior of Miller and Dunson 2019), ``alpha =
HORIZON eta / (1 - eta)`` for the learning rate ``eta`` (1: plain Bayes;
:func:`kbcli.core.adaptation.config.learning_rate`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.likelihood.blur import (
    blurred_map,
    blurred_read,
    planning_table,
    raw_prob,
)
from kbcli.core.adaptation.posteriors.likelihood.term import cell_index, inverse_coords
from kbcli.core.adaptation.posteriors.posterior import Posterior
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
        reads.append(blurred_read(patch, row, col, math.hypot(s, cell_sigma) / table.step))
    for i, v in enumerate(reads):
        v = np.broadcast_to(v, grid.shape)
        for j, e in enumerate(nuisance.outliers):
            out[i, j] = v
            out[i, j] *= np.float32(1 - e)
            out[i, j] += np.float32(e / c)
    np.log(out, out=out)
    return out.reshape((s_n * e_n,) + grid.shape)


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


__all__ = ["DEFAULT_BLURS", "DEFAULT_OUTLIERS", "Nuisance", "RobustPosterior", "blurred_map",
           "planning_table", "raw_prob", "robust_terms"]
