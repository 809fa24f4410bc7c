"""The ``grid`` layout: ``rows`` x ``cols`` square keys of side ``key_size`` (the paper's Fig. 2).

Pitches climb ``scale`` row by row from ``base_note``; the tempo of key (r, c) is ``tempo_base + c *
tempo_col_step + r * tempo_row_step``. Point location is arithmetic (:class:`GridShapes`).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kbcli.core.instrument.geometry import KeyShapes
from kbcli.core.instrument.layouts.base import (
    KeyboardConfig,
    LayoutGeometry,
    RowsCols,
    layout,
    rowcol_geometry,
    rows_cols,
)


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

    def shifted(self, dx: float, dy: float) -> GridShapes:
        return GridShapes(self.rows, self.cols, self.size, self.origin + (dx, dy))

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


def _describe(cfg: KeyboardConfig, n_keys: int) -> str:
    o = cfg.layout
    return f"{o.rows} x {o.cols} keys of {o.key_size:g} px"


class GridOptions(RowsCols):
    """The grid's options: ``rows`` x ``cols`` square keys of side ``key_size`` px."""

    what: ClassVar[str] = "layout grid"


@layout("grid", "rows x cols square keys (the paper's keyboard)", GridOptions,
        default_origin=(200.0, 250.0), describe=_describe)
def build(cfg: KeyboardConfig) -> LayoutGeometry:
    """The grid's keys, pitches and tempi."""
    rows, cols = rows_cols(cfg)
    shapes = GridShapes(rows, cols, cfg.layout.key_size)
    return rowcol_geometry(cfg, shapes, shapes.bounds)
