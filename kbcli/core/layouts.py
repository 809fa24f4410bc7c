"""Layouts of the instrument: a registry of how keys are shaped, placed and tuned (Sect. III-A).

The paper's Reactable shows any virtual object; a layout turns the layout-specific part of a
:class:`~kbcli.core.keyboard.KeyboardConfig` into the keys' shapes (:class:`KeyShapes`, in the
keyboard's own frame, lower-left at (0, 0)), their pitches (MIDI) and tempi (bpm). Registered
(:data:`LAYOUTS`; ``kbcli keyboard --layout NAME``):

``grid`` (the paper's Fig. 2)
    ``rows`` x ``cols`` square keys of side ``key_size``; pitches climb ``scale`` row by row from
    ``base_note``; the tempo of key (r, c) is ``tempo_base + c * tempo_col_step + r *
    tempo_row_step``.
``hex`` (a hexagonal isomorphic keyboard)
    ``rows`` rows of ``cols`` pointy-top hexagons, ``key_size`` across the flats, odd rows shifted
    right by half a key. Wicki-Hayden tuning: one key right is a whole tone up, up-right a fifth,
    up-left a fourth (``pitch = base + 2 (c - r // 2) + 7 r``); the same note can sit on several
    keys, told apart by their tempo (as the grid's).
``piano`` (white keys and narrower black keys)
    ``cols`` white keys of ``key_size`` x ``key_height`` from ``base_note`` (a natural) up; black
    keys of ``black_width`` x ``black_height`` stand in the upper row between the white keys that
    have a sharp between them, so the white keys are L- or T-shaped. Keys are numbered by pitch
    (chromatic). Tempo: ``tempo_base + i * tempo_col_step`` for the i-th white key (a black key
    takes its left neighbour's i) plus ``tempo_row_step`` for black keys.
``pads`` (round pads with silence between them: curved boundaries)
    ``rows`` x ``cols`` discs of radius ``pad_radius`` centred in cells of ``key_size``; pitches and
    tempi as the grid's. The keyboard's bounds are its cells (as the grid's).
``polygons`` (explicit keys, rotated or irregular)
    ``keys``: one table per key with ``vertices`` (a list of [x, y], offsets from ``origin``, which
    defaults to (0, 0): pad coordinates), and optionally ``note`` (a name or MIDI number; default:
    climbing ``scale`` from ``base_note`` in key order) and ``tempo`` (bpm; default
    ``tempo_base + k * tempo_col_step``).

A layout declares which config fields it uses and their defaults; the others must be left out. Its
builder raises :class:`~kbcli.errors.ConfigError` naming the key or option at fault.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kbcli.core.config import check_whole
from kbcli.core.geometry import KeyShapes, check_polygon
from kbcli.core.notes import BLACK, NATURAL, midi_to_name, name_to_midi, scale_pitches
from kbcli.errors import ConfigError

#: The keyboard config a layout builds from (:class:`kbcli.core.keyboard.KeyboardConfig`; not
#: imported here: the keyboard imports its layouts).
KeyboardConfig = Any
MAX_KEYS = 256
#: Where every layout's default origin puts the keyboard's centre (the default grid's centre).
DEFAULT_CENTRE = (400.0, 350.0)


class GridShapes(KeyShapes):
    """Square keys on a grid: the same shapes, with arithmetic lookups (the paper's keyboard)."""

    def __init__(self, rows: int, cols: int, size: float, origin=(0.0, 0.0)) -> None:
        self.rows, self.cols, self.size = rows, cols, float(size)
        self.origin = np.asarray(origin, float)
        k = np.arange(rows * cols)
        self.centres = np.column_stack([self.origin[0] + (k % cols + 0.5) * size,
                                        self.origin[1] + (k // cols + 0.5) * size])
        h = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * (size / 2)
        super().__init__(polygons=[c + h for c in self.centres])

    def moved(self, origin) -> GridShapes:
        return GridShapes(self.rows, self.cols, self.size, origin)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        x0, y0 = self.origin
        return (float(x0), float(y0), float(x0 + self.cols * self.size),
                float(y0 + self.rows * self.size))

    def key_at(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        u = (p - self.origin) / self.size
        col = np.floor(u[:, 0])
        row = np.floor(u[:, 1])
        inside = (col >= 0) & (col < self.cols) & (row >= 0) & (row < self.rows)
        out = np.full(len(p), -1, dtype=np.int64)
        out[inside] = (row[inside] * self.cols + col[inside]).astype(np.int64)
        return out

    def label_points(self) -> np.ndarray:
        return self.centres.copy()

    def sample(self, k: int, n: int, rng: np.random.Generator) -> np.ndarray:
        half = self.size / 2
        return rng.uniform(self.centres[k] - half, self.centres[k] + half, size=(n, 2))


@dataclass(frozen=True)
class LayoutGeometry:
    """What a layout builds, in the keyboard's own frame or on the pad.

    Attributes
    ----------
    shapes : KeyShapes
    pitches : (K,) int ndarray
        MIDI note of each key.
    tempos : (K,) ndarray
        Tempo of each key, bpm.
    bounds : tuple of float
        (xmin, ymin, xmax, ymax) of the keyboard (the keys' box, or the pads' cells).
    """

    shapes: KeyShapes
    pitches: np.ndarray
    tempos: np.ndarray
    bounds: tuple[float, float, float, float]

    def moved(self, offset: tuple[float, float]) -> LayoutGeometry:
        """The same keys shifted by ``offset`` (px)."""
        dx, dy = (float(v) for v in offset)
        s = self.shapes
        if isinstance(s, GridShapes):
            shapes: KeyShapes = s.moved(s.origin + (dx, dy))
        elif s.discs is not None:
            shapes = KeyShapes(discs=s.discs + (dx, dy, 0.0))
        else:
            shapes = KeyShapes(polygons=[p + (dx, dy) for p in s.polygons])
        x0, y0, x1, y1 = self.bounds
        return LayoutGeometry(shapes, self.pitches, self.tempos, (x0 + dx, y0 + dy, x1 + dx, y1 + dy))


@dataclass(frozen=True)
class Layout:
    """A registered layout: the config fields it uses (with defaults) and its builder."""

    name: str
    summary: str
    defaults: dict[str, Any]
    build: Callable[[KeyboardConfig], LayoutGeometry]
    uses_scale: bool = True
    default_origin: tuple[float, float] | None = None  # None: centre on DEFAULT_CENTRE
    checks_overlap: bool = False  # whether build()'s keys may overlap (explicit polygons)
    fields: tuple[str, ...] = field(default=())


LAYOUTS: dict[str, Layout] = {}
#: Config fields that belong to some layouts only (the rest apply to every layout).
LAYOUT_FIELDS = ("rows", "cols", "key_size", "key_height", "black_width", "black_height",
                 "pad_radius", "keys")


def layout(name: str, summary: str, defaults: dict[str, Any], **kw: Any):
    """Decorator registering a builder as layout ``name``."""

    def deco(fn: Callable[[KeyboardConfig], LayoutGeometry]):
        LAYOUTS[name] = Layout(name, summary, defaults, fn, fields=tuple(defaults), **kw)
        return fn

    return deco


def get_layout(name: str) -> Layout:
    """The layout called ``name``; ConfigError listing the valid ones otherwise."""
    try:
        return LAYOUTS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown layout {name!r}; valid: {', '.join(LAYOUTS)}") from None


# -- helpers ----------------------------------------------------------------------------------------
def _size(name: str, v: object) -> float:
    if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
        raise ConfigError(f"{name} must be a positive finite number, got {v!r}")
    return float(v)


def _count(rows: int, cols: int) -> None:
    if rows * cols > MAX_KEYS:
        raise ConfigError(f"rows x cols must be at most {MAX_KEYS} keys, got {rows * cols}")


def _rowcol_tempo(cfg: KeyboardConfig, rows: int, cols: int) -> np.ndarray:
    k = np.arange(rows * cols)
    return (cfg.tempo_base + (k % cols) * cfg.tempo_col_step
            + (k // cols) * cfg.tempo_row_step).astype(float)


def _base(cfg: KeyboardConfig) -> int:
    return name_to_midi(cfg.base_note)


# -- the layouts ------------------------------------------------------------------------------------
@layout("grid", "rows x cols square keys (the paper's keyboard)",
        {"rows": 4, "cols": 8, "key_size": 50.0}, default_origin=(200.0, 250.0))
def _grid(cfg: KeyboardConfig) -> LayoutGeometry:
    rows, cols = check_whole("rows", cfg.rows), check_whole("cols", cfg.cols)
    _count(rows, cols)
    s = _size("key_size", cfg.key_size)
    shapes = GridShapes(rows, cols, s)
    return LayoutGeometry(shapes, scale_pitches(_base(cfg), cfg.scale, rows * cols),
                          _rowcol_tempo(cfg, rows, cols), shapes.bounds)


@layout("hex", "hexagonal isomorphic keys (Wicki-Hayden)", {"rows": 4, "cols": 8, "key_size": 50.0},
        uses_scale=False)
def _hex(cfg: KeyboardConfig) -> LayoutGeometry:
    rows, cols = check_whole("rows", cfg.rows), check_whole("cols", cfg.cols)
    _count(rows, cols)
    w = _size("key_size", cfg.key_size)
    rad = w / math.sqrt(3)  # circumradius of a hexagon w across the flats
    k = np.arange(rows * cols)
    r, c = k // cols, k % cols
    cx = w / 2 + c * w + (r % 2) * w / 2
    cy = rad + r * 1.5 * rad
    ang = np.deg2rad(30 + 60 * np.arange(6))
    unit = np.column_stack([np.cos(ang), np.sin(ang)]) * rad
    polys = [np.array([x, y]) + unit for x, y in zip(cx, cy, strict=True)]
    pitches = _base(cfg) + 2 * (c - r // 2) + 7 * r
    shapes = KeyShapes(polygons=polys)
    return LayoutGeometry(shapes, pitches.astype(np.int64), _rowcol_tempo(cfg, rows, cols),
                          shapes.bounds)


@layout("piano", "white keys and narrower black keys in the upper row",
        {"cols": 12, "key_size": 36.0, "key_height": 160.0, "black_width": 20.0,
         "black_height": 100.0}, uses_scale=False)
def _piano(cfg: KeyboardConfig) -> LayoutGeometry:
    n = check_whole("cols", cfg.cols)
    w, h = _size("key_size", cfg.key_size), _size("key_height", cfg.key_height)
    bw, bh = _size("black_width", cfg.black_width), _size("black_height", cfg.black_height)
    if bw >= w:
        raise ConfigError(f"black_width ({bw:g}) must be below key_size ({w:g}), the white keys' "
                          "width: black keys would overlap")
    if bh >= h:
        raise ConfigError(f"black_height ({bh:g}) must be below key_height ({h:g})")
    base = _base(cfg)
    if base % 12 not in NATURAL:
        raise ConfigError(f"a piano starts on a white key: base_note {cfg.base_note!r} "
                          f"({midi_to_name(base)}) is a black key")
    whites = [base]
    while len(whites) < n:
        p = whites[-1] + 1
        whites.append(p + 1 if p % 12 in BLACK else p)
    # a black key between white keys i and i + 1 when a sharp lies between them
    black_after = [i for i in range(n - 1) if whites[i + 1] - whites[i] == 2]
    if n + len(black_after) > MAX_KEYS:
        raise ConfigError(f"a piano of {n} white keys has more than {MAX_KEYS} keys")
    keys: list[tuple[int, np.ndarray, float]] = []
    left = {i + 1 for i in black_after}
    right = set(black_after)
    for i, p in enumerate(whites):
        x0, x1 = i * w, (i + 1) * w
        v = [(x0, 0.0), (x1, 0.0)]
        v += [(x1, h - bh), (x1 - bw / 2, h - bh), (x1 - bw / 2, h)] if i in right else [(x1, h)]
        v += [(x0 + bw / 2, h), (x0 + bw / 2, h - bh), (x0, h - bh)] if i in left else [(x0, h)]
        keys.append((p, np.array(v), cfg.tempo_base + i * cfg.tempo_col_step))
    for i in black_after:
        xc = (i + 1) * w
        v = np.array([(xc - bw / 2, h - bh), (xc + bw / 2, h - bh), (xc + bw / 2, h),
                      (xc - bw / 2, h)])
        keys.append((whites[i] + 1, v,
                     cfg.tempo_base + i * cfg.tempo_col_step + cfg.tempo_row_step))
    keys.sort(key=lambda t: t[0])
    shapes = KeyShapes(polygons=[k[1] for k in keys])
    return LayoutGeometry(shapes, np.array([k[0] for k in keys], np.int64),
                          np.array([k[2] for k in keys], float), shapes.bounds)


@layout("pads", "round pads with silence between them",
        {"rows": 4, "cols": 8, "key_size": 50.0, "pad_radius": 20.0})
def _pads(cfg: KeyboardConfig) -> LayoutGeometry:
    rows, cols = check_whole("rows", cfg.rows), check_whole("cols", cfg.cols)
    _count(rows, cols)
    s, r = _size("key_size", cfg.key_size), _size("pad_radius", cfg.pad_radius)
    if 2 * r > s:
        raise ConfigError(f"pad_radius ({r:g}) must be at most half of key_size ({s:g}), the "
                          "distance between pad centres: pads would overlap")
    k = np.arange(rows * cols)
    discs = np.column_stack([(k % cols + 0.5) * s, (k // cols + 0.5) * s, np.full(len(k), r)])
    return LayoutGeometry(KeyShapes(discs=discs), scale_pitches(_base(cfg), cfg.scale, len(k)),
                          _rowcol_tempo(cfg, rows, cols), (0.0, 0.0, cols * s, rows * s))


@dataclass(frozen=True)
class PolygonKey:
    """One key of the ``polygons`` layout (a ``[[keyboard.keys]]`` table).

    Attributes
    ----------
    vertices : tuple of (x, y)
        Its outline, offsets from the keyboard's origin (px).
    note : str or int, optional
        Its note (a name like ``F#4`` or a MIDI number).
    tempo : float, optional
        Its tempo (bpm).
    """

    vertices: tuple[tuple[float, float], ...]
    note: str | int | None = None
    tempo: float | None = None

    @classmethod
    def from_dict(cls, d: Any, i: int) -> PolygonKey:
        if isinstance(d, PolygonKey):
            return d
        if not isinstance(d, dict):
            raise ConfigError(f"keys[{i}] must be a table with vertices (and optionally note, "
                              "tempo)")
        unknown = sorted(set(d) - {"vertices", "note", "tempo"})
        if unknown:
            raise ConfigError(f"keys[{i}]: unknown option {unknown[0]!r}; valid: vertices, note, "
                              "tempo")
        if "vertices" not in d:
            raise ConfigError(f"keys[{i}]: no vertices")
        try:
            verts = tuple((float(x), float(y)) for x, y in d["vertices"])
        except (TypeError, ValueError):
            raise ConfigError(f"keys[{i}]: vertices must be a list of [x, y] pairs") from None
        note = d.get("note")
        if note is not None and (isinstance(note, bool) or not isinstance(note, (str, int))):
            raise ConfigError(f"keys[{i}]: note must be a name like C4 or a MIDI number")
        tempo = d.get("tempo")
        if tempo is not None:
            tempo = _size(f"keys[{i}].tempo", tempo)
        return cls(verts, note, tempo)

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"vertices": [list(v) for v in self.vertices]}
        if self.note is not None:
            d["note"] = self.note
        if self.tempo is not None:
            d["tempo"] = self.tempo
        return d


@layout("polygons", "explicit key polygons (rotated or irregular) from the TOML",
        {"keys": None}, default_origin=(0.0, 0.0), checks_overlap=True)
def _polygons(cfg: KeyboardConfig) -> LayoutGeometry:
    if not cfg.keys:
        raise ConfigError("the polygons layout needs its keys: a [[keyboard.keys]] table per key "
                          "with vertices = [[x, y], ...] (see pipelines/layouts/polygons.toml)")
    if len(cfg.keys) > MAX_KEYS:
        raise ConfigError(f"at most {MAX_KEYS} keys, got {len(cfg.keys)}")
    climb = scale_pitches(_base(cfg), cfg.scale, len(cfg.keys))
    polys, pitches, tempos = [], [], []
    for i, key in enumerate(cfg.keys):
        polys.append(check_polygon(key.vertices, f"key {i}"))
        if key.note is None:
            pitches.append(int(climb[i]))
        elif isinstance(key.note, str):
            pitches.append(name_to_midi(key.note))
        else:
            pitches.append(int(key.note))
        if not 0 <= pitches[-1] <= 127:
            raise ConfigError(f"key {i}: note {key.note!r} is outside MIDI 0..127")
        tempos.append(cfg.tempo_base + i * cfg.tempo_col_step if key.tempo is None else key.tempo)
    shapes = KeyShapes(polygons=polys)
    return LayoutGeometry(shapes, np.array(pitches, np.int64), np.array(tempos, float),
                          shapes.bounds)


def example_polygon_keys() -> tuple[PolygonKey, ...]:
    """The ``polygons`` example (``pipelines/layouts/polygons.toml``): a fan of two rings of seven
    turned trapezoids around (400, 250), a square turned by 25 degrees and an irregular pentagon.

    Vertices are pad coordinates rounded to 0.01 px (the fan's rings share their edges exactly).
    """
    centre = np.array([400.0, 250.0])
    keys: list[PolygonKey] = []
    for r0, r1 in ((90.0, 150.0), (150.0, 210.0)):
        for a0 in range(160, 20, -20):  # left to right
            th = np.deg2rad([a0, a0 - 20])
            u = np.column_stack([np.cos(th), np.sin(th)])
            v = np.vstack([centre + r0 * u[0], centre + r0 * u[1], centre + r1 * u[1],
                           centre + r1 * u[0]])
            keys.append(PolygonKey(tuple((round(float(x), 2), round(float(y), 2)) for x, y in v)))
    a = np.deg2rad(25.0)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    square = np.array([[-18.0, -18.0], [18.0, -18.0], [18.0, 18.0], [-18.0, 18.0]]) @ rot.T + (
        330.0, 245.0)
    keys.append(PolygonKey(tuple((round(float(x), 2), round(float(y), 2)) for x, y in square),
                           note="F#5", tempo=140.0))
    pentagon = ((452.0, 232.0), (490.0, 228.0), (500.0, 250.0), (478.0, 268.0), (455.0, 262.0))
    keys.append(PolygonKey(pentagon, note=90, tempo=150.0))
    return tuple(keys)


def example_config_fields(name: str) -> dict[str, Any]:
    """Config fields of the example keyboard of a layout (the polygons' keys; nothing otherwise)."""
    get_layout(name)
    return {"keys": example_polygon_keys()} if name == "polygons" else {}
