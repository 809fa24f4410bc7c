"""The ``polygons`` layout: explicit keys, rotated or irregular, from the TOML.

``keys``: one ``[[keyboard.keys]]`` table per key (:class:`PolygonKey`) with ``vertices`` (a list of
[x, y], offsets from ``origin``, which defaults to (0, 0): pad coordinates), and optionally ``note``
(a name or MIDI number; default: climbing ``scale`` from ``base_note`` in key order) and ``tempo``
(bpm; default ``tempo_base + k * tempo_col_step``). Each outline is checked
(:func:`~kbcli.core.instrument.geometry.check_polygon`); the keyboard checks that no two keys overlap.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from pydantic import field_validator

from kbcli.core.config import Config, Positive
from kbcli.core.instrument.geometry import Coordinate, KeyShapes, check_polygon
from kbcli.core.instrument.layouts.base import (
    MAX_KEYS,
    KeyboardConfig,
    LayoutGeometry,
    base_midi,
    layout,
)
from kbcli.core.instrument.notes import name_to_midi, scale_pitches
from kbcli.core.options import Options
from kbcli.errors import ConfigError


class PolygonKey(Config):
    """One key of the ``polygons`` layout (a ``[[keyboard.keys]]`` table).

    Attributes
    ----------
    vertices : tuple of (x, y)
        Its outline, offsets from the keyboard's origin (px, each within
        :data:`~kbcli.core.instrument.geometry.MAX_COORD`).
    note : str or int, optional
        Its note (a name like ``F#4`` or a MIDI number).
    tempo : float, optional
        Its tempo (bpm).
    """

    what: ClassVar[str] = "keys"
    vertices: tuple[tuple[Coordinate, Coordinate], ...]
    note: str | int | None = None
    tempo: Positive | None = None

    @field_validator("note", mode="before")
    @classmethod
    def _note(cls, v: Any) -> Any:
        if v is not None and (isinstance(v, bool) or not isinstance(v, (str, int, np.integer))):
            raise ValueError("note must be a name like C4 or a MIDI number")
        return v

    def to_dict(self) -> dict[str, Any]:
        """The key's table: its vertices, and its note and tempo when given."""
        d = super().to_dict()
        return {k: v for k, v in d.items() if v is not None}


def polygon_keys(keys: Any) -> tuple[PolygonKey, ...]:
    """``[[keyboard.keys]]`` tables (or keys) as :class:`PolygonKey`; a bad one is named
    ``keys[i]``."""
    if isinstance(keys, (str, bytes)) or not isinstance(keys, Sequence):
        raise ConfigError("keys must be a list of tables ([[keyboard.keys]])")
    out = []
    for i, k in enumerate(keys):
        if isinstance(k, PolygonKey):
            out.append(k)
            continue
        if not isinstance(k, dict):
            raise ConfigError(f"keys[{i}] must be a table with vertices (and optionally note, "
                              "tempo)")
        try:
            out.append(PolygonKey(**k))
        except ConfigError as exc:  # name the key: "keys.tempo ..." -> "keys[3].tempo ..."
            msg = str(exc)
            msg = (msg.replace("keys option", f"keys[{i}] option", 1) if msg.startswith("unknown")
                   else f"keys[{i}]{msg[len('keys'):]}")
            raise ConfigError(msg) from None
    return tuple(out)


def _pitch(key: PolygonKey, default: int, i: int) -> int:
    if key.note is None:
        p = default
    elif isinstance(key.note, str):
        p = name_to_midi(key.note)
    else:
        p = int(key.note)
    if not 0 <= p <= 127:
        raise ConfigError(f"key {i}: note {key.note!r} is outside MIDI 0..127")
    return p


def example_polygon_keys() -> tuple[PolygonKey, ...]:
    """The ``polygons`` example (``pipelines/layouts/polygons.toml``): a fan of two rings of seven
    turned trapezoids around (400, 250), a square turned by 25 degrees and an irregular pentagon.

    Vertices are pad coordinates rounded to 0.01 px (the fan's rings share their edges exactly).
    """

    def rounded(v: np.ndarray) -> tuple[tuple[float, float], ...]:
        return tuple((round(float(x), 2), round(float(y), 2)) for x, y in v)

    centre = np.array([400.0, 250.0])
    keys: list[PolygonKey] = []
    for r0, r1 in ((90.0, 150.0), (150.0, 210.0)):
        for a0 in range(160, 20, -20):  # left to right
            th = np.deg2rad([a0, a0 - 20])
            u = np.column_stack([np.cos(th), np.sin(th)])
            v = np.vstack([centre + r0 * u[0], centre + r0 * u[1], centre + r1 * u[1],
                           centre + r1 * u[0]])
            keys.append(PolygonKey(vertices=rounded(v)))
    a = np.deg2rad(25.0)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    square = np.array([[-18.0, -18.0], [18.0, -18.0], [18.0, 18.0], [-18.0, 18.0]]) @ rot.T + (
        330.0, 245.0)
    keys.append(PolygonKey(vertices=rounded(square), note="F#5", tempo=140.0))
    pentagon = ((452.0, 232.0), (490.0, 228.0), (500.0, 250.0), (478.0, 268.0), (455.0, 262.0))
    keys.append(PolygonKey(vertices=pentagon, note=90, tempo=150.0))
    return tuple(keys)


class PolygonsOptions(Options):
    """The polygons' options: ``keys``, one :class:`PolygonKey` per key (required)."""

    what: ClassVar[str] = "layout polygons"
    keys: tuple[PolygonKey, ...] | None = None

    @field_validator("keys", mode="before")
    @classmethod
    def _keys(cls, v: Any) -> Any:
        return None if v is None else polygon_keys(v)

    def to_dict(self) -> dict[str, Any]:
        """The keys' tables (each its vertices, and its note and tempo when given)."""
        return {"name": self.name,
                "keys": None if self.keys is None else [k.to_dict() for k in self.keys]}


@layout("polygons", "explicit key polygons (rotated or irregular) from the TOML",
        PolygonsOptions, default_origin=(0.0, 0.0),
        example_fields=lambda: {"keys": example_polygon_keys()})
def build(cfg: KeyboardConfig) -> LayoutGeometry:
    """The keys' checked outlines, their notes (given or climbing ``scale``) and tempi."""
    keys = cfg.layout.keys
    if not keys:
        raise ConfigError("the polygons layout needs its keys: a [[keyboard.keys]] table per key "
                          "with vertices = [[x, y], ...] (see pipelines/layouts/polygons.toml)")
    if len(keys) > MAX_KEYS:
        raise ConfigError(f"at most {MAX_KEYS} keys, got {len(keys)}")
    climb = scale_pitches(base_midi(cfg), cfg.scale, len(keys))
    polys = [check_polygon(key.vertices, f"key {i}") for i, key in enumerate(keys)]
    pitches = [_pitch(key, int(climb[i]), i) for i, key in enumerate(keys)]
    tempos = [cfg.tempo_base + i * cfg.tempo_col_step if key.tempo is None else key.tempo
              for i, key in enumerate(keys)]
    shapes = KeyShapes(polygons=polys)
    return LayoutGeometry(shapes, np.array(pitches, np.int64), np.array(tempos, float),
                          shapes.bounds)
