"""What a robot hands the adapter, checked at the door: an action inside the working area, a felt
position, heard features. Each check returns the value as a float array or raises
:class:`~kbcli.errors.ObservationError` naming what is wrong, before any belief changes.
"""

from __future__ import annotations

import numpy as np

from kbcli.errors import ObservationError


def check_point(v, name: str) -> np.ndarray:
    """``v`` as a finite (2,) float array; raises :class:`ObservationError`."""
    try:
        p = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ObservationError(f"{name} must be two numbers (x, y in pad px), got {v!r}") from None
    if p.shape != (2,) or not np.isfinite(p).all():
        raise ObservationError(f"{name} must be two finite numbers (x, y in pad px), got "
                               f"{np.asarray(v).tolist() if p.size < 8 else f'{p.size} values'}")
    return p


def check_action(action, area: tuple[float, float, float, float],
                 name: str = "action") -> np.ndarray:
    """``action`` as a (2,) array inside ``area`` (xmin, ymin, xmax, ymax; up to a rounding
    tolerance); raises :class:`ObservationError`."""
    a = check_point(action, name)
    x0, y0, x1, y1 = area
    tol = 1e-9 * max(1.0, abs(x1 - x0), abs(y1 - y0))
    if not (x0 - tol <= a[0] <= x1 + tol and y0 - tol <= a[1] <= y1 + tol):
        raise ObservationError(f"{name} ({a[0]:g}, {a[1]:g}) is outside the working area "
                               f"({x0:g}, {y0:g})-({x1:g}, {y1:g})")
    return a


def check_heard(heard, d: int) -> np.ndarray:
    """``heard`` as a (d,) float array (None, or all NaN: silence); raises
    :class:`ObservationError`."""
    if heard is None:
        return np.full(d, np.nan)
    try:
        h = np.asarray(heard, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ObservationError(f"heard features must be {d} numbers or null (silence), got "
                               f"{heard!r}") from None
    if h.shape != (d,):
        raise ObservationError(f"heard features must be {d} numbers (or null for silence), "
                               f"got {h.size}")
    nan = np.isnan(h)
    if (nan.any() and not nan.all()) or np.isinf(h).any():
        raise ObservationError(f"heard features must be all finite (or all missing for "
                               f"silence), got {h.tolist()}")
    return h
