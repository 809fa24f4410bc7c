"""How good a model of the instrument is, against the simulator's ground truth.

Two scores, both on a dense grid of cell centres over the keyboard's working area:

- **accuracy**: the share of grid points whose sound the model predicts right (a model's class
  read as a key by Eq. 2 matching; class 0 is silence; a class that matches no key is wrong).
- **boundary error** (px): with P the model's edge cells (a cell whose right or upper neighbour
  has a different key) and T the true ones,

      boundary_error = (sum_{p in P} d(p, T) + sum_{t in T} d(t, P)) / (|P| + |T|),

  d(x, S) the distance (px) from cell x to the nearest cell of S: 0 for a perfect map, about k
  for edges k px off.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import distance_transform_edt

from kbcli.core.instrument.keyboard import Keyboard, match
from kbcli.core.model.base import grid_points

WRONG = -2  # a model class that matches no key


def class_keys(class_features: np.ndarray, keyboard: Keyboard) -> np.ndarray:
    """(C,) key index of each model class: -1 for silence (class 0), ``WRONG`` if none matches."""
    f = np.asarray(class_features, float)
    keys = np.full(len(f), WRONG, dtype=np.int64)
    keys[0] = -1
    if len(f) > 1:
        m = match(f[1:], keyboard.features, keyboard.config.match_threshold)
        keys[1:] = np.where(m >= 0, m, WRONG)
    return keys


def key_maps(model, keyboard: Keyboard, step: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Predicted and true key of every grid cell over the working area.

    Parameters
    ----------
    model : SoundModel
        Anything with ``class_features_`` and ``predict_proba`` (or ``predict_class``).
    keyboard : Keyboard
        The ground truth at its reference pose.
    step : float
        Cell size, px.

    Returns
    -------
    predicted, true : (H, W) int ndarrays
        Key index (-1 silence, ``WRONG`` an unmatched class) per cell; row i is y.
    """
    _, pts = grid_points(keyboard.area, step)
    flat = pts.reshape(-1, 2)
    if hasattr(model, "predict_class"):
        cls = model.predict_class(flat)
    else:
        cls = np.argmax(model.predict_proba(flat), axis=1)
    pred = class_keys(model.class_features_, keyboard)[cls]
    return pred.reshape(pts.shape[:2]), keyboard.key_at(flat).reshape(pts.shape[:2])


def accuracy_from_maps(predicted: np.ndarray, true: np.ndarray) -> float:
    """Share of cells where the predicted key is the true one."""
    return float(np.mean(np.asarray(predicted) == np.asarray(true)))


def accuracy(model, keyboard: Keyboard, step: float = 1.0) -> float:
    """Share of a grid of ``step`` px over the working area whose sound ``model`` predicts right."""
    return accuracy_from_maps(*key_maps(model, keyboard, step))


def edge_cells(keys: np.ndarray) -> np.ndarray:
    """(H, W) bool: cells whose right or upper neighbour holds a different key."""
    k = np.asarray(keys)
    e = np.zeros(k.shape, dtype=bool)
    e[:, :-1] |= k[:, :-1] != k[:, 1:]
    e[:-1, :] |= k[:-1, :] != k[1:, :]
    return e


def boundary_error(predicted: np.ndarray, true: np.ndarray, step: float = 1.0) -> float:
    """Symmetric mean distance (px) between predicted and true key edges (module docstring).

    Returns 0 when neither map has an edge, and inf when only one of them has.
    """
    p, t = edge_cells(predicted), edge_cells(true)
    if not p.any() and not t.any():
        return 0.0
    if not p.any() or not t.any():
        return float("inf")
    to_t = distance_transform_edt(~t) * step
    to_p = distance_transform_edt(~p) * step
    return float((to_t[p].sum() + to_p[t].sum()) / (p.sum() + t.sum()))
