"""What a weak model's own samples allow: its training samples registered to the moved keyboard.

The **samples floor** of a model is measured as if the whole moved keyboard were known: the shifts
``h`` under which the fewest of the model's training samples, put at ``x_i + h``, disagree with the
moved keyboard's key there, searched on a ``+-HALF`` px square at ``STEP`` px around the true
shift; the floor is the distance of their centre to the truth. The touches of an adaptation see
less than the whole keyboard, so no method that learns the keyboard from those samples can be
expected to beat it. For a translation it is the same for every move. Pure: arrays in, a float out.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.model.accuracy import class_keys

#: Half-width (px) and step (px) of the searched shifts around the truth.
HALF, STEP = 4.0, 0.25


def samples_floor(actions: np.ndarray, keys: np.ndarray, keyboard, truth: np.ndarray) -> float:
    """Distance (px) from ``truth`` (2,) to the centre of the shifts ``h`` with the fewest samples
    at ``actions + h`` (n, 2) whose key ``keys`` (n,) (-1: silence) differs from the key of
    ``keyboard`` moved by ``truth``."""
    off = np.arange(-HALF, HALF + STEP / 2, STEP)
    pts = np.asarray(actions, float).reshape(-1, 2) + np.asarray(truth, float)
    miss = np.array([[int((keyboard.key_at(pts + [dx, dy], truth) != keys).sum())
                      for dx in off] for dy in off])
    iy, ix = np.nonzero(miss == miss.min())
    return float(np.hypot(off[ix].mean(), off[iy].mean()))


def model_floor(model, keyboard) -> float:
    """The samples floor of a learned ``model`` (training samples ``actions_``, ``labels_``) on
    ``keyboard`` (a sample of a sound no key makes disagrees at every shift alike)."""
    keys = class_keys(model.class_features_, keyboard)[np.asarray(model.labels_)]
    return samples_floor(model.actions_, keys, keyboard, np.zeros(2))
