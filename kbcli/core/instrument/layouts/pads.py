"""The ``pads`` layout: round pads with silence between them (curved boundaries).

``rows`` x ``cols`` discs of radius ``pad_radius`` centred in cells of ``key_size``; pitches and
tempi as the grid's. The keyboard's bounds are its cells (as the grid's).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kbcli.core.instrument.geometry import MIN_AREA, KeyShapes
from kbcli.core.instrument.layouts.base import (
    KeyboardConfig,
    LayoutGeometry,
    Length,
    RowsCols,
    layout,
    rowcol_geometry,
    rows_cols,
)
from kbcli.errors import ConfigError


def _describe(cfg: KeyboardConfig, n_keys: int) -> str:
    o = cfg.layout
    return f"{o.rows} x {o.cols} round pads of radius {o.pad_radius:g} px"


class PadsOptions(RowsCols):
    """The pads' options: ``rows`` x ``cols`` discs of radius ``pad_radius`` px in cells of
    ``key_size`` px."""

    what: ClassVar[str] = "layout pads"
    pad_radius: Length = 20.0


@layout("pads", "round pads with silence between them", PadsOptions, describe=_describe)
def build(cfg: KeyboardConfig) -> LayoutGeometry:
    """The pads (discs), their pitches and tempi, and their cells' bounds."""
    rows, cols = rows_cols(cfg)
    s, r = cfg.layout.key_size, cfg.layout.pad_radius
    if np.pi * r * r < MIN_AREA:
        raise ConfigError(f"pad_radius ({r:g}) must be at least {np.ceil(100 * np.sqrt(MIN_AREA / np.pi)) / 100:g} px: "
                          f"a pad needs an area of at least {MIN_AREA:g} px^2")
    if 2 * r > s:
        raise ConfigError(f"pad_radius ({r:g}) must be at most half of key_size ({s:g}), the "
                          "distance between pad centres: pads would overlap")
    k = np.arange(rows * cols)
    discs = np.column_stack([(k % cols + 0.5) * s, (k // cols + 0.5) * s, np.full(len(k), r)])
    return rowcol_geometry(cfg, KeyShapes(discs=discs), (0.0, 0.0, cols * s, rows * s))
