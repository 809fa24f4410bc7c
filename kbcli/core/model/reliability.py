"""How good a learned model is, estimated from its own samples; and its calibration.

``K``-fold cross-validation over the exploration samples estimates ``cv_error`` (the mislabel rate
of held-out touches), ``cv_log_loss`` (their mean ``-log p(heard sound | touch)``, nats),
``cv_ece`` (:func:`expected_calibration_error`), ``boundary_error`` (how far, px, the fold models'
boundaries lie from the full model's, a stand-in for the distance to the truth) and
``expected_error`` (one minus the calibrated model's top probability averaged over a 2 px grid).

It also **calibrates** p(sound | action): among the class's ``calibration_grid()`` (read at
prediction time) and ``fit_grid()`` (refitted with each) values it keeps those with the lowest
distance-weighted held-out Brier score when they beat the model's own settings by more than one
standard error (:func:`choose_calibration`; why: ``docs/design-notes.md``).
"""

from __future__ import annotations

import copy
import itertools
from dataclasses import dataclass

import numpy as np
from sklearn.base import clone

from kbcli.core.config import Record
from kbcli.core.model.accuracy import boundary_error as _boundary_error
from kbcli.core.model.base import grid_points
from kbcli.core.model.heldout import (
    area_weights,
    class_map,
    distance_weights,
    fold_ids,
    held_out_probs,
)

#: Folds of the cross-validation.
FOLDS = 5
#: Cell (px) of the grid on which fold boundaries are compared.
BOUNDARY_STEP = 2.0
ECE_BINS = 15
#: A calibration replaces the model's own (uncalibrated) settings only when it beats them on the
#: held-out score by more than this many standard errors of the paired difference.
SE_MARGIN = 1.0


@dataclass(frozen=True)
class Reliability(Record):
    """A model's own estimate of how good it is (see the module docstring)."""

    folds: int
    samples: int
    cv_error: float
    cv_log_loss: float
    cv_ece: float
    boundary_error: float
    calibration: dict
    expected_error: float


def expected_calibration_error(probs: np.ndarray, hit: np.ndarray, bins: int = ECE_BINS,
                               weights: np.ndarray | None = None, debiased: bool = False) -> float:
    """Top-label expected calibration error, ``sum_b n_b / n |mean(hit)_b - mean(confidence)_b|``
    over ``bins`` equal-width bins of the top probability (``n_b`` the weight in bin ``b``).

    Parameters
    ----------
    probs : (n, C) ndarray
        Predicted distributions.
    hit : (n,) or (n, C) ndarray
        Whether (or how often) the most probable class was right: (n,) values in [0, 1], or an
        (n, C) true distribution of the outcome (its entry at the predicted class is taken).
    weights : (n,) ndarray, optional
        Weight of each prediction (default: equal).
    debiased : bool
        For ``hit`` drawn once per prediction: the square root of the plug-in squared gap less
        its sampling variance ``a_b (1 - a_b) / (n_b - 1)``, floored at 0 (Kumar, Liang and Ma
        2019, "Verified uncertainty calibration").
    """
    p = np.asarray(probs, float)
    conf = p.max(axis=1)
    h = np.asarray(hit, float)
    if h.ndim == 2:
        h = h[np.arange(len(p)), p.argmax(axis=1)]
    w = np.ones(len(p)) if weights is None else np.asarray(weights, float)
    idx = np.minimum((conf * bins).astype(np.int64), bins - 1)
    sum_c = np.bincount(idx, weights=w * conf, minlength=bins)
    sum_h = np.bincount(idx, weights=w * h, minlength=bins)
    total = float(w.sum())
    if total <= 0:
        return float("nan")
    if not debiased:
        return float(np.abs(sum_h - sum_c).sum() / total)
    sum_w = np.bincount(idx, weights=w, minlength=bins)
    sum_w2 = np.bincount(idx, weights=w * w, minlength=bins)
    live = sum_w > 0
    wb, acc, c = sum_w[live], sum_h[live] / sum_w[live], sum_c[live] / sum_w[live]
    n_eff = wb ** 2 / sum_w2[live]
    var = acc * (1 - acc) / np.maximum(n_eff - 1, 1.0)
    return float((wb * np.sqrt(np.maximum((acc - c) ** 2 - var, 0.0))).sum() / total)


