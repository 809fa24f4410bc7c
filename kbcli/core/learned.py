"""The learned model of the instrument, M_INST = p(sound, action), from exploration samples.

The robot touches the pad at actions a_i (the fingertip positions it feels, proprioception) and
hears sounds s_i (feature vectors, NaN for silence). From these alone (it never sees the
simulator's key ids) the model

1. **finds the sound classes** by leader clustering of the perceived features with the matching
   threshold of Eq. 2: a sound further than the threshold (Manhattan) from every class found so far
   opens a new class; classes whose mean sounds end up within the threshold are merged. Class 0 is
   silence; the others are sorted by their features, so ids do not depend on the sample order.
2. **models p(sound | action) with straight boundaries** (the keys are polygons):

   - *straddling edges*: a Delaunay edge of the samples whose ends were heard as two different
     sounds i < j crosses their boundary (edges with a third sound's sample in the circle on the
     edge as diameter are dropped: they may cross that sound's region instead);
   - *pieces*: the straddling edges of each pair (i, j) get the max-margin line separating their
     two ends (the hard-margin linear SVM, solved exactly in 2-D as the perpendicular bisector of
     the closest points of the two convex hulls); when no line separates them (silence around a
     corner key bends) they are split by the direction in which they cross, recursively;
   - *shared lines*: pieces whose lines nearly coincide (within ``merge_angle`` degrees and
     ``merge_offset`` px) are merged, closest first, when one line still separates all their
     samples (the edge between keys of one column continues across rows); a lone piece whose
     edges are all crossed by shared lines is re-expressed with them (a corner key's L). One line
     fitted to every sample along an edge is far better determined than per-pair lines;
   - *probability*: at an action a (a finger position), the candidate sounds are the classes of
     its ``n_neighbors`` nearest samples (one class: p is one-hot). For two candidates with a
     boundary, s is the signed distance (px) of a to its piece's line and
     ``p(a on i's side) = Phi(s / sigma)``, sigma the line's uncertainty at a: the width of the
     band between the hulls of the samples on either side (where any separating line must pass),
     over sqrt(12), growing beyond the samples, times ``sd_scale`` and clipped to [``min_sd``,
     ``max_sd``], combined with the label noise ``noise_sd`` (``hypot``). A pair with
     several pieces: of the pieces near a (within ``piece_reach`` px of the nearest), the sound
     inside (a corner key; whichever explains the pair's samples better) must be on its side of
     all, the other of any. Each candidate's log-score sums log 2p over its pairwise contests (log
     space, ``log_ndtr``; the factor 2 makes an undecided contest neutral); p(sound | a) is their
     softmax, floored at ``floor``. Its spread across a boundary is the paper's
     *confusion factor* (Sect. III-E). The landing scatter of a reach is estimated
     (``reach_sd_``) but not folded in: a caller that knows only where it aimed blurs by it.
3. **samples actions for a sound**, p(action | sound) ~ p(sound | action) p(action) with p(action)
   uniform over the working area (Bayes' rule; Algorithm 2, line 3), by rejection sampling.

The estimator follows the scikit-learn contract (``fit`` returns ``self``, fitted attributes end in
``_``, predicting before fitting raises) and round-trips exactly through :meth:`to_arrays` /
:meth:`from_arrays` (the fitted lines are stored, not refitted).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree
from scipy.special import log_ndtr
from sklearn.exceptions import NotFittedError

from kbcli.core.model import SILENCE, ProbabilityRaster, classify_features, grid_points
from kbcli.errors import ArtifactError, ConfigError

_CHUNK = 16384  # query points per block
#: Added to both sides of every pairwise contest: log(2 Phi(z)) instead of log Phi(z), so that a
#: contest the model knows nothing about (z = 0) is neutral instead of penalising the candidates
#: that take part in more contests (which made wide, honest boundary bands cost accuracy).
_NEUTRAL = float(np.log(2.0))


def discover_classes(perceived: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Sound classes from perceived features by leader clustering (Eq. 2 threshold).

    Parameters
    ----------
    perceived : (n, D) ndarray
        Perceived features; an all-NaN row is silence.
    threshold : float
        Manhattan distance within which a sound joins a class's leader.

    Returns
    -------
    class_features : (C, D) ndarray
        Row 0 is silence (NaN); rows 1.. the mean features of each class, sorted.
    labels : (n,) int ndarray
        Class of each sample.
    """
    s = np.atleast_2d(np.asarray(perceived, float))
    n, dim = s.shape
    silent = np.isnan(s).any(axis=1)
    lead = np.full(n, -1, dtype=np.int64)
    means: list[np.ndarray] = []
    todo = ~silent
    while todo.any():  # one pass per class, vectorized over the samples
        first = int(np.flatnonzero(todo)[0])
        near = todo & (np.abs(s - s[first]).sum(axis=1) < threshold)
        lead[near] = len(means)
        means.append(s[near].mean(axis=0))
        todo &= ~near
    if not means:
        return np.full((1, dim), np.nan), np.zeros(n, dtype=np.int64)
    centres, counts = np.array(means), np.bincount(lead[~silent])
    while len(centres) > 1:  # merge classes whose mean sounds are within the threshold
        d = np.abs(centres[:, None, :] - centres[None, :, :]).sum(axis=-1)
        d[np.diag_indices(len(d))] = np.inf
        i, j = np.unravel_index(np.argmin(d), d.shape)
        if d[i, j] >= threshold:
            break
        i, j = min(i, j), max(i, j)
        centres[i] = (counts[i] * centres[i] + counts[j] * centres[j]) / (counts[i] + counts[j])
        counts[i] += counts[j]
        centres, counts = np.delete(centres, j, axis=0), np.delete(counts, j)
        lead[lead == j] = i
        lead[lead > j] -= 1
    order = np.lexsort(centres.T[::-1])
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    features = np.vstack([np.full((1, dim), np.nan), centres[order]])
    labels = np.zeros(n, dtype=np.int64)
    labels[~silent] = rank[lead[~silent]] + 1
    # settle each sample on its nearest class centre (a leader may sit at its class's edge)
    again = classify_features(s[~silent], features, threshold)
    labels[~silent] = np.where(again > 0, again, labels[~silent])
    return features, labels


