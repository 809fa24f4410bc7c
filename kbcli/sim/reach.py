"""The arm's workspace: which points, rectangles, keys and keyboards it can reach.

The workspace of a two-link arm is the annulus ``|l1 - l2| <= r <= l1 + l2`` around its shoulder
(``SimConfig.base``). Targets outside it raise :class:`~kbcli.errors.OutOfReachError`; they are
never clipped.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.instrument.geometry import points_in_polygon, segment_distance
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.errors import OutOfReachError
from kbcli.sim.kinematics import SimSpec


def workspace_check(cfg: SimSpec, points: np.ndarray) -> np.ndarray:
    """(n,) bool: whether each point is inside the arm's annular workspace."""
    p = np.asarray(points, float).reshape(-1, 2) - np.asarray(cfg.base)
    r = np.hypot(p[:, 0], p[:, 1])
    l1, l2 = cfg.link_lengths
    return (r >= abs(l1 - l2)) & (r <= l1 + l2) & np.isfinite(r)


def check_reachable(cfg: SimSpec, targets: np.ndarray) -> np.ndarray:
    """``targets`` as an (n, 2) float array; :class:`OutOfReachError` naming the first target
    outside the workspace."""
    t = np.asarray(targets, float).reshape(-1, 2)
    ok = workspace_check(cfg, t)
    if not ok.all():
        bad = t[~ok][0]
        l1, l2 = cfg.link_lengths
        raise OutOfReachError(
            f"target ({bad[0]:.1f}, {bad[1]:.1f}) is outside the arm's workspace "
            f"({abs(l1 - l2):g} to {l1 + l2:g} px from the shoulder at {cfg.base})"
        )
    return t


def rect_reachable(cfg: SimSpec, rects: np.ndarray) -> np.ndarray:
    """(n,) bool: whether each axis-aligned rectangle lies wholly inside the arm's workspace.

    Parameters
    ----------
    rects : (n, 4) ndarray
        (xmin, ymin, xmax, ymax) rows. The workspace is an annulus: a rectangle is inside when its
        farthest corner is within ``l1 + l2`` of the shoulder and its nearest point is at least
        ``|l1 - l2|`` away.
    """
    r = np.asarray(rects, float).reshape(-1, 4)
    b = np.asarray(cfg.base)
    l1, l2 = cfg.link_lengths
    far = np.hypot(np.maximum(np.abs(r[:, 0] - b[0]), np.abs(r[:, 2] - b[0])),
                   np.maximum(np.abs(r[:, 1] - b[1]), np.abs(r[:, 3] - b[1])))
    nearest = np.column_stack([np.clip(b[0], r[:, 0], r[:, 2]), np.clip(b[1], r[:, 1], r[:, 3])])
    near = np.hypot(*(nearest - b).T)
    return (far <= l1 + l2) & (near >= abs(l1 - l2))


def polygons_reachable(cfg: SimSpec, polygons: list[np.ndarray]) -> np.ndarray:
    """(K,) bool: whether each polygon lies wholly inside the arm's annular workspace.

    The outer limit is a disc (convex): a polygon is within it when all its vertices are. The inner
    limit is a hole: a polygon clears it when the shoulder is outside the polygon and every edge
    stays at least ``|l1 - l2|`` from it.
    """
    b = np.asarray(cfg.base, float)
    l1, l2 = cfg.link_lengths
    out = np.empty(len(polygons), dtype=bool)
    for k, poly in enumerate(polygons):  # one per key
        far = np.hypot(*(np.asarray(poly, float) - b).T).max() <= l1 + l2
        near = (segment_distance(b[None], poly)[0] >= abs(l1 - l2)
                and not points_in_polygon(b[None], poly)[0])
        out[k] = far and near
    return out


def check_keyboard_reachable(cfg: SimSpec, keyboard: Keyboard) -> None:
    """Raise OutOfReachError unless the keyboard's whole working area is within the arm's reach.

    The message names the keys out of reach (or says that only the margin is).
    """
    if rect_reachable(cfg, np.asarray(keyboard.area))[0]:
        return
    bad = ~polygons_reachable(cfg, keyboard.key_outlines())
    l1, l2 = cfg.link_lengths
    x0, y0, x1, y1 = keyboard.area
    where = (f"the working area ({x0:g}, {y0:g})-({x1:g}, {y1:g}) is not all within the arm's "
             f"reach ({abs(l1 - l2):g} to {l1 + l2:g} px from the shoulder at "
             f"({cfg.base[0]:g}, {cfg.base[1]:g}))")
    if bad.any():
        names = [keyboard.key_label(k) for k in np.flatnonzero(bad)]
        shown = ", ".join(names[:12]) + (f" and {len(names) - 12} more" if len(names) > 12 else "")
        raise OutOfReachError(f"{where}: {len(names)} key(s) out of reach: {shown}")
    raise OutOfReachError(f"{where}: every key is reachable but part of the margin is not")