def _own_index(model, names: list[str], combos: list[tuple]) -> int:
    """Index in ``combos`` of ``model``'s own values of the parameters ``names`` (0 if absent)."""
    own = tuple(getattr(model, nm, None) for nm in names)
    return combos.index(own) if own in combos else 0


def choose_calibration(scores: np.ndarray, weights: np.ndarray,
                       own: tuple[int, ...], margin: float = SE_MARGIN) -> tuple[int, ...]:
    """The calibration to keep, from each candidate's held-out scores ``scores``
    (*candidates, n) (lower is better) and the touches' ``weights`` (n,).

    Returns the index of the candidate with the best weighted mean score among those that beat
    ``own`` (the model's own settings) by more than ``margin`` standard errors of the paired
    difference, or ``own`` when none does.
    """
    shape = scores.shape[:-1]
    b = scores.reshape(-1, scores.shape[-1])
    w = np.asarray(weights, float)
    ref = int(np.ravel_multi_index(own, shape))
    mean = b @ w
    gain = mean - mean[ref]
    se = np.sqrt(((b - b[ref] - gain[:, None]) ** 2) @ (w * w))
    ok = gain < -margin * se
    ok[ref] = True
    live = np.flatnonzero(ok)
    return tuple(int(i) for i in np.unravel_index(int(live[np.argmin(mean[live])]), shape))


def _grid(model, method: str, calibrate: bool) -> tuple[list[str], list[tuple]]:
    """Names and every combination of the candidate values of a model's ``method()`` grid."""
    cands = getattr(model, method, lambda: {})() if calibrate else {}
    names = sorted(cands)
    return names, list(itertools.product(*(cands[nm] for nm in names))) or [()]


def _refit(model, x: np.ndarray, s: np.ndarray, params: dict):
    """A fresh model of ``model``'s class and settings, ``params`` on top, fitted to (x, s)."""
    return clone(model).set_params(**params).fit(x, s)


def _recalibrated(model, params: dict):
    """A copy of the fitted ``model`` with the prediction-time ``params`` set."""
    return copy.copy(model).set_params(**params)


@dataclass
class _CrossValidation:
    """Held-out predictions of every fold under every candidate calibration."""

    held: np.ndarray  # (F, P, n, C) in the full model's classes
    boundary: list[list[float]]  # per fit candidate, each fold's boundary error
    fulls: list  # per fit candidate, the model fitted on every sample


def _cross_validate(full_model, x: np.ndarray, s: np.ndarray, fold: np.ndarray, k: int,
                    pts: np.ndarray, grids: tuple) -> _CrossValidation:
    """Fit the folds with every fit candidate and predict their held-out touches with every
    prediction-time candidate."""
    (names, combos), (fit_names, fit_combos) = grids
    flat = pts.reshape(-1, 2)
    c_full, thr = full_model.n_classes, full_model.match_threshold
    cv = _CrossValidation(np.zeros((len(fit_combos), len(combos), len(x), c_full)), [], [])
    for j, fc in enumerate(fit_combos):  # F x (K + 1) fits
        fp = dict(zip(fit_names, fc, strict=True))
        full_j = _refit(full_model, x, s, fp) if fp else full_model
        cv.fulls.append(full_j)
        cmap_full = class_map(full_j.class_features_, full_model.class_features_, thr)
        full_map = cmap_full[full_j.predict_class(flat)].reshape(pts.shape[:2])
        cv.boundary.append([])
        for f in range(k):
            test = fold == f
            if test.all() or not test.any():
                continue
            m = _refit(full_model, x[~test], s[~test], fp)
            cmap = class_map(m.class_features_, full_model.class_features_, thr)
            fold_map = cmap[m.predict_class(flat)].reshape(pts.shape[:2])
            cv.boundary[j].append(_boundary_error(fold_map, full_map, BOUNDARY_STEP))
            for i, combo in enumerate(combos):
                mc = _recalibrated(m, dict(zip(names, combo, strict=True)))
                cv.held[j, i, test] = held_out_probs(mc, x[test], cmap, c_full)
    return cv


