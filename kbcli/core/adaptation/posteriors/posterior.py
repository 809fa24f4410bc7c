"""The posterior over the keyboard's displacement: Eq. 8, the product of per-observation terms, on
a hypothesis grid, in log space (paper Sect. III-D, Algorithm 2).

The prior is uniform over the grid; :class:`Posterior` (immutable) holds the normalised
log-probability of every cell. Estimates: the maximum-likelihood cell, the mean, the entropy in
nats (``log G`` for the prior) and the mass within a radius.
"""

from __future__ import annotations

import math

import numpy as np

from kbcli.core.adaptation.grid import HypothesisGrid


def log_normalise(logw: np.ndarray, axis: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Normalise log weights: ``(logw - logsumexp(logw), exp(logw - max) / sum)`` along ``axis``
    (None: the whole array); ``logw`` needs a finite maximum.

    Hand-written rather than ``scipy.special.logsumexp``: the probabilities must be ``exp(logw -
    max) / sum`` exactly, as every stored artifact was computed (scipy differs in the last bit).

    Raises
    ------
    ValueError
        When no weight is finite (``axis`` None).
    """
    if axis is None:
        m = float(np.max(logw))
        if not math.isfinite(m):
            raise ValueError("a posterior needs at least one cell of finite log-probability")
        p = np.exp(logw - m)
        total = float(p.sum())
        p /= total
        return logw - (m + math.log(total)), p
    m = np.max(logw, axis=axis, keepdims=True)
    p = np.exp(logw - m)
    total = p.sum(axis=axis, keepdims=True)
    p /= total
    return logw - (m + np.log(total)), p


#: Cells within this relative distance of the most probable one tie with it (``fair_argmax``).
TIE_RTOL = 1e-9


def fair_argmax(p: np.ndarray, seed) -> int:
    """Index of the largest of ``p`` (1-D), ties (within ``TIE_RTOL``) broken uniformly at random
    from ``numpy.random.default_rng(seed)``: no positional bias (``np.argmax`` gives the first)."""
    m = float(np.max(p))
    tied = np.flatnonzero(p >= m * (1 - TIE_RTOL)) if m > 0 else np.flatnonzero(p == m)
    if len(tied) == 1:
        return int(tied[0])
    return int(tied[np.random.default_rng(seed).integers(len(tied))])


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

    __slots__ = ("grid", "logp", "probs", "_entropy", "n_obs", "_ml", "_marg", "tie_seed")

    def __init__(self, grid: HypothesisGrid, logp: np.ndarray, n_obs: int = 0,
                 tie_seed: int | None = None) -> None:
        logp, p = log_normalise(np.asarray(logp, float).reshape(grid.shape))
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
        #: None: ties of the most probable cell go to the lowest index; else they are broken
        #: uniformly at random, from ``SeedSequence([tie_seed, n_obs])`` (:func:`fair_argmax`)
        self.tie_seed = tie_seed

    @classmethod
    def uniform(cls, grid: HypothesisGrid, tie_seed: int | None = None) -> Posterior:
        """The flat prior over the grid."""
        return cls(grid, np.zeros(grid.shape), tie_seed=tie_seed)

    def update(self, term: np.ndarray) -> Posterior:
        """Multiply in one observation's term (Eq. 8: add its log)."""
        return Posterior(self.grid, self.logp + term, self.n_obs + 1, self.tie_seed)

    def log_ratio_at(self, params: np.ndarray) -> float:
        """``log(p(params) / max p)``: how far below the most probable cell the posterior puts
        ``params`` (P,), read on the cells that bracket it (:meth:`HypothesisGrid.around`: the
        most probable of them, an upper bound of any interpolation between them). 0 where
        ``params`` is among the most probable; about -27.6 is 1e-12 of the maximum."""
        return float(np.max(self.logp[self.grid.around(params)]) - np.max(self.logp))

    def entropies_after(self, terms: np.ndarray) -> np.ndarray:
        """(k,) the entropy (nats) of the posterior updated with each of ``k`` terms
        ``(k, *grid.shape)``: ``update(terms[i]).entropy()`` bit for bit, without building the
        posteriors."""
        k = len(terms)
        flat = self.logp.reshape(-1)
        rows = np.asarray(terms, float).reshape(k, -1)
        logw, p = np.empty_like(flat), np.empty_like(flat)
        out = np.empty(k)
        for i in range(k):
            np.add(flat, rows[i], out=logw)
            m = float(np.max(logw))
            if not math.isfinite(m):
                raise ValueError("a posterior needs at least one cell of finite log-probability")
            np.subtract(logw, m, out=p)
            np.exp(p, out=p)
            total = float(p.sum())
            p /= total
            logw -= m + math.log(total)  # math.log, as log_normalise takes it
            out[i] = -np.einsum("i,i->", p, logw)
        return out

    def with_tie_seed(self, tie_seed: int | None) -> Posterior:
        """The same posterior (same arrays, no renormalisation) with another tie rule."""
        out = object.__new__(Posterior)
        for k in ("grid", "logp", "probs", "_entropy", "n_obs", "_marg"):
            setattr(out, k, getattr(self, k))
        out._ml = None
        out.tie_seed = tie_seed
        return out

    # -- summaries -------------------------------------------------------------------------------
    def entropy(self) -> float:
        """Entropy of the cell distribution, nats."""
        return self._entropy

    def ml_index(self) -> int:
        """Flat index of the most probable cell (ties: see ``tie_seed``)."""
        if self._ml is None:
            if self.tie_seed is None:
                self._ml = int(np.argmax(self.probs))
            else:
                self._ml = fair_argmax(self.probs.reshape(-1), [self.tie_seed, self.n_obs])
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
        """A weighted set of at most ``k`` cells standing for the posterior: ``(index, weights)``,
        flat cell indices and weights summing to one. The support itself when it has at most
        ``k`` cells, else ``k`` systematic-resampling draws from it merged into distinct cells.
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
