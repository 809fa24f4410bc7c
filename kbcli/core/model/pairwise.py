"""The learned model classes' common base, :class:`ModelBase`: p(sound | action) from pairwise
contests between the sounds heard nearby (paper Sect. III-A). A subclass decides a pair's contest
(``lines``, ``svc``); fitting the sounds, storage, prediction, sampling and the raster are here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.exceptions import NotFittedError

from kbcli.core.model.base import ProbabilityRaster, grid_points
from kbcli.core.model.sounds import SILENCE, classify_features, prepare_samples
from kbcli.errors import ArtifactError, ConfigError

#: Query points per block of a prediction.
_CHUNK = 16384
#: Added to both sides of every pairwise contest: log(2 Phi(z)), so that a contest the model knows
#: nothing about (z = 0) is neutral rather than penalising candidates in more contests.
_NEUTRAL = float(np.log(2.0))
#: Default ``area`` of the learned classes: the default keyboard's working area.
DEFAULT_AREA = (150.0, 200.0, 650.0, 500.0)


class ModelBase(ClassifierMixin, BaseEstimator):
    """Base of the learned model classes: p(sound | action) from pairwise contests.

    A scikit-learn estimator. The candidate sounds at an action are the classes of its
    ``n_neighbors`` nearest samples; a candidate's log-score sums ``log 2 p(on its side)`` over its
    contests with the other candidates; p(sound | action) is their softmax. After ``fit`` a
    subclass has ``_tree`` (a :class:`scipy.spatial.cKDTree` of ``actions_``) and ``_pairs`` (pair
    code ``lower * C + higher`` -> what decides the pair's contests), and implements
    ``_pair_logp(code, q) -> (log p(lower's side), log p(higher's side))``.

    Parameters
    ----------
    match_threshold : float
        Manhattan distance under which two perceived sounds are the same sound (Eq. 2).
    area : tuple of float
        (xmin, ymin, xmax, ymax) working area: the support of p(action) and of :meth:`raster`.

    Attributes
    ----------
    class_features_ : (C, D) ndarray
        Features of each class; row 0 (silence) is NaN.
    actions_ : (n, 2) ndarray
        Where the finger landed for each sample.
    labels_ : (n,) int ndarray
        Sound class of each sample.
    reach_sd_ : float
        Landing scatter of a reach (px, per-axis rms of landing minus target), for information.
    """

    #: True only for the exact model (the keyboard's own geometry, :class:`ExactModel`).
    exact_map = False
    n_neighbors: int
    match_threshold: float
    area: tuple[float, float, float, float]

    def fit(self, actions: np.ndarray, perceived: np.ndarray,
            targets: np.ndarray | None = None) -> ModelBase:
        """Learn the sound classes and p(sound | action) from exploration samples.

        Parameters
        ----------
        actions : (n, 2) ndarray
            Where the finger landed (proprioception).
        perceived : (n, D) ndarray
            What was heard there (NaN rows: silence).
        targets : (n, 2) ndarray, optional
            Where the reaches aimed; gives the landing scatter ``reach_sd_`` (else 0).

        Returns
        -------
        self
        """
        self._check_params()
        x, features, labels, reach_sd = prepare_samples(actions, perceived, targets,
                                                        self.match_threshold)
        self._set_fitted(features, x, labels, reach_sd)
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "class_features_"):
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet: call fit(actions, perceived)")

    @property
    def n_classes(self) -> int:
        self._check_fitted()
        return len(self.class_features_)

    def _check_common(self) -> None:
        """The checks of every learned class (``match_threshold`` > 0, a valid ``area``); raises
        :class:`ConfigError` naming the parameter."""
        if not (np.isfinite(self.match_threshold) and self.match_threshold > 0):
            raise ConfigError(f"match_threshold must be > 0, got {self.match_threshold!r}")
        x0, y0, x1, y1 = (float(v) for v in self.area)
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(
                f"area must be (xmin, ymin, xmax, ymax) with max > min, got {self.area!r}")

    # -- storage (a subclass's ``to_arrays`` / ``from_arrays``) ------------------------------------
    def _arrays(self, **own: np.ndarray) -> dict[str, np.ndarray]:
        """The fitted model as named arrays: the samples, their classes, the landing scatter, the
        parameters every class has and ``own`` (the class's own parameters and what it learned).
        """
        self._check_fitted()
        return {
            "class_features": self.class_features_.copy(),
            "actions": self.actions_.copy(),
            "labels": self.labels_.copy(),
            "reach_sd_fitted": np.float64(self.reach_sd_),
            "match_threshold": np.float64(self.match_threshold),
            "area": np.asarray(self.area, float),
            **own,
        }

    @classmethod
    def _from_stored(cls, d: Mapping, kind: str, params: Callable[[Mapping], dict],
                     fitted: Callable[[Mapping], tuple] = lambda d: ()) -> ModelBase:
        """Rebuild a model from :meth:`_arrays` output (``params(d)``: the class's parameters,
        ``fitted(d)``: what it learned besides the samples).

        Raises
        ------
        ArtifactError
            Where ``d`` is not a stored ``kind`` model.
        """
        try:
            model = cls(match_threshold=float(d["match_threshold"]),
                        area=tuple(float(v) for v in np.asarray(d["area"]).reshape(4)),
                        **params(d))
            model._check_params()
            model._set_fitted(np.asarray(d["class_features"], float),
                              np.asarray(d["actions"], float).reshape(-1, 2),
                              np.asarray(d["labels"], np.int64), *fitted(d),
                              float(d["reach_sd_fitted"]))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise ArtifactError(
                f"not a stored {kind} model ({type(exc).__name__}: {exc})") from None
        return model

    def _pair_logp(self, code: int, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(log p(on the lower class's side), log p(on the higher's)) of the pair ``code`` at
        each of the points ``q`` (n, 2): the subclass's contest."""
        raise NotImplementedError

    # -- prediction -----------------------------------------------------------------------------
    def _slot_scores(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidate classes ``(n, k)`` and their log-scores ``(n, k)`` at each point; repeated
        classes get -inf."""
        n = len(q)
        k = int(min(self.n_neighbors, len(self.actions_)))
        _, idx = self._tree.query(q, k=k)
        cls = self.labels_[np.asarray(idx).reshape(n, k)]
        first = np.ones((n, k), dtype=bool)
        for c in range(1, k):  # k columns, each vectorized over the points
            first[:, c] = ~(cls[:, :c] == cls[:, c : c + 1]).any(axis=1)
        score = np.where(first, 0.0, -np.inf)
        near = first.sum(axis=1) >= 2
        if not near.any() or not self._pairs:
            return cls, score
        rows_l, sa_l, sb_l = [], [], []
        for a in range(k):
            for b in range(a + 1, k):
                r = np.flatnonzero(near & first[:, a] & first[:, b])
                rows_l.append(r)
                sa_l.append(np.full(len(r), a))
                sb_l.append(np.full(len(r), b))
        rows, sa, sb = np.concatenate(rows_l), np.concatenate(sa_l), np.concatenate(sb_l)
        ca, cb = cls[rows, sa], cls[rows, sb]
        swap = ca > cb
        slo, shi = np.where(swap, sb, sa), np.where(swap, sa, sb)
        nc = len(self.class_features_)
        code = np.minimum(ca, cb) * nc + np.maximum(ca, cb)
        for c in np.unique(code):
            if int(c) not in self._pairs:
                continue  # sounds that never met: no boundary between them to judge by
            sel = np.flatnonzero(code == c)
            lp_lo, lp_hi = self._pair_logp(int(c), q[rows[sel]])
            np.add.at(score, (rows[sel], slo[sel]), lp_lo + _NEUTRAL)
            np.add.at(score, (rows[sel], shi[sel]), lp_hi + _NEUTRAL)
        return cls, score

    def _predict(self, points: np.ndarray, proba: bool) -> np.ndarray:
        self._check_fitted()
        q = np.asarray(points, float).reshape(-1, 2)
        nc = self.n_classes
        out = np.zeros((len(q), nc)) if proba else np.zeros(len(q), dtype=np.int64)
        for start in range(0, len(q), _CHUNK):
            blk = slice(start, start + _CHUNK)
            cls, score = self._slot_scores(q[blk])
            if proba:
                m = score.max(axis=1, keepdims=True)
                w = np.exp(score - m)
                w /= w.sum(axis=1, keepdims=True)
                r = np.repeat(np.arange(len(cls)), cls.shape[1])
                block = np.zeros((len(cls), nc))
                np.add.at(block, (r, cls.ravel()), w.ravel())
                out[blk] = block
            else:
                # ties (no boundary between two candidates) go to the nearer sample's class
                tie = -1e-9 * np.arange(cls.shape[1])
                out[blk] = cls[np.arange(len(cls)), np.argmax(score + tie, axis=1)]
        return out

    def predict_proba(self, points: np.ndarray) -> np.ndarray:
        """(n, C) p(sound class | action) at each of ``points`` (n, 2), mixed with a uniform
        ``floor`` where the class has one (``p = (1 - floor) p + floor / C``)."""
        p = self._predict(points, proba=True)
        floor = getattr(self, "floor", 0.0)
        if floor > 0:
            p = (1.0 - floor) * p + floor / p.shape[1]
        return p

    def predict_class(self, points: np.ndarray) -> np.ndarray:
        """(n,) most probable sound class at each point."""
        return self._predict(points, proba=False)

    def confusion(self, points: np.ndarray) -> np.ndarray:
        """(n,) the confusion factor 1 - (p1 - p2): 0 where sure, 1 on a boundary."""
        p = np.sort(self.predict_proba(points), axis=1)
        if p.shape[1] < 2:
            return np.zeros(len(p))
        return 1.0 - (p[:, -1] - p[:, -2])

    def classify(self, perceived: np.ndarray) -> np.ndarray:
        """(n,) class of perceived sounds: 0 silence, -1 unknown (Eq. 2 matching)."""
        self._check_fitted()
        return classify_features(perceived, self.class_features_, self.match_threshold)

    def sample_actions(self, cls: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) draws from p(action | sound class ``cls``), uniform prior over the area, by
        rejection sampling over the box of the class's samples.

        Raises
        ------
        ValueError
            If ``cls`` is not a class of the model.
        """
        self._check_fitted()
        if not 0 <= cls < self.n_classes:
            raise ValueError(f"class {cls} out of range 0..{self.n_classes - 1}")
        x0, y0, x1, y1 = (float(v) for v in self.area)
        lo, hi = np.array([x0, y0]), np.array([x1, y1])
        mine = self.actions_[self.labels_ == cls]
        if cls != SILENCE and len(mine) and len(self.actions_) > 1:
            pad = float(np.max(self._tree.query(mine, k=2)[0][:, 1])) + 1.0
            lo = np.maximum(lo, mine.min(axis=0) - pad)
            hi = np.minimum(hi, mine.max(axis=0) + pad)
        out = np.empty((0, 2))
        for _ in range(1000):
            if len(out) >= n:
                break
            prop = rng.uniform(lo, hi, size=(max(4 * (n - len(out)), 64), 2))
            keep = rng.uniform(size=len(prop)) < self.predict_proba(prop)[:, cls]
            out = np.vstack([out, prop[keep]])
        if len(out) < n:
            raise ValueError(f"class {cls} has (almost) no support in the working area")
        return out[:n]

    def raster(self, step: float = 1.0) -> ProbabilityRaster:
        """p(class | point) on a grid of cells of ``step`` px over the working area."""
        origin, pts = grid_points(tuple(float(v) for v in self.area), step)
        probs = self.predict_proba(pts.reshape(-1, 2)).astype(np.float32)
        return ProbabilityRaster(
            origin=origin, step=float(step), probs=probs.reshape(*pts.shape[:2], -1)
        )

    def predict(self, points: np.ndarray) -> np.ndarray:
        """(n,) most probable sound class at each point (:meth:`predict_class`)."""
        return self.predict_class(points)