def _choose(full_model, hk: np.ndarray, p_true: np.ndarray, wd: np.ndarray,
            grids: tuple) -> tuple[int, int]:
    """(fit candidate, prediction-time candidate) of the calibration to keep: the Brier score of
    every held-out touch (``hk`` (F, P, n, C) held-out predictions, ``p_true`` (F, P, n) their
    probability of the heard sound) weighted by ``wd`` (:func:`choose_calibration`)."""
    (names, combos), (fit_names, fit_combos) = grids
    wd = wd / wd.sum() if wd.sum() > 0 else wd
    scores = (hk ** 2).sum(axis=-1) - 2 * p_true + 1  # (F, P, n_known) Brier of each touch
    own = (_own_index(full_model, fit_names, fit_combos), _own_index(full_model, names, combos))
    return choose_calibration(scores, wd, own)


def assess(full_model, actions: np.ndarray, perceived: np.ndarray, *,
           rng: np.random.Generator, folds: int = FOLDS,
           calibrate: bool = True) -> tuple[object, Reliability]:
    """Cross-validate a model class on its samples, calibrate it, and estimate its reliability.

    Parameters
    ----------
    full_model : ModelBase
        The model fitted on every sample; each fold's model is a clone of it.
    actions, perceived : (n, 2), (n, D) ndarrays
        The samples (where the robot felt it touched, what it heard).
    rng : numpy.random.Generator
        Assigns samples to folds.
    calibrate : bool
        Choose the calibration parameters, if the model has any (:func:`choose_calibration`).

    Returns
    -------
    model : ModelBase
        ``full_model`` with the chosen calibration (a copy or a refit; the original unchanged).
    reliability : Reliability
    """
    x = np.asarray(actions, float).reshape(-1, 2)
    s = np.asarray(perceived, float).reshape(len(x), -1)
    n = len(x)
    labels = full_model.classify(s)
    k = int(min(folds, n))
    grids = (_grid(full_model, "calibration_grid", calibrate),
             _grid(full_model, "fit_grid", calibrate))
    (names, combos), (fit_names, fit_combos) = grids
    fold = fold_ids(n, k, rng)
    _, pts = grid_points(tuple(float(v) for v in full_model.area), BOUNDARY_STEP)
    flat = pts.reshape(-1, 2)
    cv = _cross_validate(full_model, x, s, fold, k, pts, grids)
    known = labels >= 0
    w = area_weights(x)[known]
    hk = cv.held[:, :, known, :]
    p_true = hk[:, :, np.arange(known.sum()), labels[known]]  # (F, P, n_known)
    nll = -(np.log(np.maximum(p_true, 1e-12)) @ w)  # (F, P)
    bj, bi = _choose(full_model, hk, p_true, distance_weights(x, fold, flat)[known], grids)
    at_predict = dict(zip(names, combos[bi], strict=True))
    chosen = {**dict(zip(fit_names, fit_combos[bj], strict=True)), **at_predict}
    model = _recalibrated(cv.fulls[bj], at_predict)
    hit = cv.held[bj, bi, known].argmax(axis=1) == labels[known]
    finite = [b for b in cv.boundary[bj] if np.isfinite(b)]
    rel = Reliability(
        folds=k,
        samples=n,
        cv_error=float(1.0 - hit @ w) if len(hit) else float("nan"),
        cv_log_loss=float(nll[bj, bi]),
        cv_ece=expected_calibration_error(cv.held[bj, bi, known], hit.astype(float), weights=w,
                                          debiased=True) if len(hit) else float("nan"),
        boundary_error=float(np.mean(finite)) if finite else float("inf"),
        calibration={nm: float(v) for nm, v in chosen.items()},
        expected_error=float(1.0 - model.predict_proba(flat).max(axis=1).mean()),
    )
    return model, rel


__all__ = ["Reliability", "assess", "choose_calibration", "expected_calibration_error", "FOLDS"]
