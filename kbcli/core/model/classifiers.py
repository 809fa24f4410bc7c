"""Model classes on plain scikit-learn classifiers: random forests (``forest``, ``forest-xy``) and
k-NN (``knn``), behind the interface of the bespoke classes.

p(sound | action) is the classifier's ``predict_proba``, sharpened (``p_c ** sharpen / sum_c'
p_c' ** sharpen``) and mixed with a uniform ``floor``, both chosen by held-out score
(:meth:`SklearnModel.calibration_grid`). Boundary sites for active exploration are where the
predicted class changes on a 2 px grid. Storage keeps the samples and hyper-parameters
(``random_state`` included); loading refits deterministically.
"""

from __future__ import annotations

import warnings
from typing import ClassVar

import numpy as np
from scipy.spatial import cKDTree

from kbcli.core.config import Whole, between
from kbcli.core.model.pairwise import DEFAULT_AREA, ModelBase
from kbcli.core.options import Options
from kbcli.errors import ConfigError

SITE_GRID = 2.0  # px, grid on which boundary sites are looked for
_CHUNK = 65536  # query points per block of a prediction
#: Candidate values of the calibration's uniform floor (:meth:`SklearnModel.calibration_grid`).
FLOOR_GRID = (0.0, 0.002, 0.01, 0.03)
#: The forests' candidate floors (0.03 left out: ``docs/design-notes.md``, Model classes).
FOREST_FLOOR_GRID = (0.0, 0.002, 0.01)
#: Candidate values of the forests' ``sharpen`` (their own, 2, first: kept unless another beats it
#: on the held-out touches by a standard error).
FOREST_SHARPEN_GRID = (2.0, 4.0, 8.0)
#: Candidate values of ``sharpen`` for k-NN, whose own is 1 (its distance-weighted votes).
SHARPEN_GRID = (1.0, 2.0, 4.0, 8.0)
#: Largest ``sharpen`` accepted (no underflow of a class that has a vote among 120 trees).
MAX_SHARPEN = 16.0


def sharpened(p: np.ndarray, k: float) -> np.ndarray:
    """(n, C) rows of ``p`` raised to the power ``k`` and renormalised (``p`` itself when
    ``k`` is 1: bit for bit). The argmax of every row is unchanged (ties stay ties)."""
    if k == 1.0:
        return p
    q = p ** k
    return q / q.sum(axis=1, keepdims=True)


def class_distance(actions: np.ndarray, labels: np.ndarray, pts: np.ndarray,
                   cls: np.ndarray) -> np.ndarray:
    """(m,) distance from each point ``pts[i]`` to the nearest sample of class ``cls[i]``
    (inf when the class has no sample)."""
    out = np.full(len(pts), np.inf)
    for c in np.unique(cls):  # one tree per class present
        sel = np.flatnonzero(cls == c)
        mine = actions[labels == c]
        if len(mine):
            out[sel] = cKDTree(mine).query(pts[sel])[0]
    return out


def grid_boundary_sites(model, phase: float = 0.0, step: float = SITE_GRID) -> dict:
    """Boundary sites of any fitted model: where its predicted class changes between neighbouring
    cells of a ``step`` px grid (shifted by ``phase`` of a cell), each with the width of its band
    (distance to the nearest sample of either sound, summed): ``points`` (m, 2), ``width`` (m,),
    ``pair`` (m, 2)."""
    x0, y0, x1, y1 = (float(v) for v in model.area)
    g = np.stack(np.meshgrid(np.arange(x0 + phase * step, x1, step),
                             np.arange(y0 + phase * step, y1, step)), -1)
    cl = model.predict_class(g.reshape(-1, 2)).reshape(g.shape[:2])
    iy, ix = np.nonzero(cl[:, 1:] != cl[:, :-1])
    jy, jx = np.nonzero(cl[1:, :] != cl[:-1, :])
    pts = np.vstack([(g[iy, ix] + g[iy, ix + 1]) / 2, (g[jy, jx] + g[jy + 1, jx]) / 2])
    cc = np.vstack([np.column_stack([cl[iy, ix], cl[iy, ix + 1]]),
                    np.column_stack([cl[jy, jx], cl[jy + 1, jx]])]).astype(np.int64)
    la, lb = cc.min(axis=1), cc.max(axis=1)
    width = (class_distance(model.actions_, model.labels_, pts, la)
             + class_distance(model.actions_, model.labels_, pts, lb))
    return {"points": pts.reshape(-1, 2), "width": width, "pair": np.column_stack([la, lb])}


