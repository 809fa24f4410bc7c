"""Key shapes of an instrument: polygons or discs, and vectorized point location (Sect. III-A).

Every layout (:mod:`kbcli.core.instrument.layouts`) turns its config into a :class:`KeyShapes`, one
shape per key at the keyboard's reference pose, in pad pixels; everything that needs the keys'
geometry goes through it (:meth:`~KeyShapes.key_at`, :meth:`~KeyShapes.outlines`,
:meth:`~KeyShapes.label_points`, :meth:`~KeyShapes.sample`, :meth:`~KeyShapes.grid_points`,
:meth:`~KeyShapes.contains`, :attr:`~KeyShapes.bounds`). Points on an edge shared by two polygon
keys belong to the key on its right or above it, as in a grid of cells.

The checks a layout's keys must pass (:func:`check_polygon`, :func:`check_overlaps`,
:func:`check_in_pad`, with shapely) raise :class:`~kbcli.errors.ConfigError` naming the key:
vertices beyond :data:`MAX_COORD`, degenerate polygons and keys whose interiors overlap by more
than :data:`OVERLAP_AREA` px^2.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated

import numpy as np
import shapely
from pydantic import Field, Strict
from scipy.spatial import cKDTree

from kbcli.errors import ConfigError

DISC_VERTICES = 64  # vertices of a disc's outline polygon
#: px: the largest |x| or |y| of a key's vertex (the pad is ~800 px; far beyond is a typo).
MAX_COORD = 10_000.0
#: A vertex coordinate in a config: a finite number within [-MAX_COORD, MAX_COORD] px.
Coordinate = Annotated[float, Strict(), Field(ge=-MAX_COORD, le=MAX_COORD, allow_inf_nan=False)]
MIN_AREA = 1.0  # px^2: a key smaller than this is degenerate
#: px^2: two keys whose intersection is larger than this overlap (a shared edge has area 0).
OVERLAP_AREA = 1e-9
_CHUNK = 1 << 18  # points per block in the crossing test


def polygon_area(v: np.ndarray) -> float:
    """Signed area (px^2) of a polygon, positive when its vertices run counter-clockwise."""
    v = np.asarray(v, float)
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def polygon_centroid(v: np.ndarray) -> np.ndarray:
    """(2,) area centroid of a simple polygon."""
    v = np.asarray(v, float)
    w = np.roll(v, -1, axis=0)
    cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
    a = cross.sum() / 2
    return np.array([((v[:, 0] + w[:, 0]) * cross).sum(), ((v[:, 1] + w[:, 1]) * cross).sum()]) / (
        6 * a)


def points_in_polygon(points: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n,) bool: whether each point is inside the polygon ``v`` (m, 2) (even-odd rule).

    Half-open: a point on a vertical edge is inside the polygon to its right, on a horizontal edge
    inside the polygon above it. Each edge is evaluated from its lower end, so two keys sharing a
    slanted edge compute the same crossing bit for bit and a point on it is in exactly one of them.
    Vectorized over points; a loop over the (few) edges.
    """
    p = np.asarray(points, float).reshape(-1, 2)
    v = np.asarray(v, float)
    out = np.zeros(len(p), dtype=bool)
    for lo in range(0, len(p), _CHUNK):
        px, py = p[lo:lo + _CHUNK, 0], p[lo:lo + _CHUNK, 1]
        inside = np.zeros(len(px), dtype=bool)
        for i in range(len(v)):  # the polygon's edges: a handful per key
            (x1, y1), (x2, y2) = sorted((tuple(v[i]), tuple(v[(i + 1) % len(v)])),
                                        key=lambda q: q[1])  # lower end first: see above
            if y1 == y2:
                continue
            spans = (y1 > py) != (y2 > py)
            xc = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
            inside ^= spans & (px < xc)
        out[lo:lo + _CHUNK] = inside
    return out


