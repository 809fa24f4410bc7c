"""Straight boundary pieces between neighbouring sounds (the ``lines`` model's fit).

The straddling edges of each pair of sounds (:func:`kbcli.core.model.sounds.straddling_edges`) get the
max-margin line separating their two ends (the hard-margin linear SVM, solved exactly in 2-D as the
perpendicular bisector of the closest points of the two convex hulls, :func:`separating_line`);
when no line separates them (silence around a corner key bends) they are split by the direction
in which they cross, recursively (:func:`split_pieces`). Pieces whose lines nearly coincide are
merged when one line still separates all their samples (:func:`merge_pieces`), and a lone piece
whose edges are all crossed by shared lines is re-expressed with them (:func:`absorb_pieces`).
:func:`fit_pieces` runs the three steps.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.model.sounds import straddling_edges


def convex_hull(p: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of 2-D points, counter-clockwise (Andrew's monotone chain)."""
    pts = np.unique(np.asarray(p, float), axis=0)  # sorted by x, then y
    if len(pts) <= 2:
        return pts

    def half(seq: np.ndarray) -> list[np.ndarray]:
        h: list[np.ndarray] = []
        for q in seq:  # a few points per boundary piece
            while len(h) >= 2 and (
                (h[-1][0] - h[-2][0]) * (q[1] - h[-2][1])
                - (h[-1][1] - h[-2][1]) * (q[0] - h[-2][0]) <= 0
            ):
                h.pop()
            h.append(q)
        return h

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _closest_to_segments(p: np.ndarray, hull: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point, the nearest point of a convex polygon's boundary (vertices or edges).

    Returns
    -------
    dist : (n,) ndarray
    foot : (n, 2) ndarray
    """
    a = hull
    b = np.roll(hull, -1, axis=0) if len(hull) > 1 else hull
    ab = b - a  # (e, 2)
    ll = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    t = np.clip(np.einsum("ned,ed->ne", p[:, None, :] - a[None], ab) / ll, 0.0, 1.0)
    foot = a[None] + t[..., None] * ab[None]  # (n, e, 2)
    d = np.hypot(*(p[:, None, :] - foot).transpose(2, 0, 1))
    k = np.argmin(d, axis=1)
    r = np.arange(len(p))
    return d[r, k], foot[r, k]


def separating_line(a: np.ndarray, b: np.ndarray, tol: float = 0.0) -> tuple[np.ndarray, bool]:
    """Max-margin line between points ``a`` (its positive side) and ``b``.

    For separable sets it is the perpendicular bisector of the closest pair of points of their
    convex hulls (the hard-margin linear SVM, solved exactly in 2-D). With a label-noise tolerance
    ``tol`` > 0 (px), sets that no line separates get a soft-margin line (logistic regression),
    which counts as separating when every point on its wrong side is within ``tol`` of it: labels
    flipped near a boundary by an arm that does not feel exactly where it touched then give one
    straight boundary, not a splinter of pieces.

    Returns
    -------
    line : (3,) ndarray
        (nx, ny, c), unit normal towards ``a``: signed distance ``n . x - c``.
    separable : bool
        Whether the line puts every point of ``a`` and ``b`` strictly on its own side.
    """
    ha, hb = convex_hull(a), convex_hull(b)
    da, fa = _closest_to_segments(ha, hb)  # a's vertices to b's hull
    db, fb = _closest_to_segments(hb, ha)
    if da.min() <= db.min():
        i = int(np.argmin(da))
        p, q = ha[i], fa[i]
    else:
        i = int(np.argmin(db))
        p, q = fb[i], hb[i]
    w = p - q
    nw = float(np.hypot(*w))
    if nw < 1e-12:  # touching or overlapping: fall back to the direction between the means
        w = a.mean(axis=0) - b.mean(axis=0)
        nw = max(float(np.hypot(*w)), 1e-12)
        p, q = a.mean(axis=0), b.mean(axis=0)
    n = w / nw
    c = float(n @ (p + q) / 2)
    separable = bool((a @ n - c > 0).all() and (b @ n - c < 0).all())
    if separable or tol <= 0:
        return np.array([n[0], n[1], c]), separable
    n, c = _soft_line(a, b)
    separable = bool((a @ n - c > -tol).all() and (b @ n - c < tol).all())
    return np.array([n[0], n[1], c]), separable


def _soft_line(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit normal (towards ``a``) and offset of a logistic-regression line between two point
    sets that overlap (deterministic: lbfgs, centred and scaled coordinates)."""
    from sklearn.linear_model import LogisticRegression

    pts = np.vstack([a, b])
    mu = pts.mean(axis=0)
    scale = max(float(pts.std()), 1e-9)
    y = np.r_[np.ones(len(a)), np.zeros(len(b))]
    clf = LogisticRegression(C=10.0).fit((pts - mu) / scale, y)
    w = clf.coef_[0] / scale
    nw = max(float(np.hypot(*w)), 1e-12)
    n = w / nw
    c = float(n @ mu - clf.intercept_[0] / nw)
    return n, c


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

    Two pieces are candidates when their lines are within ``max_angle`` rad and ``max_offset`` px
    of each other; candidates are merged, closest first, when a single line still separates the
    samples on either side of all their pieces (the data decide; a merge the samples contradict
    is never made, and refitting with more samples undoes any that later turn out wrong).

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
    centre = np.array([x[np.r_[a, b]].mean(axis=0) for a, b in zip(side_a, side_b, strict=True)])
    centre = centre.reshape(-1, 2)
    n, c = lines[:, :2], lines[:, 2]
    cos = n @ n.T
    off = np.abs(centre @ n.T - c[None, :])  # off[q, p]: piece q's centre from piece p's line
    p_i, q_i = np.triu_indices(npc, 1)
    ok = (np.abs(cos[p_i, q_i]) >= np.cos(max_angle)) & (off[q_i, p_i] < max_offset) & (
        off[p_i, q_i] < max_offset
    )
    p_i, q_i = p_i[ok], q_i[ok]
    order = np.argsort(off[q_i, p_i] + off[p_i, q_i], kind="stable")
    root = np.arange(npc)
    sign = np.ones(npc)
    members = {p: [p] for p in range(npc)}
    pts = {p: (side_a[p], side_b[p]) for p in range(npc)}
    glines = {p: lines[p].copy() for p in range(npc)}
    for k in order:  # a loop over candidate merges (a few per piece)
        p, q = int(p_i[k]), int(q_i[k])
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
    roots, group = np.unique(root, return_inverse=True)
    # number groups by their first piece, so the layout does not depend on merge order
    first = np.array([np.flatnonzero(group == g)[0] for g in range(len(roots))], dtype=np.int64)
    rank = np.empty(len(roots), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(roots))
    group_lines = np.array([glines[int(r)] for r in roots])[np.argsort(first)]
    return rank[group], sign, group_lines.reshape(-1, 3)


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
    """Re-express lone boundary pieces with lines that several pieces share.

    A piece alone on its line (typically a pair of sounds whose boundary bends, such as silence
    around a corner key, fitted with too few samples to see the bend) is replaced by pieces on
    shared lines when every one of its straddling edges is crossed by a shared line (within
    ``reach`` px of that line's samples), each shared line crossed in one direction only, and each
    line still separates its samples once the new ones are added (its line is then refitted).

    Returns
    -------
    edge_piece, pairs, group, sign, glines
        The same structure, renumbered (lines by first piece).
    """
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
        ln = np.array([glines[g] for g in strong])
        a, b = x[e[rows, 0]], x[e[rows, 1]]
        va, vb = a @ ln[:, :2].T - ln[:, 2], b @ ln[:, :2].T - ln[:, 2]
        mid = (a + b) / 2
        t = mid @ np.column_stack([-ln[:, 1], ln[:, 0]]).T
        span = np.array([_span(x, sets[g], glines[g]) for g in strong])
        ok = (va * vb < 0) & (t >= span[:, 0] - reach) & (t <= span[:, 1] + reach)
        if not ok.any(axis=1).all():
            continue
        dist = np.where(ok, np.abs(mid @ ln[:, :2].T - ln[:, 2]), np.inf)
        choice = np.argmin(dist, axis=1)
        orient = np.sign(va[np.arange(len(rows)), choice])
        plan = {}
        good = True
        for k in np.unique(choice):
            o = np.unique(orient[choice == k])
            g = int(strong[k])
            sel = rows[choice == k]
            new_pos = e[sel, 0] if o[0] > 0 else e[sel, 1]
            new_neg = e[sel, 1] if o[0] > 0 else e[sel, 0]
            pa, na = np.union1d(sets[g][0], new_pos), np.union1d(sets[g][1], new_neg)
            if len(o) != 1 or np.intersect1d(pa, na).size:
                good = False
                break
            line, separable = separating_line(x[pa], x[na], tol)
            if not separable:
                good = False
                break
            plan[g] = (sel, float(o[0]), pa, na, line)
        if not good:
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
        Sound class of each sample (:func:`kbcli.core.model.sounds.discover_classes`).
    n_classes : int
        Number of classes, silence included.
    merge_angle : float
        Pieces whose lines are within this angle (degrees) may share a line (0: never).
    merge_offset : float
        ... and within this offset (px).
    tol : float
        Label-noise tolerance (px) of the separating lines (:func:`separating_line`).

    Returns
    -------
    edges : (m, 2) int ndarray
        Straddling edges (the lower class's end first), sorted by pair.
    edge_piece : (m,) int ndarray
        Piece of each edge.
    pairs : (P, 2) int ndarray
        The two classes (lower first) each piece separates.
    group : (P,) int ndarray
        The line each piece lies on.
    sign : (P,) ndarray
        +1 where a piece's lower class is on its line's positive side, else -1.
    lines : (L, 3) ndarray
        (nx, ny, c) of each line.
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
