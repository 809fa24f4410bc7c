"""Adaptation that repairs the model: a joint belief over the shift and the model's map.

Each hypothesis ``h`` of the displacement is scored by how well its own map, repaired by the
touches mapped back at ``h``, predicted each touch before it was made: a Rao-Blackwellised joint
belief over (shift, map) (Grisetti et al. 2005). The map at a reference point ``x`` is a Dirichlet
over the sounds (Doherty et al. 2017), ``alpha_c(x) = kappa(x) q(c | x) + sum_s k(x - x_s) [c_s =
c]``, ``q`` the model locally blurred, ``kappa`` its local confidence and ``k`` a Gaussian kernel
of width ``w``. The predictive of touch ``t`` under ``h`` with outlier rate ``eps`` is

``p(c_t | a_t, h, D_<t) = (1 - eps) (kappa(x) q(c_t | x) + N_t^c) / (kappa(x) + N_t) + eps / C``,
``x = a_t - h``, where for a translation the counts ``N`` do not depend on ``h``. The blur's scale
and ``eps`` are marginalised online (:class:`~.posteriors.likelihood.robust.RobustPosterior`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sklearn.base import clone

from kbcli.core.adaptation.config import REDUNDANCY_FACTOR, own_boundary_error
from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.likelihood.robust import (
    Nuisance,
    RobustPosterior,
)
from kbcli.core.adaptation.posteriors.likelihood.term import inverse_coords
from kbcli.core.adaptation.posteriors.posterior import Posterior
from kbcli.core.adaptation.repair_prior import (
    DEFAULT_KERNEL,
    DEFAULT_SCALE,
    RepairMap,
    kernel,
    repair_map,
)
from kbcli.core.adaptation.strategies import entropy_rows, outcome_distribution
from kbcli.core.model.table import LikelihoodTable

#: Default outlier rates (marginalised).
DEFAULT_OUTLIERS = (0.001, 0.02, 0.1)


@dataclass(frozen=True)
class Touches:
    """The touches absorbed so far: where they were read and what they sounded (immutable)."""

    points: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    classes: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))

    def add(self, point: np.ndarray, cls: int) -> Touches:
        return Touches(np.vstack([self.points, np.asarray(point, float).reshape(1, 2)]),
                       np.append(self.classes, int(cls)))

    def counts(self, points: np.ndarray, n_classes: int, width: float) -> np.ndarray:
        """(m, C) the kernel-weighted counts of each sound at ``points`` (m, 2)."""
        pts = np.asarray(points, float).reshape(-1, 2)
        out = np.zeros((len(pts), n_classes))
        if len(self.classes) == 0:
            return out
        d2 = ((pts[:, None, :] - self.points[None, :, :]) ** 2).sum(axis=2)
        wts = kernel(d2, width)
        for c in np.unique(self.classes):
            out[:, c] = wts[:, self.classes == c].sum(axis=1)
        return out

    def __len__(self) -> int:
        return len(self.classes)


def repaired_map(rmap: RepairMap, touches: Touches, shift: np.ndarray,
                 scale: float = DEFAULT_SCALE) -> np.ndarray:
    """(H, W, C) the Dirichlet parameters ``alpha`` of the map repaired by ``touches`` mapped back
    by ``shift``, on ``rmap``'s raster."""
    t = rmap.table
    h, w = t.shape
    gx, gy = np.meshgrid(t.origin[0] + t.step * np.arange(w), t.origin[1] + t.step * np.arange(h))
    prior = np.stack([rmap.prob(gx, gy, c, scale) for c in range(t.n_classes)], axis=-1)
    alpha = rmap.kappa[..., None].astype(float) * prior
    pts = touches.points - np.asarray(shift, float)[-2:]
    for p, c in zip(pts, touches.classes, strict=True):
        alpha[..., c] += kernel((gx - p[0]) ** 2 + (gy - p[1]) ** 2, rmap.width)
    return alpha


def repair_terms(grid: HypothesisGrid, rmap: RepairMap, touches: Touches, action: np.ndarray,
                 cls: int, nuisance: Nuisance) -> np.ndarray:
    """``log p(cls | action, h, D_<t)`` under every nuisance value (scale, outlier) and cell h:
    the Dirichlet-multinomial predictive of the map repaired by ``touches`` at h.

    Returns
    -------
    (S * E, *grid.shape) float32 ndarray
        Nuisance values in row-major (scale, outlier) order.
    """
    if grid.rigid:
        raise ValueError("the repaired belief needs a translation grid")
    x, y = inverse_coords(grid, action)
    c = rmap.table.n_classes
    cnt = touches.counts(np.asarray(action, float), c, rmap.width)[0]
    n_c, n = np.float32(cnt[cls]), np.float32(cnt.sum())
    kappa = np.broadcast_to(rmap.confidence(x, y), grid.shape)
    s_n, e_n = len(nuisance.blurs), len(nuisance.outliers)
    out = np.empty((s_n, e_n) + grid.shape, np.float32)
    for i, s in enumerate(nuisance.blurs):
        q = np.broadcast_to(rmap.prob(x, y, cls, float(s)), grid.shape)
        p = (kappa * q + n_c) / (kappa + n)
        for j, e in enumerate(nuisance.outliers):
            out[i, j] = p * np.float32(1 - e) + np.float32(e / c)
    np.log(out, out=out)
    return out.reshape((s_n * e_n,) + grid.shape)


