"""Straight boundary pieces between neighbouring sounds (the ``lines`` model's fit).

Each pair of sounds' straddling edges get the max-margin line separating their ends
(:func:`separating_line`), split by the direction in which they cross where no line separates them
(:func:`split_pieces`); pieces whose lines nearly coincide are merged (:func:`merge_pieces`) and a
lone piece crossed by shared lines is re-expressed with them (:func:`absorb_pieces`).
:func:`fit_pieces` runs the steps.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.model.separation import separating_line
from kbcli.core.model.sounds import straddling_edges


def split_pieces(x: np.ndarray, e: np.ndarray, depth: int = 0,
            tol: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split the straddling edges of one pair of sounds into straight boundary pieces.

    The pair's edges get one max-margin line if it separates their two ends; otherwise (an L- or
    U-shaped boundary, e.g. silence around a corner key) they are split in two by the direction
    in which they cross the boundary (2-means on unit edge directions) and each half is treated
    alike, at most 4 levels deep.

    Returns
    -------
    list of (edge rows, line)
    """
    ua, ub = np.unique(e[:, 0]), np.unique(e[:, 1])
    line, ok = separating_line(x[ua], x[ub], tol)
    if ok or len(e) < 2 or depth >= 4:
        return [(np.arange(len(e)), line)]
    d = x[e[:, 0]] - x[e[:, 1]]
    u = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    j = int(np.argmin(u @ u[0]))
    centres = np.stack([u[j], u[int(np.argmin(u @ u[j]))]])
    side = np.zeros(len(u), dtype=bool)
    for _ in range(10):  # 2-means on directions, a few iterations
        side = (u @ centres[1]) > (u @ centres[0])
        if side.all() or not side.any():
            return [(np.arange(len(e)), line)]
        m = np.stack([u[~side].mean(axis=0), u[side].mean(axis=0)])
        centres = m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-12)
    out = []
    for part in (np.flatnonzero(~side), np.flatnonzero(side)):
        out += [(part[sub], ln) for sub, ln in split_pieces(x, e[part], depth + 1, tol)]
    return out


