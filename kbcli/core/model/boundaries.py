"""Where the ``lines`` model's boundary lines can be, and how sure it is (the band of each line).

A line separating the samples heard on either side must pass between their hulls
(:func:`line_hulls`); the band's width along the line is its uncertainty (:func:`band`). A pair
with several pieces has one sound inside (:func:`pair_inside`), on its side of every piece, the
other of any one (:func:`log_any`).
"""

from __future__ import annotations

import numpy as np

#: Per line: (t, v) vertices of the hull the line passes under, then of the one it passes over.
Hull = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def log_any(log_miss: np.ndarray) -> np.ndarray:
    """log(1 - prod_k exp(log_miss_k)) along axis 1: the log-probability of at least one hit."""
    return np.log(-np.expm1(np.minimum(log_miss.sum(axis=1), -1e-300)))


def lower_hull(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (sorted by t) of the lower convex hull of points (t, v) (monotone chain)."""
    order = np.lexsort((v, t))
    t, v = t[order], v[order]
    keep_t, keep_v = np.unique(t, return_index=True)  # lowest v per t
    t, v = keep_t, v[keep_v]
    ht: list[float] = []
    hv: list[float] = []
    for ti, vi in zip(t.tolist(), v.tolist(), strict=True):  # a few points per boundary piece
        while len(ht) >= 2 and (
            (ht[-1] - ht[-2]) * (vi - hv[-2]) - (hv[-1] - hv[-2]) * (ti - ht[-2]) <= 0
        ):
            ht.pop()
            hv.pop()
        ht.append(ti)
        hv.append(vi)
    return np.array(ht), np.array(hv)


def line_hulls(
    actions: np.ndarray, pos: np.ndarray, neg: np.ndarray, edge_line: np.ndarray,
    lines: np.ndarray,
) -> tuple[list[Hull], np.ndarray]:
    """The hulls that bound where each boundary line can be, and the span where both sides have
    samples.

    Parameters
    ----------
    actions : (n, 2) ndarray
        The samples.
    pos, neg : (m,) int ndarrays
        Per straddling edge, its sample on the positive / negative side of its line.
    edge_line : (m,) int ndarray
        Line of each straddling edge.
    lines : (L, 3) ndarray
        (nx, ny, c) of each line.

    Returns
    -------
    hulls : list of L :data:`Hull`
        In line coordinates (t along the line, v the signed distance).
    line_range : (L, 2) ndarray
        (max of the hulls' first t, min of their last t).
    """
    hulls: list[Hull] = []
    line_range = np.zeros((len(lines), 2))
    for g in range(len(lines)):  # one loop per boundary line; the hulls bound where it can be
        nx, ny, c = lines[g]
        a = actions[np.unique(pos[edge_line == g])]
        b = actions[np.unique(neg[edge_line == g])]
        ha = lower_hull(a @ (-ny, nx), a @ (nx, ny) - c)  # the line passes under these
        hb = lower_hull(b @ (-ny, nx), c - b @ (nx, ny))  # and over these
        hulls.append((ha[0], ha[1], hb[0], -hb[1]))
        line_range[g] = (max(ha[0][0], hb[0][0]), min(ha[0][-1], hb[0][-1]))
    return hulls, line_range


def piece_extents(
    actions: np.ndarray, edges: np.ndarray, edge_piece: np.ndarray, piece_line: np.ndarray,
    lines: np.ndarray,
) -> np.ndarray:
    """(P, 2) span (min, max of t along its line) of each piece's straddling samples."""
    out = np.zeros((len(piece_line), 2))
    for p in range(len(piece_line)):
        nx, ny, _ = lines[piece_line[p]]
        ends = actions[edges[edge_piece == p].ravel()]
        t = ends @ (-ny, nx)
        out[p] = (t.min(), t.max()) if len(t) else (0.0, 0.0)
    return out


def pair_inside(
    actions: np.ndarray, edges: np.ndarray, edge_piece: np.ndarray, pieces: np.ndarray,
    piece_lines: np.ndarray, piece_sign: np.ndarray,
) -> bool:
    """Whether the lower sound of a pair with several pieces is the one inside.

    The sound inside (a key within silence's L around a corner) must be on its side of every
    piece, the other of any one; it is the one that explains more of the pair's straddling
    samples (ties: the lower class).

    Parameters
    ----------
    pieces : (k,) int ndarray
        The pair's pieces.
    piece_lines : (k, 3) ndarray
        Line of each of them.
    piece_sign : (k,) ndarray
        Their signs.
    """
    ed = edges[np.isin(edge_piece, pieces)]
    ln, sg = piece_lines, piece_sign
    va = (actions[np.unique(ed[:, 0])] @ ln[:, :2].T - ln[:, 2]) * sg
    vb = (actions[np.unique(ed[:, 1])] @ ln[:, :2].T - ln[:, 2]) * sg
    wrong_if_lo = np.sum(~(va > 0).all(axis=1)) + np.sum((vb > 0).all(axis=1))
    wrong_if_hi = np.sum(~(vb < 0).all(axis=1)) + np.sum((va < 0).all(axis=1))
    return bool(wrong_if_lo <= wrong_if_hi)


def band(hull: Hull, line_range: np.ndarray, extrapolation: float,
         t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Width (px) and centre (v) of the band where a line can be, at positions ``t`` along it.

    Inside the span of samples on both sides, a separating line must pass under the lower hull of
    the positive side's samples and over the upper hull of the negative side's; beyond that span
    the band widens by ``2 * extrapolation`` px per px.
    """
    ta, va, tb, vb = hull
    lo, hi = line_range
    tc = np.clip(t, min(lo, hi), max(lo, hi))
    top, bottom = np.interp(tc, ta, va), np.interp(tc, tb, vb)
    out = np.abs(t - tc) + max(lo - hi, 0.0)
    width = np.abs(top - bottom) + 2 * extrapolation * out
    centre = np.where(out > 0, 0.0, (top + bottom) / 2)
    return width, centre