def prepare_samples(
    actions: np.ndarray, perceived: np.ndarray, targets: np.ndarray | None, threshold: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Check exploration samples and find their sound classes (the start of every model's fit).

    Parameters
    ----------
    actions : (n, 2) array_like
        Where the finger landed (proprioception); finite, at least one.
    perceived : (n, D) array_like
        What was heard there (NaN rows: silence).
    targets : (n, 2) array_like or None
        Where the reaches aimed.
    threshold : float
        Eq. 2's matching threshold (:func:`discover_classes`).

    Returns
    -------
    x : (n, 2) ndarray
    features : (C, D) ndarray
    labels : (n,) ndarray
        As :func:`discover_classes`.
    reach_sd : float
        Per-axis rms of landed minus aimed (~0 for an ideal arm; 0 without ``targets``).

    Raises
    ------
    ConfigError
        No sample, or a non-finite action.
    """
    x = np.asarray(actions, float).reshape(-1, 2)
    if len(x) < 1:
        raise ConfigError("fit needs at least one sample")
    if not np.isfinite(x).all():
        raise ConfigError("actions must be finite")
    s = np.asarray(perceived, float).reshape(len(x), -1)
    features, labels = discover_classes(s, threshold)
    reach_sd = 0.0
    if targets is not None:
        d = x - np.asarray(targets, float).reshape(-1, 2)
        reach_sd = float(np.sqrt(np.mean(d * d)))
    return x, features, labels, reach_sd


def _straddling_edges(points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(m, 2) Delaunay edges joining samples of two different sounds, lower class's end first.

    An edge is dropped when a sample of a third sound lies inside the circle on the edge as
    diameter (the segment may then pass through that sound's region, so its two ends need not
    be neighbours across one boundary).
    """
    n = len(points)
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    try:
        tri = Delaunay(points)
        s = tri.simplices
        e = np.vstack([s[:, [0, 1]], s[:, [1, 2]], s[:, [0, 2]]])
    except (QhullError, ValueError):  # fewer than 3 points, or all on a line
        i, j = np.triu_indices(n, 1)
        e = np.column_stack([i, j])
    e = np.unique(np.sort(e, axis=1), axis=0)
    e = e[labels[e[:, 0]] != labels[e[:, 1]]]
    if len(e) == 0:
        return np.empty((0, 2), dtype=np.int64)
    mid = (points[e[:, 0]] + points[e[:, 1]]) / 2
    r = np.hypot(*(points[e[:, 0]] - points[e[:, 1]]).T) / 2
    k = min(12, n)
    d, idx = cKDTree(points).query(mid, k=k)
    d, idx = d.reshape(len(e), k), idx.reshape(len(e), k)
    third = (labels[idx] != labels[e[:, :1]]) & (labels[idx] != labels[e[:, 1:]])
    e = e[~(third & (d < r[:, None] * (1 - 1e-9))).any(axis=1)]
    flip = labels[e[:, 0]] > labels[e[:, 1]]
    e[flip] = e[flip][:, ::-1]
    return e


def _convex_hull(p: np.ndarray) -> np.ndarray:
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


def _separating_line(a: np.ndarray, b: np.ndarray, tol: float = 0.0) -> tuple[np.ndarray, bool]:
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
    ha, hb = _convex_hull(a), _convex_hull(b)
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


def _pieces(x: np.ndarray, e: np.ndarray, depth: int = 0,
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
    line, ok = _separating_line(x[ua], x[ub], tol)
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
        out += [(part[sub], ln) for sub, ln in _pieces(x, e[part], depth + 1, tol)]
    return out


def _merge_pieces(
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
        line, separable = _separating_line(x[a], x[b], tol)
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


def _line_sides(
    e: np.ndarray, edge_piece: np.ndarray, sign: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per straddling edge, the sample on its line's positive side and the one on its negative."""
    flip = sign[edge_piece] < 0
    return np.where(flip, e[:, 1], e[:, 0]), np.where(flip, e[:, 0], e[:, 1])


def _absorb_pieces(
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
    pos, neg = _line_sides(e, edge_piece, np.asarray(sign))
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
            line, separable = _separating_line(x[pa], x[na], tol)
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


def _log_any(log_miss: np.ndarray) -> np.ndarray:
    """log(1 - prod_k exp(log_miss_k)) along axis 1: the log-probability of at least one hit."""
    return np.log(-np.expm1(np.minimum(log_miss.sum(axis=1), -1e-300)))


def _lower_hull(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


class LearnedModel:
    """p(sound | action) learned from exploration samples (see the module docstring).

    Parameters
    ----------
    match_threshold : float
        Manhattan distance under which two perceived sounds are the same sound (Eq. 2).
    area : tuple of float
        (xmin, ymin, xmax, ymax) working area: the support of p(action) and of :meth:`raster`.
    n_neighbors : int
        Samples looked at around an action to find the sounds it could make.
    min_sd, max_sd : float
        Bounds (px) of a boundary line's uncertainty sigma_b in p(sound | action). A line known
        only from samples 30 px apart is uncertain by about 9 px: the bound must not make it sure
        (a 4 px bound made weak models confidently wrong, expected calibration error 0.10-0.19).
    sd_scale : float
        Factor on every boundary's band-width uncertainty (calibration, see
        :mod:`kbcli.core.reliability`; 1: the band as it is).
    noise_sd : float
        Std (px) of the label noise near a boundary (an arm that does not feel exactly where it
        touched, a finger of finite size): combined with sigma_b as ``hypot(sigma_b, noise_sd)``.
    noise_tol : float
        Label-noise tolerance (px) of the boundary fit: two sounds' samples that no line separates
        get one soft-margin line when every sample on its wrong side is within ``noise_tol`` of it
        (0: exact separation, as for an arm that feels exactly where it touched).
    floor : float
        Share of probability spread evenly over all sounds (``p = (1 - floor) p + floor / C``):
        the rate at which a touch sounds other than the map says, far from any boundary.
    extrapolation : float
        Growth (px per px) of a boundary band's width beyond the samples along its line.
    merge_angle, merge_offset : float
        Pieces whose lines are within this angle (degrees) and offset (px) may share a line
        (0 degrees: never).
    piece_reach : float
        Where a pair of sounds has several boundary pieces, those within this many px of the
        nearest one (both legs of a corner) decide together; further ones have no say.

    Attributes
    ----------
    class_features_ : (C, D) ndarray
        Features of each class; row 0 (silence) is NaN.
    actions_ : (n, 2) ndarray
        Where the finger landed for each sample.
    labels_ : (n,) int ndarray
        Sound class of each sample.
    edges_ : (m, 2) int ndarray
        Straddling edges: sample indices, the lower class's end first.
    edge_piece_ : (m,) int ndarray
        Boundary piece of each straddling edge.
    piece_pair_ : (P, 2) int ndarray
        The two classes (lower first) each piece separates.
    piece_line_ : (P,) int ndarray
        The line each piece lies on.
    piece_sign_ : (P,) ndarray
        +1 where a piece's lower class is on its line's positive side, else -1.
    lines_ : (L, 3) ndarray
        Boundary lines (nx, ny, c), unit normal: signed distance ``nx * x + ny * y - c``.
    reach_sd_ : float
        Landing scatter of a reach (px, per-axis rms of landing minus target), for information:
        p(sound | action) is about where the finger *is*; a caller that only knows where it aimed
        blurs it by this much.
    """

    def __init__(
        self,
        *,
        match_threshold: float = 1.5,
        area: tuple[float, float, float, float] = (150.0, 200.0, 650.0, 500.0),
        n_neighbors: int = 8,
        min_sd: float = 0.05,
        max_sd: float = 25.0,
        sd_scale: float = 1.0,
        noise_sd: float = 0.0,
        floor: float = 0.0,
        noise_tol: float = 0.0,
        extrapolation: float = 1.0,
        merge_angle: float = 10.0,
        merge_offset: float = 10.0,
        piece_reach: float = 10.0,
    ) -> None:
        self.match_threshold = match_threshold
        self.area = area
        self.n_neighbors = n_neighbors
        self.min_sd = min_sd
        self.max_sd = max_sd
        self.sd_scale = sd_scale
        self.noise_sd = noise_sd
        self.floor = floor
        self.noise_tol = noise_tol
        self.extrapolation = extrapolation
        self.merge_angle = merge_angle
        self.merge_offset = merge_offset
        self.piece_reach = piece_reach

    # -- parameters -----------------------------------------------------------------------------
    def _check_params(self) -> None:
        if not (np.isfinite(self.match_threshold) and self.match_threshold > 0):
            raise ConfigError(f"match_threshold must be > 0, got {self.match_threshold!r}")
        x0, y0, x1, y1 = (float(v) for v in self.area)
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(
                f"area must be (xmin, ymin, xmax, ymax) with max > min, got {self.area!r}"
            )
        if int(self.n_neighbors) < 2:
            raise ConfigError(f"n_neighbors must be >= 2, got {self.n_neighbors!r}")
        if not (np.isfinite(self.min_sd) and self.min_sd > 0):
            raise ConfigError(f"min_sd must be > 0 px, got {self.min_sd!r}")
        if not (np.isfinite(self.max_sd) and self.max_sd >= self.min_sd):
            raise ConfigError(f"max_sd must be >= min_sd, got {self.max_sd!r}")
        if not (np.isfinite(self.sd_scale) and self.sd_scale > 0):
            raise ConfigError(f"sd_scale must be > 0, got {self.sd_scale!r}")
        if not (np.isfinite(self.noise_sd) and self.noise_sd >= 0):
            raise ConfigError(f"noise_sd must be >= 0 px, got {self.noise_sd!r}")
        if not (np.isfinite(self.noise_tol) and self.noise_tol >= 0):
            raise ConfigError(f"noise_tol must be >= 0 px, got {self.noise_tol!r}")
        if not (np.isfinite(self.floor) and 0 <= self.floor < 1):
            raise ConfigError(f"floor must be in [0, 1), got {self.floor!r}")
        if not (np.isfinite(self.extrapolation) and self.extrapolation >= 0):
            raise ConfigError(f"extrapolation must be >= 0, got {self.extrapolation!r}")
        if not (np.isfinite(self.merge_angle) and 0 <= self.merge_angle < 90):
            raise ConfigError(f"merge_angle must be in [0, 90) degrees, got {self.merge_angle!r}")
        if not (np.isfinite(self.merge_offset) and self.merge_offset >= 0):
            raise ConfigError(f"merge_offset must be >= 0 px, got {self.merge_offset!r}")
        if not (np.isfinite(self.piece_reach) and self.piece_reach >= 0):
            raise ConfigError(f"piece_reach must be >= 0 px, got {self.piece_reach!r}")

    def _check_fitted(self) -> None:
        if not hasattr(self, "class_features_"):
            raise NotFittedError(
                "this LearnedModel is not fitted yet: call fit(actions, perceived)"
            )

    @property
    def n_classes(self) -> int:
        self._check_fitted()
        return len(self.class_features_)

    @staticmethod
    def fit_grid() -> dict[str, tuple[float, ...]]:
        """Candidate values of the fit's own calibration parameter, the label-noise tolerance
        (px; :func:`kbcli.core.reliability.assess` refits with each and keeps the best held-out
        score: 0 for an arm that feels exactly where it touched, more for a noisy one)."""
        return {"noise_tol": (0.0, 2.0, 4.0)}

    @staticmethod
    def calibration_grid() -> dict[str, tuple[float, ...]]:
        """Candidate values of the calibration parameters (read at prediction time, so a fitted
        model is recalibrated by setting them; :func:`kbcli.core.reliability.assess` picks them by
        held-out Brier score, weighted for the distance to the samples)."""
        return {"noise_sd": (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.5, 6.0), "floor": (0.0, 0.002, 0.01)}

    # -- fitting --------------------------------------------------------------------------------
    def fit(
        self, actions: np.ndarray, perceived: np.ndarray, targets: np.ndarray | None = None
    ) -> LearnedModel:
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
        e = _straddling_edges(x, labels)
        e = e[np.lexsort((e[:, 1], e[:, 0], labels[e[:, 1]], labels[e[:, 0]]))]
        piece = np.zeros(len(e), dtype=np.int64)
        pairs, lines, rows_of = [], [], []
        code = labels[e[:, 0]] * len(features) + labels[e[:, 1]]
        for c in np.unique(code):  # one loop per pair of neighbouring sounds
            rows = np.flatnonzero(code == c)
            for part, line in _pieces(x, e[rows], tol=self.noise_tol):
                piece[rows[part]] = len(lines)
                pairs.append(divmod(int(c), len(features)))
                lines.append(line)
                rows_of.append(rows[part])
        lines_arr = np.array(lines, float).reshape(-1, 3)
        if self.merge_angle > 0 and len(lines):
            group, sign, glines = _merge_pieces(
                x, e, rows_of, lines_arr, np.radians(self.merge_angle), self.merge_offset,
                self.noise_tol)
        else:
            group, sign, glines = np.arange(len(lines)), np.ones(len(lines)), lines_arr
        pairs_arr = np.array(pairs, dtype=np.int64).reshape(-1, 2)
        if self.merge_angle > 0 and len(lines):
            piece, pairs_arr, group, sign, glines = _absorb_pieces(
                x, e, piece, pairs_arr, group, sign, glines, reach=2 * self.merge_offset,
                tol=self.noise_tol)
        self._set_fitted(features, x, labels, e, piece, pairs_arr, group, sign, glines, reach_sd)
        return self

    def _set_fitted(
        self, features, actions, labels, edges, edge_piece, pairs, group, sign, lines, reach_sd
    ) -> None:
        self.class_features_ = np.asarray(features, float)
        self.actions_ = np.asarray(actions, float)
        self.labels_ = np.asarray(labels, np.int64)
        self.edges_ = np.asarray(edges, np.int64).reshape(-1, 2)
        self.edge_piece_ = np.asarray(edge_piece, np.int64)
        self.piece_pair_ = np.asarray(pairs, np.int64).reshape(-1, 2)
        self.piece_line_ = np.asarray(group, np.int64)
        self.piece_sign_ = np.asarray(sign, float)
        self.lines_ = np.asarray(lines, float).reshape(-1, 3)
        self.reach_sd_ = float(reach_sd)
        self._tree = cKDTree(self.actions_)
        n_pieces, n_lines = len(self.piece_pair_), len(self.lines_)
        # samples on the positive / negative side of each line: the pieces' lower-class ends,
        # or higher-class ends where the piece runs the other way
        lo_end = self.edges_[:, 0]
        hi_end = self.edges_[:, 1]
        flip = self.piece_sign_[self.edge_piece_] < 0
        pos = np.where(flip, hi_end, lo_end)
        neg = np.where(flip, lo_end, hi_end)
        eline = self.piece_line_[self.edge_piece_]
        self._hulls = []
        self._line_range = np.zeros((n_lines, 2))
        for g in range(n_lines):  # one loop per boundary line; the hulls bound where it can be
            nx, ny, c = self.lines_[g]
            a = self.actions_[np.unique(pos[eline == g])]
            b = self.actions_[np.unique(neg[eline == g])]
            ha = _lower_hull(a @ (-ny, nx), a @ (nx, ny) - c)  # the line passes under these
            hb = _lower_hull(b @ (-ny, nx), c - b @ (nx, ny))  # and over these
            self._hulls.append((ha[0], ha[1], hb[0], -hb[1]))
            self._line_range[g] = (max(ha[0][0], hb[0][0]), min(ha[0][-1], hb[0][-1]))
        self._piece_extent = np.zeros((n_pieces, 2))
        for p in range(n_pieces):
            nx, ny, _ = self.lines_[self.piece_line_[p]]
            ends = self.actions_[self.edges_[self.edge_piece_ == p].ravel()]
            t = ends @ (-ny, nx)
            self._piece_extent[p] = (t.min(), t.max()) if len(t) else (0.0, 0.0)
        nc = len(self.class_features_)
        pcode = self.piece_pair_[:, 0] * nc + self.piece_pair_[:, 1]
        self._pair_pieces = {int(c): np.flatnonzero(pcode == c) for c in np.unique(pcode)}
        # with several pieces, one sound of the pair is "inside" (a key within silence's L around
        # a corner): it must be on its side of every piece, the other of any one; the one that
        # explains more of the pair's straddling samples (ties: the lower class)
        self._pair_inside = {}
        for c, pieces in self._pair_pieces.items():
            ed = self.edges_[np.isin(self.edge_piece_, pieces)]
            ln = self.lines_[self.piece_line_[pieces]]
            sg = self.piece_sign_[pieces]
            va = (self.actions_[np.unique(ed[:, 0])] @ ln[:, :2].T - ln[:, 2]) * sg
            vb = (self.actions_[np.unique(ed[:, 1])] @ ln[:, :2].T - ln[:, 2]) * sg
            wrong_if_lo = np.sum(~(va > 0).all(axis=1)) + np.sum((vb > 0).all(axis=1))
            wrong_if_hi = np.sum(~(vb < 0).all(axis=1)) + np.sum((va < 0).all(axis=1))
            self._pair_inside[c] = bool(wrong_if_lo <= wrong_if_hi)

    # -- the boundary lines ---------------------------------------------------------------------
    def _band(self, g: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Width (px) and centre (v) of the band where line ``g`` can be, at positions ``t``.

        Inside the span of samples on both sides, a separating line must pass under the lower
        hull of the positive side's samples and over the upper hull of the negative side's; beyond
        that span the band widens by ``2 * extrapolation`` px per px.
        """
        ta, va, tb, vb = self._hulls[g]
        lo, hi = self._line_range[g]
        tc = np.clip(t, min(lo, hi), max(lo, hi))
        top, bottom = np.interp(tc, ta, va), np.interp(tc, tb, vb)
        out = np.abs(t - tc) + max(lo - hi, 0.0)
        width = np.abs(top - bottom) + 2 * self.extrapolation * out
        centre = np.where(out > 0, 0.0, (top + bottom) / 2)
        return width, centre

    def _pair_logp(self, code: int, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Log-probability that each point is on the lower / higher class's side of their boundary.

        With one boundary piece, ``log Phi(z)`` and ``log Phi(-z)``, z = s / sigma (s the signed
        distance to the line, sigma the boundary's uncertainty there).
        With several pieces, only those near the point count: the nearest (distance to the
        piece's extent along its line) and any within ``piece_reach`` px more (both legs of a
        corner). The sound inside (see :meth:`_set_fitted`) must be on its side of all of them
        (product), the other of any: the two log-probabilities are complementary.
        """
        pieces = self._pair_pieces[code]
        g = self.piece_line_[pieces]
        lines = self.lines_[g]
        v = (q @ lines[:, :2].T - lines[:, 2]) * self.piece_sign_[pieces]  # (n, k)
        t = q @ np.column_stack([-lines[:, 1], lines[:, 0]]).T
        sd = np.empty_like(v)
        for j in range(len(pieces)):  # a few pieces per pair
            sd[:, j] = self._band(int(g[j]), t[:, j])[0] / np.sqrt(12.0)
        sd = np.clip(sd * self.sd_scale, self.min_sd, self.max_sd)
        if self.noise_sd > 0:
            sd = np.hypot(sd, self.noise_sd)
        lp_lo, lp_hi = log_ndtr(v / sd), log_ndtr(-v / sd)
        if len(pieces) == 1:
            return lp_lo[:, 0], lp_hi[:, 0]
        ext = self._piece_extent[pieces]
        over = np.maximum(ext[:, 0] - t, 0) + np.maximum(t - ext[:, 1], 0)
        dist = np.hypot(v, over)
        far = dist > dist.min(axis=1, keepdims=True) + self.piece_reach
        lp_lo, lp_hi = np.where(far, 0.0, lp_lo), np.where(far, 0.0, lp_hi)  # far: no say
        if self._pair_inside[code]:  # lower class inside: on its side of all pieces
            return lp_lo.sum(axis=1), _log_any(lp_lo)
        return _log_any(lp_hi), lp_hi.sum(axis=1)

    def boundary_sites(
        self, step: float = 1.0, extend: float = 25.0, phase: float = 0.0
    ) -> dict[str, np.ndarray]:
        """Points along every boundary piece and how uncertain the boundary is there.

        The points run along each piece's line every ``step`` px (shifted by ``phase`` in [0, 1)),
        from ``extend`` px before its first straddling sample to ``extend`` px after its last; each
        sits in the middle of the band the piece's boundary must lie in (between the hulls of the
        samples on either side: any line separating them crosses there), and ``width`` is the
        band's width (px), growing by ``2 * extrapolation`` px per px beyond the samples. Points
        that the model does not put between the piece's two sounds are dropped.

        Returns
        -------
        dict with ``points`` (m, 2), ``width`` (m,), ``piece`` (m,), ``t`` (m,)
        """
        self._check_fitted()
        pts, wid, pcs, ts = [], [], [], []
        for p in range(len(self.piece_pair_)):
            g = int(self.piece_line_[p])
            nx, ny, c = self.lines_[g]
            t = np.arange(self._piece_extent[p, 0] - extend + phase * step,
                          self._piece_extent[p, 1] + extend, step)
            w, v = self._band(g, t)
            pts.append(np.outer(t, (-ny, nx)) + np.outer(v + c, (nx, ny)))
            wid.append(w)
            pcs.append(np.full(len(t), p))
            ts.append(t)
        if not pts:
            return {"points": np.empty((0, 2)), "width": np.empty(0),
                    "piece": np.empty(0, dtype=np.int64), "t": np.empty(0)}
        xy, w, pc, t = np.vstack(pts), np.concatenate(wid), np.concatenate(pcs), np.concatenate(ts)
        nrm = self.lines_[self.piece_line_[pc], :2] * self.piece_sign_[pc, None]
        pair = self.piece_pair_[pc]
        off = np.maximum(w / 2, 0.5)[:, None] * nrm
        ok = (self.predict_class(xy + off) == pair[:, 0]) & (
            self.predict_class(xy - off) == pair[:, 1]
        )
        return {"points": xy[ok], "width": w[ok], "piece": pc[ok], "t": t[ok]}

    # -- prediction -----------------------------------------------------------------------------
    def _slot_scores(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidate classes and their log-scores at each point.

        The candidates are the distinct classes among the ``n_neighbors`` nearest samples; a
        candidate's log-score is the sum over the other candidates of log p(on its side of their
        boundary) = log Phi(+-s / sigma). Repeated classes get -inf.

        Returns
        -------
        cls : (n, k) int ndarray
        score : (n, k) ndarray
        """
        n = len(q)
        k = int(min(self.n_neighbors, len(self.actions_)))
        _, idx = self._tree.query(q, k=k)
        cls = self.labels_[np.asarray(idx).reshape(n, k)]
        first = np.ones((n, k), dtype=bool)
        for c in range(1, k):  # k columns, each vectorized over the points
            first[:, c] = ~(cls[:, :c] == cls[:, c : c + 1]).any(axis=1)
        score = np.where(first, 0.0, -np.inf)
        near = first.sum(axis=1) >= 2
        if not near.any() or len(self.piece_pair_) == 0:
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
            if int(c) not in self._pair_pieces:
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
        """p(sound class | action) at each point.

        Parameters
        ----------
        points : (n, 2) ndarray

        Returns
        -------
        (n, C) ndarray
            Rows sum to 1.
        """
        p = self._predict(points, proba=True)
        if self.floor > 0:
            p = (1 - self.floor) * p + self.floor / p.shape[1]
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
        """(n, 2) draws from p(action | sound class ``cls``), uniform prior over the area.

        Rejection sampling: uniform proposals over the box of the class's samples (widened by
        their spacing; the whole area for silence), accepted with probability p(cls | proposal).

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

    # -- storage --------------------------------------------------------------------------------
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted model as named arrays (for an HDF5 artifact group)."""
        self._check_fitted()
        return {
            "class_features": self.class_features_.copy(),
            "actions": self.actions_.copy(),
            "labels": self.labels_.copy(),
            "edges": self.edges_.copy(),
            "edge_piece": self.edge_piece_.copy(),
            "piece_pair": self.piece_pair_.copy(),
            "piece_line": self.piece_line_.copy(),
            "piece_sign": self.piece_sign_.copy(),
            "lines": self.lines_.copy(),
            "merge_angle": np.float64(self.merge_angle),
            "merge_offset": np.float64(self.merge_offset),
            "piece_reach": np.float64(self.piece_reach),
            "reach_sd_fitted": np.float64(self.reach_sd_),
            "match_threshold": np.float64(self.match_threshold),
            "area": np.asarray(self.area, float),
            "n_neighbors": np.int64(self.n_neighbors),
            "min_sd": np.float64(self.min_sd),
            "max_sd": np.float64(self.max_sd),
            "sd_scale": np.float64(self.sd_scale),
            "noise_sd": np.float64(self.noise_sd),
            "floor": np.float64(self.floor),
            "noise_tol": np.float64(self.noise_tol),
            "extrapolation": np.float64(self.extrapolation),
        }

    @classmethod
    def from_arrays(cls, d: dict) -> LearnedModel:
        """Rebuild a fitted model from :meth:`to_arrays` output (exactly the same predictions)."""
        try:
            model = cls(
                match_threshold=float(d["match_threshold"]),
                area=tuple(float(v) for v in np.asarray(d["area"]).reshape(4)),
                n_neighbors=int(d["n_neighbors"]),
                min_sd=float(d["min_sd"]),
                max_sd=float(d["max_sd"]),
                sd_scale=float(d.get("sd_scale", 1.0)),  # absent before model schema 2
                noise_sd=float(d.get("noise_sd", 0.0)),
                floor=float(d.get("floor", 0.0)),
                noise_tol=float(d.get("noise_tol", 0.0)),
                extrapolation=float(d["extrapolation"]),
                merge_angle=float(d["merge_angle"]),
                merge_offset=float(d["merge_offset"]),
                piece_reach=float(d["piece_reach"]),
            )
            model._check_params()
            model._set_fitted(
                np.asarray(d["class_features"], float),
                np.asarray(d["actions"], float).reshape(-1, 2),
                np.asarray(d["labels"], np.int64),
                np.asarray(d["edges"], np.int64).reshape(-1, 2),
                np.asarray(d["edge_piece"], np.int64),
                np.asarray(d["piece_pair"], np.int64),
                np.asarray(d["piece_line"], np.int64),
                np.asarray(d["piece_sign"], float),
                np.asarray(d["lines"], float),
                float(d["reach_sd_fitted"]),
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise ArtifactError(
                f"not a stored learned model ({type(exc).__name__}: {exc})"
            ) from None
        return model