def merge_pieces(
    x: np.ndarray, e: np.ndarray, piece_rows: list[np.ndarray], lines: np.ndarray,
    max_angle: float, max_offset: float, tol: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Group boundary pieces that one straight line explains (an edge continuing across keys).

    Pieces whose lines are within ``max_angle`` rad and ``max_offset`` px are merged, closest
    first, when a single line still separates the samples on either side of all of them.

    Returns
    -------
    group : (P,) int ndarray
        Line (group) of each piece, numbered by first piece.
    sign : (P,) ndarray
        +1 where the piece's lower class is on the positive side of its group's line, else -1.
    group_lines : (G, 3) ndarray
        (nx, ny, c) of each group's line.
    """
    npc = len(piece_rows)
    side_a = [np.unique(e[r, 0]) for r in piece_rows]  # sample indices on the lower class's side
    side_b = [np.unique(e[r, 1]) for r in piece_rows]
    p_i, q_i, cos = _merge_candidates(x, side_a, side_b, lines, max_angle, max_offset)
    root = np.arange(npc)
    sign = np.ones(npc)
    members = {p: [p] for p in range(npc)}
    pts = {p: (side_a[p], side_b[p]) for p in range(npc)}
    glines = {p: lines[p].copy() for p in range(npc)}
    for p, q in zip(p_i.tolist(), q_i.tolist(), strict=True):  # candidate merges, closest first
        rp, rq = int(root[p]), int(root[q])
        if rp == rq:
            continue
        aligned = np.sign(cos[p, q]) * sign[p] * sign[q] > 0
        ap, bp = pts[rp]
        aq, bq = pts[rq] if aligned else pts[rq][::-1]
        a, b = np.union1d(ap, aq), np.union1d(bp, bq)
        if np.intersect1d(a, b).size:
            continue
        line, separable = separating_line(x[a], x[b], tol)
        if not separable:
            continue
        for m in members[rq]:
            root[m] = rp
            if not aligned:
                sign[m] = -sign[m]
        members[rp] += members.pop(rq)
        pts[rp] = (a, b)
        glines[rp] = line
        del pts[rq], glines[rq]
    group, group_lines = _numbered(root, glines)
    return group, sign, group_lines


def _merge_candidates(x: np.ndarray, side_a: list[np.ndarray], side_b: list[np.ndarray],
                      lines: np.ndarray, max_angle: float,
                      max_offset: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs of pieces (p < q) whose lines are within ``max_angle`` rad and ``max_offset`` px
    of each other, closest first, and the cosines between all the pieces' lines (P, P)."""
    centre = np.array([x[np.r_[a, b]].mean(axis=0) for a, b in zip(side_a, side_b, strict=True)])
    centre = centre.reshape(-1, 2)
    n, c = lines[:, :2], lines[:, 2]
    cos = n @ n.T
    off = np.abs(centre @ n.T - c[None, :])  # off[q, p]: piece q's centre from piece p's line
    p_i, q_i = np.triu_indices(len(side_a), 1)
    ok = (np.abs(cos[p_i, q_i]) >= np.cos(max_angle)) & (off[q_i, p_i] < max_offset) & (
        off[p_i, q_i] < max_offset
    )
    p_i, q_i = p_i[ok], q_i[ok]
    order = np.argsort(off[q_i, p_i] + off[p_i, q_i], kind="stable")
    return p_i[order], q_i[order], cos


def _numbered(root: np.ndarray, glines: dict) -> tuple[np.ndarray, np.ndarray]:
    """(group of each piece, (G, 3) group lines), the groups numbered by their first piece, so the
    layout does not depend on merge order."""
    roots, group = np.unique(root, return_inverse=True)
    first = np.array([np.flatnonzero(group == g)[0] for g in range(len(roots))], dtype=np.int64)
    rank = np.empty(len(roots), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(roots))
    group_lines = np.array([glines[int(r)] for r in roots])[np.argsort(first)]
    return rank[group], group_lines.reshape(-1, 3)


def line_sides(
    e: np.ndarray, edge_piece: np.ndarray, sign: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per straddling edge, the sample on its line's positive side and the one on its negative."""
    flip = sign[edge_piece] < 0
    return np.where(flip, e[:, 1], e[:, 0]), np.where(flip, e[:, 0], e[:, 1])


def absorb_pieces(
    x: np.ndarray, e: np.ndarray, edge_piece: np.ndarray, pairs: np.ndarray, group: np.ndarray,
    sign: np.ndarray, glines: np.ndarray, reach: float, tol: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Re-express lone boundary pieces with lines that several pieces share: a piece alone on its
    line is replaced by pieces on shared lines when every one of its straddling edges is crossed
    by one (within ``reach`` px of its samples, each in one direction) and each still separates
    its samples (then refitted). Returns ``edge_piece, pairs, group, sign, glines`` renumbered."""
    edge_piece, pairs = edge_piece.copy(), [tuple(p) for p in pairs]
    group, sign, glines = list(group), list(sign), [g.copy() for g in glines]
    sizes = np.bincount(np.asarray(group), minlength=len(glines))
    pos, neg = line_sides(e, edge_piece, np.asarray(sign))
    sets = {}
    for g in np.flatnonzero(sizes >= 2):
        on = np.asarray(group)[edge_piece] == g
        sets[int(g)] = (np.unique(pos[on]), np.unique(neg[on]))
    if not sets:
        return _renumber(edge_piece, np.array(pairs), group, sign, glines)
    removed = set()
    for p in np.flatnonzero(sizes[np.asarray(group)] == 1):  # one loop per lone piece
        p = int(p)
        rows = np.flatnonzero(edge_piece == p)
        strong = np.array(sorted(sets))
        crossing = _crossings(x, e, rows, strong, glines, sets, reach)
        if crossing is None:
            continue
        plan = _absorb_plan(x, e, rows, *crossing, strong, sets, tol)
        if plan is None:
            continue
        removed.add(p)
        for g, (sel, o, pa, na, line) in plan.items():
            edge_piece[sel] = len(pairs)
            pairs.append(pairs[p])
            group.append(g)
            sign.append(o)
            sets[g] = (pa, na)
            glines[g] = line
    keep = np.array([q not in removed for q in range(len(pairs))], dtype=bool)
    remap = np.cumsum(keep) - 1
    edge_piece = remap[edge_piece]
    return _renumber(
        edge_piece, np.array(pairs)[keep], list(np.asarray(group)[keep]),
        list(np.asarray(sign)[keep]), glines,
    )


def _crossings(x: np.ndarray, e: np.ndarray, rows: np.ndarray, strong: np.ndarray, glines: list,
               sets: dict, reach: float) -> tuple[np.ndarray, np.ndarray] | None:
    """For each straddling edge ``rows`` of a lone piece, the nearest shared line (index into
    ``strong``) that crosses it within ``reach`` px of the line's samples, and the side (+-1) the
    edge's lower-class end lies on; None when some edge is crossed by none."""
    ln = np.array([glines[g] for g in strong])
    a, b = x[e[rows, 0]], x[e[rows, 1]]
    va, vb = a @ ln[:, :2].T - ln[:, 2], b @ ln[:, :2].T - ln[:, 2]
    mid = (a + b) / 2
    t = mid @ np.column_stack([-ln[:, 1], ln[:, 0]]).T
    span = np.array([_span(x, sets[g], glines[g]) for g in strong])
    ok = (va * vb < 0) & (t >= span[:, 0] - reach) & (t <= span[:, 1] + reach)
    if not ok.any(axis=1).all():
        return None
    dist = np.where(ok, np.abs(mid @ ln[:, :2].T - ln[:, 2]), np.inf)
    choice = np.argmin(dist, axis=1)
    return choice, np.sign(va[np.arange(len(rows)), choice])


def _absorb_plan(x: np.ndarray, e: np.ndarray, rows: np.ndarray, choice: np.ndarray,
                 orient: np.ndarray, strong: np.ndarray, sets: dict, tol: float) -> dict | None:
    """``{line: (edges, side, positive samples, negative samples, refitted line)}`` moving a lone
    piece's edges onto the shared lines that cross them; None when a line would be crossed both
    ways or would no longer separate its samples."""
    plan = {}
    for k in np.unique(choice):
        o = np.unique(orient[choice == k])
        g = int(strong[k])
        sel = rows[choice == k]
        new_pos = e[sel, 0] if o[0] > 0 else e[sel, 1]
        new_neg = e[sel, 1] if o[0] > 0 else e[sel, 0]
        pa, na = np.union1d(sets[g][0], new_pos), np.union1d(sets[g][1], new_neg)
        if len(o) != 1 or np.intersect1d(pa, na).size:
            return None
        line, separable = separating_line(x[pa], x[na], tol)
        if not separable:
            return None
        plan[g] = (sel, float(o[0]), pa, na, line)
    return plan


def _span(
    x: np.ndarray, sides: tuple[np.ndarray, np.ndarray], line: np.ndarray
) -> tuple[float, float]:
    """(min, max) position along ``line`` of the samples on either side of it."""
    t = x[np.r_[sides[0], sides[1]]] @ (-line[1], line[0])
    return float(t.min()), float(t.max())


def _renumber(edge_piece, pairs, group, sign, glines):
    """Join pieces of one pair on one line, drop unused lines, number lines by first piece."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    group = np.asarray(group, dtype=np.int64)
    sign = np.asarray(sign, float)
    key = np.column_stack([pairs, group, sign.astype(np.int64)])
    _, first_of, piece_of = np.unique(key, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first_of)  # keep the pieces in their first-seen order
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    edge_piece = rank[piece_of.reshape(-1)][np.asarray(edge_piece, np.int64)]
    keep = first_of[order]
    pairs, group, sign = pairs[keep], group[keep], sign[keep]
    used, first = np.unique(group, return_index=True)
    order = used[np.argsort(first)]
    rank = np.full(len(glines), -1, dtype=np.int64)
    rank[order] = np.arange(len(order))
    lines = np.array([glines[g] for g in order], float).reshape(-1, 3)
    return edge_piece, pairs, rank[group], sign, lines


def fit_pieces(
    x: np.ndarray, labels: np.ndarray, n_classes: int, *, merge_angle: float,
    merge_offset: float, tol: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The straight boundary pieces of every pair of neighbouring sounds, on shared lines.

    Parameters
    ----------
    x : (n, 2) ndarray
        The samples (where the finger landed).
    labels : (n,) int ndarray
        Sound class of each sample.
    n_classes : int
        Number of classes, silence included.
    merge_angle, merge_offset : float
        Pieces whose lines are within this angle (degrees) and offset (px) may share a line.
    tol : float
        Label-noise tolerance (px) of the separating lines (:func:`separating_line`).

    Returns
    -------
    edges, edge_piece, pairs, group, sign, lines
        Straddling edges (the lower class's end first, sorted by pair), the piece of each edge,
        the two classes of each piece, its line, its side (+1: lower class on the line's positive
        side) and the lines (L, 3) ``(nx, ny, c)``.
    """
    e = straddling_edges(x, labels)
    e = e[np.lexsort((e[:, 1], e[:, 0], labels[e[:, 1]], labels[e[:, 0]]))]
    piece = np.zeros(len(e), dtype=np.int64)
    pairs, lines, rows_of = [], [], []
    code = labels[e[:, 0]] * n_classes + labels[e[:, 1]]
    for c in np.unique(code):  # one loop per pair of neighbouring sounds
        rows = np.flatnonzero(code == c)
        for part, line in split_pieces(x, e[rows], tol=tol):
            piece[rows[part]] = len(lines)
            pairs.append(divmod(int(c), n_classes))
            lines.append(line)
            rows_of.append(rows[part])
    lines_arr = np.array(lines, float).reshape(-1, 3)
    pairs_arr = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    if not (merge_angle > 0 and len(lines)):
        return e, piece, pairs_arr, np.arange(len(lines)), np.ones(len(lines)), lines_arr
    group, sign, glines = merge_pieces(x, e, rows_of, lines_arr, np.radians(merge_angle),
                                       merge_offset, tol)
    piece, pairs_arr, group, sign, glines = absorb_pieces(
        x, e, piece, pairs_arr, group, sign, glines, reach=2 * merge_offset, tol=tol)
    return e, piece, pairs_arr, group, sign, glines
