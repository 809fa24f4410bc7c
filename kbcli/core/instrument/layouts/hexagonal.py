"""The ``hex`` layout: a hexagonal isomorphic keyboard (Wicki-Hayden tuning).

``rows`` rows of ``cols`` pointy-top hexagons, ``key_size`` across the flats, odd rows shifted right
by half a key. One key right is a whole tone up, up-right a fifth, up-left a fourth (``pitch = base +
2 (c - r // 2) + 7 r``); the same note can sit on several keys, told apart by their tempo (as the
grid's).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from kbcli.core.instrument.geometry import KeyShapes
from kbcli.core.instrument.layouts.base import (
    KeyboardConfig,
    LayoutGeometry,
    RowsCols,
    base_midi,
    layout,
    rowcol_geometry,
    rows_cols,
)


def _describe(cfg: KeyboardConfig, n_keys: int) -> str:
    o = cfg.layout
    return f"{o.rows} x {o.cols} hexagonal keys {o.key_size:g} px across"


class HexOptions(RowsCols):
    """The hex layout's options: ``rows`` rows of ``cols`` hexagons ``key_size`` px across."""

    what: ClassVar[str] = "layout hex"


@layout("hex", "hexagonal isomorphic keys (Wicki-Hayden)", HexOptions, uses_scale=False,
        describe=_describe)
def build(cfg: KeyboardConfig) -> LayoutGeometry:
    """The hexagons, their Wicki-Hayden pitches and their tempi."""
    rows, cols = rows_cols(cfg)
    w = cfg.layout.key_size
    rad = w / math.sqrt(3)  # circumradius of a hexagon w across the flats
    k = np.arange(rows * cols)
    r, c = k // cols, k % cols
    # Vertices on an exact lattice of (w / 2, rad / 2) steps, counterclockwise from 30 degrees: a
    # vertex two keys share is the same float in both (the half-open rule on shared edges).
    ix = 1 + 2 * c + r % 2  # centre in half-widths
    iy = 2 + 3 * r  # centre in half-radii
    dx, dy = np.array([1, 0, -1, -1, 0, 1]), np.array([1, 2, 1, -1, -2, -1])
    polys = [np.column_stack([(x + dx) * (w / 2), (y + dy) * (rad / 2)])
             for x, y in zip(ix, iy, strict=True)]
    pitches = base_midi(cfg) + 2 * (c - r // 2) + 7 * r
    shapes = KeyShapes(polygons=polys)
    return rowcol_geometry(cfg, shapes, shapes.bounds, pitches.astype(np.int64))
