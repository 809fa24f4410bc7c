"""What every layout shares: the :data:`LAYOUTS` registry, the :class:`Layout` entry, the
:class:`LayoutGeometry` a builder returns and the helpers the built-in layouts use."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kbcli.core.config import Count, Number, between
from kbcli.core.instrument.geometry import MAX_COORD, KeyShapes
from kbcli.core.instrument.notes import name_to_midi, scale_pitches
from kbcli.core.options import Options
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: The keyboard config a layout builds from (:class:`kbcli.core.instrument.keyboard.KeyboardConfig`; not
#: imported here: the keyboard imports its layouts).
KeyboardConfig = Any
MAX_KEYS = 256
#: Where every layout's default origin puts the keyboard's centre (the default grid's centre).
DEFAULT_CENTRE = (400.0, 350.0)
#: A length of a layout's options, px: finite, in (0, MAX_COORD].
Length = between(Number, 0, MAX_COORD, low_open=True)


class RowsCols(Options):
    """Options of a layout of ``rows`` x ``cols`` keys of ``key_size`` px."""

    rows: Count = 4
    cols: Count = 8
    key_size: Length = 50.0


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
        x0, y0, x1, y1 = self.bounds
        return LayoutGeometry(self.shapes.shifted(dx, dy), self.pitches, self.tempos,
                              (x0 + dx, y0 + dy, x1 + dx, y1 + dy))


@dataclass(frozen=True)
class Layout:
    """A registered layout: its own options (an :class:`~kbcli.core.options.Options` model, the
    config's ``layout`` field) and its builder.

    The builder gets a validated config (its options checked by their model: whole ``rows`` and
    ``cols`` >= 1, positive sizes) and checks how its own options relate (a pad's radius against
    the distance between pads, ...).

    ``build(config) -> LayoutGeometry`` places the keys in the keyboard's own frame (lower-left at
    (0, 0)) and raises :class:`~kbcli.errors.ConfigError` naming the key or option at fault; it
    reads its options as ``config.layout.NAME`` and the keyboard's own (``base_note``, the tempi)
    as ``config.NAME``.
    """

    name: str
    summary: str
    build: Callable[[KeyboardConfig], LayoutGeometry]
    options: type[Options] = Options
    uses_scale: bool = True
    default_origin: tuple[float, float] | None = None  # None: centre on DEFAULT_CENTRE
    #: ``(config, n_keys) -> str``: the keys in words, for :meth:`Keyboard.describe`.
    describe: Callable[[KeyboardConfig, int], str] = field(default=lambda cfg, n: f"{n} keys")
    #: ``() -> dict``: config fields of the layout's example keyboard (its polygons' keys).
    example_fields: Callable[[], dict[str, Any]] = field(default=dict)


#: The layouts by name (``kbcli keyboard --layout NAME``).
LAYOUTS: Registry[Layout] = Registry("layout")


def layout(name: str, summary: str, options: type[Options] = Options, **kw: Any):
    """Decorator registering a builder as layout ``name`` in :data:`LAYOUTS`, with its options
    model (``traits={"options": options}``)."""

    def deco(fn: Callable[[KeyboardConfig], LayoutGeometry]):
        LAYOUTS.register(name, Layout(name, summary, fn, options, **kw), summary=summary,
                         traits={"options": options})
        return fn

    return deco


def rows_cols(cfg: KeyboardConfig) -> tuple[int, int]:
    """The config's ``rows`` and ``cols`` (ConfigError when ``rows * cols`` exceeds
    :data:`MAX_KEYS`)."""
    rows, cols = cfg.layout.rows, cfg.layout.cols
    if rows * cols > MAX_KEYS:
        raise ConfigError(f"rows x cols must be at most {MAX_KEYS} keys, got {rows * cols}")
    return rows, cols


def rowcol_geometry(cfg: KeyboardConfig, shapes: KeyShapes,
                    bounds: tuple[float, float, float, float],
                    pitches: np.ndarray | None = None) -> LayoutGeometry:
    """The geometry of ``rows`` x ``cols`` keys numbered row by row: their tempi by row and column
    (:func:`rowcol_tempo`) and, unless given, pitches climbing the config's ``scale`` from its
    ``base_note``."""
    rows, cols = cfg.layout.rows, cfg.layout.cols
    if pitches is None:
        pitches = scale_pitches(base_midi(cfg), cfg.scale, rows * cols)
    return LayoutGeometry(shapes, pitches, rowcol_tempo(cfg, rows, cols), bounds)


def rowcol_tempo(cfg: KeyboardConfig, rows: int, cols: int) -> np.ndarray:
    """(rows * cols,) tempo of key (r, c): ``tempo_base + c * col_step + r * row_step``."""
    k = np.arange(rows * cols)
    return (cfg.tempo_base + (k % cols) * cfg.tempo_col_step
            + (k // cols) * cfg.tempo_row_step).astype(float)


def base_midi(cfg: KeyboardConfig) -> int:
    """MIDI number of the config's ``base_note``."""
    return name_to_midi(cfg.base_note)