class SklearnModel(ModelBase):
    """Base of the model classes on one scikit-learn classifier (see the module docstring).

    A subclass sets ``kind`` (its registry name, for messages), ``_PARAMS`` ((name, type) of its
    own hyper-parameters, stored by :meth:`to_arrays`) and implements ``_check_own()``,
    ``_classifier()`` and, optionally, ``_features(points)``.
    """

    kind = "sklearn"
    _PARAMS: tuple[tuple[str, type], ...] = ()
    _SHARPEN_GRID: tuple[float, ...] = SHARPEN_GRID
    _FLOOR_GRID: tuple[float, ...] = FLOOR_GRID

    # -- parameters -----------------------------------------------------------------------------
    @classmethod
    def calibration_grid(cls) -> dict[str, tuple[float, ...]]:
        """Candidate values of the calibration: ``sharpen`` (the class's own first) and ``floor``."""
        return {"floor": cls._FLOOR_GRID, "sharpen": cls._SHARPEN_GRID}

    def _check_params(self) -> None:
        self._check_common()
        if not (np.isfinite(self.floor) and 0 <= self.floor < 1):
            raise ConfigError(f"floor must be in [0, 1), got {self.floor!r}")
        k = self.sharpen
        if (isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, float, np.integer,
                                                                   np.floating))
                or not (np.isfinite(k) and 1 <= k <= MAX_SHARPEN)):
            raise ConfigError(f"sharpen must be a number in [1, {MAX_SHARPEN:g}], got {k!r}")
        self._check_own()

    def _check_own(self) -> None:
        raise NotImplementedError

    def _classifier(self):
        raise NotImplementedError

    def _features(self, points: np.ndarray) -> np.ndarray:
        """(n, F) the classifier's features of points (n, 2): the points themselves."""
        return points

    # -- fitting --------------------------------------------------------------------------------
    def _set_fitted(self, features: np.ndarray, actions: np.ndarray, labels: np.ndarray,
                    reach_sd: float) -> None:
        self.class_features_ = np.asarray(features, float)
        self.actions_ = np.asarray(actions, float).reshape(-1, 2)
        self.labels_ = np.asarray(labels, np.int64)
        self.reach_sd_ = float(reach_sd)
        self._tree = cKDTree(self.actions_)
        self._pairs = {}
        with warnings.catch_warnings():  # a few reaches heard as many sounds is no regression
            warnings.filterwarnings("ignore", "The number of unique classes", UserWarning)
            self.classifier_ = self._classifier().fit(self._features(self.actions_),
                                                      self.labels_)

    # -- prediction -----------------------------------------------------------------------------
    def _predict(self, points: np.ndarray, proba: bool) -> np.ndarray:
        self._check_fitted()
        q = np.asarray(points, float).reshape(-1, 2)
        nc = self.n_classes
        p = np.zeros((len(q), nc))
        cols = np.asarray(self.classifier_.classes_, np.int64)
        for start in range(0, len(q), _CHUNK):
            blk = slice(start, start + _CHUNK)
            p[blk, cols] = self.classifier_.predict_proba(self._features(q[blk]))
        if not proba:
            return np.argmax(p, axis=1)
        return sharpened(p, float(self.sharpen))

    # -- exploration ----------------------------------------------------------------------------
    def boundary_sites(self, step: float = 1.0, extend: float = 25.0,
                       phase: float = 0.0) -> dict[str, np.ndarray]:
        """Boundary sites (:func:`grid_boundary_sites`; ``step`` and ``extend`` are accepted for
        the ``lines`` model's signature)."""
        self._check_fitted()
        return grid_boundary_sites(self, phase)

    # -- storage --------------------------------------------------------------------------------
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted model as named arrays (:meth:`from_arrays` refits, deterministically)."""
        own = {
            "floor": np.float64(self.floor),
            "sharpen": np.float64(self.sharpen),
            # every stored learned model has it (the artifact schema); 0: no neighbours looked at
            "n_neighbors": np.int64(getattr(self, "n_neighbors", 0)),
        }
        for name, typ in self._PARAMS:
            own[name] = (np.int64 if typ is int else np.float64)(getattr(self, name))
        return self._arrays(**own)

    @classmethod
    def from_arrays(cls, d: dict) -> SklearnModel:
        """Rebuild a fitted model from :meth:`to_arrays` output (a model stored before
        ``sharpen`` existed loads with ``sharpen`` 1)."""
        return cls._from_stored(d, cls.kind, lambda d: {
            "floor": float(d["floor"]),
            "sharpen": float(d["sharpen"]) if "sharpen" in d else 1.0,
            **{name: typ(np.asarray(d[name]).item()) for name, typ in cls._PARAMS}})


def _positive_int(model, name: str, least: int = 1) -> None:
    v = getattr(model, name)
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < least:
        raise ConfigError(f"{name} must be a whole number >= {least}, got {v!r}")


class ForestXYOptions(Options):
    """``forest-xy``'s options (a user sets them; the defaults are the class's): ``n_estimators``
    trees (while exploring, 60 unless set) and ``min_samples_leaf``, the fewest samples in a leaf."""

    what: ClassVar[str] = "model class forest-xy"
    n_estimators: between(Whole, 1, 10_000) = 120
    min_samples_leaf: between(Whole, 1, 1_000) = 1


class ForestOptions(ForestXYOptions):
    """``forest``'s options: ``forest-xy``'s and ``n_directions``, the directions its trees split
    along (x, y and ``n_directions - 2`` oblique ones)."""

    what: ClassVar[str] = "model class forest"
    n_directions: between(Whole, 2, 180) = 6


class KNNOptions(Options):
    """``knn``'s option: ``n_neighbors``, the samples that vote."""

    what: ClassVar[str] = "model class knn"
    n_neighbors: between(Whole, 1, 1_000) = 5


