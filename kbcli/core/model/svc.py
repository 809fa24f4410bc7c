"""The ``svc`` model class: pairwise support-vector machines, for keys of any shape.

From the exploration samples alone: the sound classes as ``lines`` finds them; the neighbouring
sounds from the straddling Delaunay edges (:func:`~kbcli.core.model.sounds.straddling_edges`);
one :class:`~sklearn.svm.SVC` per pair of neighbouring sounds on the pair's samples within
``local_radius`` px of their edges (hard-margin linear when a line separates them, a hard-margin
circle when one sound is an island in the other, else RBF). A pair's contest at an action is
``Phi(sqrt(3) f(a))``, f the decision value; far from a machine's samples it fades into the
nearest-sample rule. Storage keeps the samples and hyper-parameters; loading refits
deterministically. Defaults: ``docs/design-notes.md``, Model classes.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import cKDTree
from scipy.special import log_ndtr
from sklearn.svm import SVC

from kbcli.core.config import Flag, Positive, Whole, between
from kbcli.core.model.classifiers import class_distance, grid_boundary_sites
from kbcli.core.model.pairwise import DEFAULT_AREA, ModelBase
from kbcli.core.model.sounds import straddling_edges
from kbcli.core.options import Options
from kbcli.errors import ArtifactError, ConfigError

_SQRT3 = float(np.sqrt(3.0))
_EDGE_STEPS = 17  # points along a straddling edge where the boundary site is looked for
SITE_GRID = 2.0  # px, grid on which boundary sites between straddling edges are looked for
#: a sound whose straddling edges are at least this share with one other sound is an island in
#: it (a pad in silence): their pair may get a circle machine (``docs/design-notes.md``)
ISLAND = 0.75
_HARD_C = 1e6  # margin penalty of a pair's linear machine: a hard margin (its samples separate)


def _separable(x: np.ndarray, y: np.ndarray) -> bool:
    """Whether a hyperplane separates the points ``x`` (n, F) of labels ``y`` in {0, 1} (a
    straight line for F = 2): the linear program ``(2 y - 1) (w . x + b) >= 1`` is feasible."""
    s = (2.0 * y - 1.0)[:, None]
    f = x.shape[1] + 1
    res = linprog(np.zeros(f), A_ub=-s * np.column_stack([x, np.ones(len(x))]),
                  b_ub=-np.ones(len(x)), bounds=[(None, None)] * f, method="highs")
    return res.status == 0


class _CircleMachine:
    """A hard-margin linear machine on the features ``(u, v, u^2 + v^2)`` of points (in length
    scales, relative to the centre of its samples): its boundary is a circle (or a line)."""

    def __init__(self, centre: np.ndarray) -> None:
        self.centre_ = np.asarray(centre, float)

    def features(self, x: np.ndarray) -> np.ndarray:
        u, v = (np.asarray(x, float) - self.centre_).T
        return np.column_stack([u, v, u * u + v * v])

    def fit(self, x: np.ndarray, y: np.ndarray) -> _CircleMachine:
        self.svm_ = SVC(kernel="linear", C=_HARD_C).fit(self.features(x), y)
        self.n_support_ = self.svm_.n_support_
        return self

    def decision_function(self, x: np.ndarray) -> np.ndarray:
        return self.svm_.decision_function(self.features(x))


def _stored_params(d: dict) -> dict:
    """The parameters of a stored svc model (:meth:`SVCModel.from_arrays`)."""
    return {
        "length_scale": float(d["length_scale"]),
        "C": float(d["C"]),
        "local_radius": float(d["local_radius"]),
        "n_neighbors": int(d["n_neighbors"]),
        # models stored before linear pairs existed had RBF machines only
        "linear_pairs": bool(int(d["linear_pairs"])) if "linear_pairs" in d else False,
        # and before circle pairs existed, no circles
        "circle_pairs": bool(int(d["circle_pairs"])) if "circle_pairs" in d else False,
    }


class SVCOptions(Options):
    """``svc``'s options, the fit's parameters of :class:`SVCModel` (its defaults)."""

    what: ClassVar[str] = "model class svc"
    length_scale: Positive = 25.0
    C: Positive = 1e3
    local_radius: Positive = 30.0
    n_neighbors: between(Whole, 2, 1_000) = 8
    linear_pairs: Flag = True
    circle_pairs: Flag = True


class SVCModel(ModelBase):
    """p(sound | action) from pairwise linear or RBF SVMs (see the module docstring).

    Parameters
    ----------
    match_threshold, area
        As every class (:class:`~kbcli.core.model.pairwise.ModelBase`).
    length_scale : float
        Length scale (px) of the RBF kernel: ``exp(-|a - b|^2 / (2 length_scale^2))``.
    C : float
        Penalty of margin violations (large: a hard margin; the samples' labels are exact).
    local_radius : float
        A pair's machine is fitted on the samples of its two sounds within this many px of one of
        their straddling edges' ends.
    n_neighbors : int
        Samples looked at around an action to find the sounds it could make.
    linear_pairs, circle_pairs : bool
        Fit a hard-margin linear machine to a pair whose samples a line separates, a circular one
        to a pair one of whose sounds is an island in the other and a circle separates (else the
        RBF one). Models stored before these options existed load with False.

    Attributes
    ----------
    pairs_ : (P, 2) int ndarray
        The neighbouring pairs of classes (lower first) that have a machine.
    edges_ : (m, 2) int ndarray
        Straddling edges: sample indices, the lower class's end first.
    """

    def __init__(self, *, match_threshold: float = 1.5,
                 area: tuple[float, float, float, float] = DEFAULT_AREA,
                 length_scale: float = 25.0, C: float = 1e3, local_radius: float = 30.0,
                 n_neighbors: int = 8, linear_pairs: bool = True,
                 circle_pairs: bool = True) -> None:
        self.match_threshold = match_threshold
        self.area = area
        self.length_scale = length_scale
        self.C = C
        self.local_radius = local_radius
        self.n_neighbors = n_neighbors
        self.linear_pairs = linear_pairs
        self.circle_pairs = circle_pairs

    # -- parameters -----------------------------------------------------------------------------
    def _check_params(self) -> None:
        self._check_common()
        for name in ("length_scale", "C", "local_radius"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ConfigError(f"{name} must be a positive number, got {v!r}")
        if int(self.n_neighbors) < 2:
            raise ConfigError(f"n_neighbors must be >= 2, got {self.n_neighbors!r}")
        for name in ("linear_pairs", "circle_pairs"):
            v = getattr(self, name)
            if not isinstance(v, (bool, np.bool_)):
                raise ConfigError(f"{name} must be True or False, got {v!r}")

    # -- fitting --------------------------------------------------------------------------------
    def _set_fitted(self, features: np.ndarray, actions: np.ndarray, labels: np.ndarray,
                    reach_sd: float) -> None:
        self.class_features_ = np.asarray(features, float)
        self.actions_ = np.asarray(actions, float)
        self.labels_ = np.asarray(labels, np.int64)
        self.reach_sd_ = float(reach_sd)
        self._tree = cKDTree(self.actions_)
        e = straddling_edges(self.actions_, self.labels_)
        self.edges_ = e[np.lexsort((e[:, 1], e[:, 0]))] if len(e) else e
        nc = len(self.class_features_)
        code = self.labels_[self.edges_[:, 0]] * nc + self.labels_[self.edges_[:, 1]]
        #: pair code -> its machine (the contests of :class:`~kbcli.core.model.pairwise.ModelBase`)
        self._pairs: dict[int, SVC] = {}
        self._support: dict[int, tuple[cKDTree, cKDTree, cKDTree]] = {}
        self._edge_code = code
        pairs = []
        # straddling edges of each sound (an edge joins two different sounds: one for each)
        per_sound = np.bincount(self.labels_[self.edges_].ravel(), minlength=nc)
        for c in np.unique(code):  # one machine per pair of neighbouring sounds
            i, j = divmod(int(c), nc)
            ends = np.unique(self.edges_[code == c])
            near = self._tree.query_ball_point(self.actions_[ends], r=self.local_radius)
            idx = np.unique(np.concatenate([ends, *[np.asarray(n, np.int64) for n in near]]))
            idx = idx[np.isin(self.labels_[idx], (i, j))]
            y = (self.labels_[idx] == j).astype(np.int64)
            # an island: nearly all of one sound's straddling edges are with the other
            island = np.count_nonzero(code == c) >= ISLAND * min(per_sound[i], per_sound[j])
            svm = self._pair_machine(self.actions_[idx] / self.length_scale, y, island)
            self._pairs[int(c)] = svm
            self._support[int(c)] = (cKDTree(self.actions_[idx]), cKDTree(self.actions_[idx][y == 0]),
                                     cKDTree(self.actions_[idx][y == 1]))
            pairs.append((i, j))
        self.pairs_ = np.array(pairs, np.int64).reshape(-1, 2)

    def _pair_machine(self, x: np.ndarray, y: np.ndarray, island: bool = False) -> SVC:
        """A pair's machine on its samples ``x`` (in length scales) of labels ``y`` in {0, 1}:
        linear, circle (``island``) or RBF, as the class docstring says."""
        if self.linear_pairs and y.min() < y.max() and _separable(x, y):
            svm = SVC(kernel="linear", C=_HARD_C).fit(x, y)
            if np.all((2 * y - 1) * svm.decision_function(x) > 0):
                return svm
        if self.circle_pairs and island and y.min() < y.max():
            circle = _CircleMachine(x.mean(axis=0))
            if _separable(circle.features(x), y):
                circle.fit(x, y)
                if np.all((2 * y - 1) * circle.decision_function(x) > 0):
                    return circle
        return SVC(kernel="rbf", gamma=0.5, C=float(self.C)).fit(x, y)

    # -- the pairwise contests ------------------------------------------------------------------
    def _decision(self, code: int, q: np.ndarray) -> np.ndarray:
        """(n,) the pair's decision value: > 0 on the higher class's side, +-1 on the margin;
        beyond half a length scale from its samples it fades (weight ``exp(-2 d^2 /
        length_scale^2)``) into the nearest-sample rule ``(d_lower - d_higher) / length_scale``.
        """
        f = self._pairs[code].decision_function(q / self.length_scale)
        both, lo, hi = self._support[code]
        d = both.query(q)[0]
        near = d > 0.5 * self.length_scale
        if near.any():
            qn = q[near]
            nn = (lo.query(qn)[0] - hi.query(qn)[0]) / self.length_scale
            w = np.exp(-2.0 * (d[near] / self.length_scale) ** 2)
            f[near] = w * f[near] + (1 - w) * nn
        return f

    def _pair_logp(self, code: int, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """log p(on the lower / higher class's side) of a pair's boundary at each point: the
        boundary anywhere in the margin, ``log Phi(-+sqrt(3) f)``."""
        z = _SQRT3 * self._decision(code, q)
        return log_ndtr(-z), log_ndtr(z)

    # -- exploration ----------------------------------------------------------------------------
    def boundary_sites(self, step: float = 1.0, extend: float = 25.0,
                       phase: float = 0.0) -> dict[str, np.ndarray]:
        """Boundary sites: on every straddling edge, where its pair's machine changes sign (the
        midpoint when it does not), and where the predicted class changes on a 2 px grid
        (shifted by ``phase``); ``width`` is the distance to the nearest sample of either sound,
        summed. ``step`` and ``extend`` are accepted for the ``lines`` model's signature.

        Returns
        -------
        dict with ``points`` (m, 2), ``width`` (m,), ``pair`` (m, 2)
        """
        self._check_fitted()
        e = self.edges_
        if len(e) == 0:
            return {"points": np.empty((0, 2)), "width": np.empty(0),
                    "pair": np.empty((0, 2), dtype=np.int64)}
        a, b = self.actions_[e[:, 0]], self.actions_[e[:, 1]]
        t = np.linspace(0.0, 1.0, _EDGE_STEPS)
        line = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]  # (m, T, 2)
        f = np.empty(line.shape[:2])
        for c in np.unique(self._edge_code):  # one call per pair
            sel = np.flatnonzero(self._edge_code == c)
            f[sel] = self._decision(int(c), line[sel].reshape(-1, 2)).reshape(len(sel), -1)
        cross = (f[:, :-1] < 0) & (f[:, 1:] >= 0)  # from the lower class (< 0) to the higher
        has = cross.any(axis=1)
        j = np.argmax(cross, axis=1)
        r = np.arange(len(e))
        f0, f1 = f[r, j], f[r, j + 1]
        frac = np.where(has, (t[j] + (t[j + 1] - t[j]) * f0 / np.where(f0 != f1, f0 - f1, 1.0)),
                        0.5)
        pts = a + np.clip(frac, 0.0, 1.0)[:, None] * (b - a)
        la, lb = self.labels_[e[:, 0]], self.labels_[e[:, 1]]
        width = (class_distance(self.actions_, self.labels_, pts, la)
                 + class_distance(self.actions_, self.labels_, pts, lb))
        grid = grid_boundary_sites(self, phase, SITE_GRID)  # the boundary between the edges
        return {"points": np.vstack([pts, grid["points"]]), "width": np.r_[width, grid["width"]],
                "pair": np.vstack([np.column_stack([la, lb]), grid["pair"]])}

    # -- storage --------------------------------------------------------------------------------
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted model as named arrays (:meth:`from_arrays` refits, deterministically)."""
        self._check_fitted()
        return self._arrays(
            pairs=self.pairs_.copy(),
            n_support=np.array([int(self._pairs[int(c)].n_support_.sum()) for c in
                                self.pairs_[:, 0] * self.n_classes + self.pairs_[:, 1]], np.int64),
            length_scale=np.float64(self.length_scale),
            C=np.float64(self.C),
            local_radius=np.float64(self.local_radius),
            n_neighbors=np.int64(self.n_neighbors),
            linear_pairs=np.int64(bool(self.linear_pairs)),
            circle_pairs=np.int64(bool(self.circle_pairs)),
        )

    @classmethod
    def from_arrays(cls, d: dict) -> SVCModel:
        """Rebuild a fitted model from :meth:`to_arrays` output (nothing is unpickled)."""
        model = cls._from_stored(d, "svc", _stored_params)
        if "pairs" in d and not np.array_equal(np.asarray(d["pairs"]).reshape(-1, 2),
                                               model.pairs_):
            raise ArtifactError("stored svc model: refitting found other pairs of sounds than "
                                "were stored (a different scikit-learn or scipy?)")
        return model


__all__ = ["SVCModel"]