def segment_distance(points: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n,) distance from each point to the boundary of the polygon ``v`` (its closed outline)."""
    p = np.asarray(points, float).reshape(-1, 2)
    a = np.asarray(v, float)
    b = np.roll(a, -1, axis=0)
    ab = b - a
    ll = np.maximum((ab * ab).sum(axis=1), 1e-300)
    t = np.clip(np.einsum("ned,ed->ne", p[:, None, :] - a[None], ab) / ll, 0.0, 1.0)
    foot = a[None] + t[..., None] * ab[None]
    return np.hypot(*(p[:, None, :] - foot).transpose(2, 0, 1)).min(axis=1)


def _as_vertices(vertices: Sequence, what: str) -> np.ndarray:
    """(m, 2) finite vertices within :data:`MAX_COORD`; ConfigError naming ``what`` otherwise."""
    try:
        v = np.asarray(vertices, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{what}: vertices must be a list of [x, y] pairs") from None
    if v.ndim != 2 or v.shape[1] != 2:
        raise ConfigError(f"{what}: vertices must be a list of [x, y] pairs, got shape {v.shape}")
    if not np.isfinite(v).all():
        raise ConfigError(f"{what}: vertices must be finite numbers")
    if len(v) and np.abs(v).max() > MAX_COORD:
        raise ConfigError(f"{what}: vertices must lie within -{MAX_COORD:g}..{MAX_COORD:g} px, "
                          f"got {np.abs(v).max():g}")
    return v


def _deduplicated(v: np.ndarray) -> np.ndarray:
    """``v`` without repeated consecutive vertices and without a closing copy of the first."""
    keep = np.ones(len(v), dtype=bool)
    keep[1:] = np.any(v[1:] != v[:-1], axis=1)
    v = v[keep]
    if len(v) > 1 and np.array_equal(v[0], v[-1]):
        v = v[:-1]
    return v


def check_polygon(vertices: Sequence, what: str) -> np.ndarray:
    """A key's polygon, cleaned and counter-clockwise; ConfigError naming ``what`` if degenerate.

    Repeated consecutive vertices (and a closing vertex equal to the first) are dropped. Refused:
    non-finite coordinates or beyond :data:`MAX_COORD` (before anything is built from them), fewer
    than three distinct vertices, an area under 1 px^2, and an outline that is not simple (its
    edges cross or touch: shapely's ``is_simple`` of the ring).
    """
    v = _deduplicated(_as_vertices(vertices, what))
    if len(np.unique(v, axis=0)) < 3:
        raise ConfigError(f"{what}: degenerate polygon: fewer than 3 distinct vertices")
    area = polygon_area(v)
    hull = shapely.MultiPoint(v).convex_hull.area
    if hull >= MIN_AREA and not shapely.LinearRing(v).is_simple:
        reason = shapely.is_valid_reason(shapely.Polygon(v))
        raise ConfigError(f"{what}: degenerate polygon: its edges cross (a self-intersecting "
                          f"outline: {reason})")
    if abs(area) < MIN_AREA:
        raise ConfigError(f"{what}: degenerate polygon: its area is {abs(area):.3g} px^2 "
                          f"(at least {MIN_AREA:g} needed)")
    return v if area > 0 else v[::-1].copy()


def disc_outline(centre: np.ndarray, radius: float, n: int = DISC_VERTICES) -> np.ndarray:
    """(n, 2) counter-clockwise polygon inscribed in a disc."""
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.asarray(centre, float) + radius * np.column_stack([np.cos(a), np.sin(a)])


class KeyShapes:
    """The keys of a layout: K polygons, or K discs (see the module docstring).

    Parameters
    ----------
    polygons : sequence of (m_k, 2) arrays, optional
        Counter-clockwise outlines (see :func:`check_polygon`).
    discs : (K, 3) ndarray, optional
        ``(cx, cy, radius)`` of each disc key.
    """

    def __init__(self, polygons: Sequence[np.ndarray] | None = None,
                 discs: np.ndarray | None = None) -> None:
        if (polygons is None) == (discs is None):
            raise ValueError("give either polygons or discs")
        self.discs = None if discs is None else np.asarray(discs, float).reshape(-1, 3)
        if self.discs is not None:
            self.polygons = [disc_outline(d[:2], d[2]) for d in self.discs]
            self._tree = cKDTree(self.discs[:, :2])
        else:
            self.polygons = [np.asarray(p, float) for p in polygons]
        self.n_keys = len(self.polygons)
        if self.n_keys == 0:
            raise ConfigError("a keyboard needs at least one key")
        if self.discs is not None:
            c, r = self.discs[:, :2], self.discs[:, 2:]
            self.boxes = np.hstack([c - r, c + r])
        else:
            self.boxes = np.array([[*p.min(axis=0), *p.max(axis=0)] for p in self.polygons])

    @property
    def kind(self) -> str:
        """``polygon`` or ``disc``."""
        return "disc" if self.discs is not None else "polygon"

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of all keys."""
        b = self.boxes
        return (float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()),
                float(b[:, 3].max()))

    def key_at(self, points: np.ndarray) -> np.ndarray:
        """(n,) int: the key under each point of (n, 2) ``points``, -1 for silence."""
        p = np.asarray(points, float).reshape(-1, 2)
        out = np.full(len(p), -1, dtype=np.int64)
        if len(p) == 0:
            return out
        if self.discs is not None:  # the nearest centre is the only disc a point can be in
            d, k = self._tree.query(p)
            k = np.asarray(k, np.int64).reshape(-1)
            inside = np.asarray(d).reshape(-1) <= self.discs[np.minimum(k, self.n_keys - 1), 2]
            out[inside] = k[inside]
            return out
        for k, (poly, box) in enumerate(zip(self.polygons, self.boxes, strict=True)):
            cand = np.flatnonzero((p[:, 0] >= box[0]) & (p[:, 0] <= box[2])
                                  & (p[:, 1] >= box[1]) & (p[:, 1] <= box[3]) & (out < 0))
            if len(cand):
                out[cand[points_in_polygon(p[cand], poly)]] = k
        return out

    def shifted(self, dx: float, dy: float) -> KeyShapes:
        """The same keys moved by (dx, dy) px."""
        if self.discs is not None:
            return KeyShapes(discs=self.discs + (dx, dy, 0.0))
        return KeyShapes(polygons=[p + (dx, dy) for p in self.polygons])

    def contains(self, k: int, points: np.ndarray) -> np.ndarray:
        """(n,) bool: whether each of (n, 2) ``points`` is in key ``k`` alone (the same half-open
        rule as :meth:`key_at`, without looking at the other keys)."""
        p = np.asarray(points, float).reshape(-1, 2)
        if self.discs is not None:
            cx, cy, r = self.discs[k]
            return np.hypot(p[:, 0] - cx, p[:, 1] - cy) <= r
        x0, y0, x1, y1 = self.boxes[k]
        out = np.zeros(len(p), dtype=bool)
        box = np.flatnonzero((p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1))
        out[box] = points_in_polygon(p[box], self.polygons[k])
        return out

    def shapely(self) -> np.ndarray:
        """(K,) shapely Polygons of the keys (discs as their 64-gon outlines)."""
        coords = np.vstack(self.polygons)
        index = np.repeat(np.arange(self.n_keys), [len(p) for p in self.polygons])
        return shapely.polygons(shapely.linearrings(coords, indices=index))

    def outlines(self) -> list[np.ndarray]:
        """The boundary of each key as a counter-clockwise polygon (discs as 64-gons)."""
        return [p.copy() for p in self.polygons]

    def label_points(self) -> np.ndarray:
        """(K, 2) a point inside each key: its centroid when that is inside, else the inner point
        furthest from the key's edges (on a fine grid)."""
        if self.discs is not None:
            return self.discs[:, :2].copy()
        out = np.empty((self.n_keys, 2))
        for k, poly in enumerate(self.polygons):  # one per key
            c = polygon_centroid(poly)
            if points_in_polygon(c[None], poly)[0] and segment_distance(c[None], poly)[0] > 0:
                out[k] = c
                continue
            x0, y0, x1, y1 = self.boxes[k]
            g = np.stack(np.meshgrid(np.linspace(x0, x1, 41), np.linspace(y0, y1, 41)),
                         -1).reshape(-1, 2)
            g = g[points_in_polygon(g, poly)]
            out[k] = g[int(np.argmax(segment_distance(g, poly)))]
        return out

    def sample(self, k: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) uniform draws inside key ``k`` (rejection from its bounding box)."""
        x0, y0, x1, y1 = self.boxes[k]
        out = np.empty((0, 2))
        while len(out) < n:
            p = rng.uniform((x0, y0), (x1, y1), size=(2 * (n - len(out)) + 16, 2))
            out = np.vstack([out, p[self.key_at(p) == k]])
        return out[:n]

    def grid_points(self, per_side: int) -> tuple[np.ndarray, np.ndarray]:
        """An even grid of points inside every key: ``per_side`` x ``per_side`` cell centres over
        each key's bounding box, kept where the key is (and off its edges).

        Returns
        -------
        points : (m, 2) ndarray
        keys : (m,) int ndarray
        """
        u = (np.arange(per_side) + 0.5) / per_side
        gx, gy = np.meshgrid(u, u)
        unit = np.column_stack([gx.ravel(), gy.ravel()])
        pts, keys = [], []
        for k, (x0, y0, x1, y1) in enumerate(self.boxes):
            p = np.array([x0, y0]) + unit * np.array([x1 - x0, y1 - y0])
            p = p[self.key_at(p) == k]
            p = p[segment_distance(p, self.polygons[k]) > 1e-6]  # off the edges: no ties
            pts.append(p)
            keys.append(np.full(len(p), k, dtype=np.int64))
        return np.vstack(pts), np.concatenate(keys)

    def outline_points(self, spacing: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
        """Points along every key's outline (its vertices and at most ``spacing`` px apart).

        Returns
        -------
        points : (m, 2) ndarray
        keys : (m,) int ndarray
        """
        pts, keys = [], []
        for k, poly in enumerate(self.polygons):
            a, b = poly, np.roll(poly, -1, axis=0)
            for p, q in zip(a, b, strict=True):  # a few edges per key
                n = max(1, int(np.ceil(np.hypot(*(q - p)) / spacing)))
                t = np.arange(n)[:, None] / n
                pts.append(p + t * (q - p))
                keys.append(np.full(n, k, dtype=np.int64))
        return np.vstack(pts), np.concatenate(keys)


def check_overlaps(shapes: KeyShapes, names: Sequence[str]) -> None:
    """ConfigError naming the first two keys whose interiors overlap (sharing an edge is allowed).

    Discs overlap when their centres are closer than the sum of their radii. Polygons overlap when
    the area of their intersection (shapely) exceeds :data:`OVERLAP_AREA` px^2 (plus 1e-12 of the
    smaller key's area, for round-off on long shared edges): exact, so keys overlapping by a
    fraction of a pixel are refused. Pairs are found with an STR-tree, areas computed vectorised.
    """
    ii, jj = overlapping_pairs(shapes)
    if len(ii):
        i, j = int(ii[0]), int(jj[0])
        raise ConfigError(f"keys {i} ({names[i]}) and {j} ({names[j]}) overlap")


def overlapping_pairs(shapes: KeyShapes) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) index arrays, i < j, of the key pairs whose interiors overlap (see
    :func:`check_overlaps`), in lexicographic order."""
    if shapes.discs is not None:
        d = shapes.discs
        ii, jj = np.triu_indices(shapes.n_keys, 1)
        gap = np.hypot(d[ii, 0] - d[jj, 0], d[ii, 1] - d[jj, 1]) - d[ii, 2] - d[jj, 2]
        bad = gap < -1e-9
        return ii[bad], jj[bad]
    polys = shapes.shapely()
    ii, jj = shapely.STRtree(polys).query(polys, predicate="intersects")
    keep = ii < jj
    ii, jj = ii[keep], jj[keep]
    area = shapely.area(shapely.intersection(polys[ii], polys[jj]))
    tol = OVERLAP_AREA + 1e-12 * np.minimum(shapely.area(polys[ii]), shapely.area(polys[jj]))
    bad = area > tol
    order = np.lexsort((jj[bad], ii[bad]))
    return ii[bad][order].astype(np.int64), jj[bad][order].astype(np.int64)


def check_key_areas(shapes: KeyShapes, names: Sequence[str]) -> None:
    """ConfigError naming the smallest key when its area is under :data:`MIN_AREA` px^2 (a key
    size or pad radius of 1e-9 px: a keyboard no touch could find)."""
    if shapes.discs is not None:
        areas = np.pi * shapes.discs[:, 2] ** 2
    else:
        areas = np.array([abs(polygon_area(p - p.mean(axis=0))) for p in shapes.polygons])
    k = int(np.argmin(areas))
    if not areas[k] >= MIN_AREA:
        raise ConfigError(f"key {k} ({names[k]}) has an area of {areas[k]:.3g} px^2, at least "
                          f"{MIN_AREA:g} needed: the layout's key sizes are too small")


def check_in_pad(shapes: KeyShapes) -> None:
    """ConfigError unless every key lies inside the pad's coordinate box (|x|, |y| <=
    :data:`MAX_COORD` px): a far origin is refused before anything is sampled over the keys."""
    x0, y0, x1, y1 = shapes.bounds
    far = max(abs(x0), abs(y0), abs(x1), abs(y1))
    if not far <= MAX_COORD:
        raise ConfigError(f"the keys must lie within -{MAX_COORD:g}..{MAX_COORD:g} px of the pad's "
                          f"origin, got a key at {far:g} px: move origin")