class ForestModel(SklearnModel):
    """p(sound | action) from a random forest on the coordinates and oblique projections.

    Parameters
    ----------
    match_threshold, area
        As every class (:class:`~kbcli.core.model.pairwise.ModelBase`).
    n_estimators : int
        Trees.
    n_directions : int
        Directions the trees split along, evenly spaced in [0, pi): x, y and
        ``n_directions - 2`` oblique projections.
    min_samples_leaf : int
        Fewest samples in a leaf (1: fully grown trees).
    random_state : int
        Seed of the trees (fixed: a stored model refits to the same trees).
    sharpen : float
        Exponent in [1, 16] on the share of votes, renormalised (calibration; the most probable
        sound never changes).
    floor : float
        Probability spread evenly over the sounds after ``sharpen`` (calibration).
    """

    kind = "forest"
    _PARAMS = (("n_estimators", int), ("n_directions", int), ("min_samples_leaf", int),
               ("random_state", int))
    _SHARPEN_GRID = FOREST_SHARPEN_GRID
    _FLOOR_GRID = FOREST_FLOOR_GRID

    def __init__(self, *, match_threshold: float = 1.5,
                 area: tuple[float, float, float, float] = DEFAULT_AREA,
                 n_estimators: int = 120, n_directions: int = 6, min_samples_leaf: int = 1,
                 random_state: int = 0, floor: float = 0.0, sharpen: float = 2.0) -> None:
        self.match_threshold = match_threshold
        self.area = area
        self.n_estimators = n_estimators
        self.n_directions = n_directions
        self.min_samples_leaf = min_samples_leaf
        self.random_state = random_state
        self.floor = floor
        self.sharpen = sharpen

    def _check_own(self) -> None:
        _positive_int(self, "n_estimators")
        _positive_int(self, "n_directions", 2)
        _positive_int(self, "min_samples_leaf")
        _positive_int(self, "random_state", 0)

    def _classifier(self):
        from sklearn.ensemble import RandomForestClassifier

        return RandomForestClassifier(n_estimators=int(self.n_estimators),
                                      min_samples_leaf=int(self.min_samples_leaf),
                                      random_state=int(self.random_state), n_jobs=1)

    def _features(self, points: np.ndarray) -> np.ndarray:
        """(n, n_directions) projections of the points on directions evenly spaced in [0, pi),
        relative to the centre of the working area."""
        x0, y0, x1, y1 = (float(v) for v in self.area)
        t = np.arange(int(self.n_directions)) * np.pi / int(self.n_directions)
        u = np.column_stack([np.cos(t), np.sin(t)])
        return (np.asarray(points, float) - ((x0 + x1) / 2, (y0 + y1) / 2)) @ u.T


class ForestXYModel(ForestModel):
    """:class:`ForestModel` whose trees split on the two coordinates only (``n_directions`` 2):
    exact for axis-aligned key edges, a staircase on slanted ones."""

    kind = "forest-xy"

    def __init__(self, *, match_threshold: float = 1.5,
                 area: tuple[float, float, float, float] = DEFAULT_AREA,
                 n_estimators: int = 120, n_directions: int = 2, min_samples_leaf: int = 1,
                 random_state: int = 0, floor: float = 0.0, sharpen: float = 2.0) -> None:
        super().__init__(match_threshold=match_threshold, area=area, n_estimators=n_estimators,
                         n_directions=n_directions, min_samples_leaf=min_samples_leaf,
                         random_state=random_state, floor=floor, sharpen=sharpen)


class KNNModel(SklearnModel):
    """p(sound | action) from the distance-weighted votes of the ``n_neighbors`` nearest samples.

    ``sharpen`` and ``floor`` calibrate as :class:`ForestModel`'s.
    """

    kind = "knn"
    _PARAMS = (("n_neighbors", int),)

    def __init__(self, *, match_threshold: float = 1.5,
                 area: tuple[float, float, float, float] = DEFAULT_AREA,
                 n_neighbors: int = 5, floor: float = 0.0, sharpen: float = 1.0) -> None:
        self.match_threshold = match_threshold
        self.area = area
        self.n_neighbors = n_neighbors
        self.floor = floor
        self.sharpen = sharpen

    def _check_own(self) -> None:
        _positive_int(self, "n_neighbors")

    def _classifier(self):
        from sklearn.neighbors import KNeighborsClassifier

        return _KNN(KNeighborsClassifier, int(self.n_neighbors))


class _KNN:
    """k-NN with ``k`` capped by the number of samples (a handful of reaches is a valid model)."""

    def __init__(self, factory, k: int) -> None:
        self.factory, self.k = factory, k

    def fit(self, x: np.ndarray, y: np.ndarray) -> _KNN:
        self.clf = self.factory(n_neighbors=min(self.k, len(x)), weights="distance").fit(x, y)
        self.classes_ = self.clf.classes_
        return self

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        return self.clf.predict_proba(x)


__all__ = ["ForestModel", "ForestOptions", "ForestXYOptions", "KNNModel", "KNNOptions", "SklearnModel", "grid_boundary_sites", "class_distance"]