class RepairBelief:
    """The joint belief over the shift and the repaired map (module docstring); immutable.

    ``radius``: a candidate within this many px of ``k`` earlier touches promises ``1 / (k + 1)``
    of its information when planning (0: no discount).
    """

    __slots__ = ("posterior", "rmap", "touches", "radius")

    def __init__(self, posterior: RobustPosterior, rmap: RepairMap,
                 touches: Touches | None = None, radius: float = 0.0) -> None:
        self.posterior = posterior
        self.rmap = rmap
        self.touches = Touches() if touches is None else touches
        self.radius = float(radius)

    @classmethod
    def start(cls, grid: HypothesisGrid, rmap: RepairMap, scales=(DEFAULT_SCALE,),
              outliers=DEFAULT_OUTLIERS, eta: float = 1.0, radius: float = 0.0) -> RepairBelief:
        """The flat prior over the grid and the nuisance values."""
        return cls(RobustPosterior(grid, Nuisance.build(scales, outliers), eta=eta), rmap,
                   radius=radius)

    @classmethod
    def for_model(cls, grid: HypothesisGrid, table: LikelihoodTable, model, cfg) -> RepairBelief:
        """The flat prior for ``model`` (rasterised as ``table``) and an adapter config ``cfg``
        (None options read the defaults; the blur's, the model's landing scatter); the planning
        radius is the robust posterior's default spot."""
        opts = cfg.posterior
        width = DEFAULT_KERNEL if opts.repair_kernel is None else float(opts.repair_kernel)
        blur = (float(getattr(model, "reach_sd_", 0.0)) if opts.repair_blur is None
                else float(opts.repair_blur))
        scale = DEFAULT_SCALE if opts.repair_scale is None else float(opts.repair_scale)
        rmap = repair_map(table, getattr(model, "actions_", None), width, blur)
        berr = own_boundary_error(getattr(model, "reliability_", None))
        return cls.start(grid, rmap, (scale,), opts.robust_outliers or DEFAULT_OUTLIERS,
                         radius=0.0 if berr is None else REDUNDANCY_FACTOR * berr)

    def update(self, point: np.ndarray, cls: int) -> RepairBelief:
        """Absorb a touch read at ``point`` that sounded ``cls``."""
        post = self.posterior
        terms = repair_terms(post.grid, self.rmap, self.touches, point, cls, post.nuisance)
        return RepairBelief(post.update(terms), self.rmap, self.touches.add(point, cls),
                            self.radius)

    def marginal(self) -> Posterior:
        return self.posterior.marginal()

    def outcome(self, table: LikelihoodTable, hyp: np.ndarray, weights: np.ndarray,
                actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`repair_outcome` of this belief (the strategies' ``Context.outcome``)."""
        return repair_outcome(self, table, hyp, weights, actions)

    def planning_table(self) -> LikelihoodTable:
        """The prior predictive map at the most probable (scale, outlier) value."""
        i, j = self.posterior.map_index()
        nz = self.posterior.nuisance
        return self.rmap.planning_table(float(nz.blurs[i]), float(nz.outliers[j]))


def repair_outcome(belief: RepairBelief, table: LikelihoodTable, hyp: np.ndarray,
                   weights: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The predictive ``pred`` (M, C) of each action's outcome under the repaired belief and the
    expected conditional entropy ``cond`` (M,) (as
    :func:`kbcli.core.adaptation.strategies.outcome_distribution`): the translation hypotheses
    ``hyp`` (K, 2) weighted by ``weights``, the outcome following the belief's planning ``table``
    at ``a - h``; an action within ``belief.radius`` of ``k`` earlier touches keeps ``1 / (k + 1)``
    of its information.
    """
    pred, cond = outcome_distribution(table, "translation", hyp, weights, actions, np.zeros(2))
    pts, r = belief.touches.points, belief.radius
    if r <= 0 or len(pts) == 0:
        return pred, cond
    near = (((actions[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2) <= r * r).sum(axis=1)
    h = entropy_rows(pred)
    return pred, h - (h - cond) / (1 + near)


def absorb(model, points: np.ndarray, classes: np.ndarray, shift: np.ndarray):
    """The model refitted on its own training samples and the touches (``points`` (n, 2),
    ``classes`` (n,), unknown sounds left out) mapped into its reference frame by ``shift``
    (``a - shift``): a clone of ``model``, fitted with the touches last; the class ids are
    unchanged and ``model`` is left as it is.
    """
    pts = np.asarray(points, float).reshape(-1, 2)
    cls = np.asarray(classes, np.int64).reshape(-1)
    keep = cls >= 0
    actions = np.vstack([model.actions_, pts[keep] - np.asarray(shift, float)[-2:]])
    labels = np.concatenate([model.labels_, cls[keep]])
    new = clone(model).fit(actions, np.asarray(model.class_features_, float)[labels])
    new.reach_sd_ = model.reach_sd_
    return new
