"""What every layout shares: the :data:`LAYOUTS` registry, the :class:`Layout` entry, the
:class:`LayoutGeometry` a builder returns and the helpers the built-in layouts use."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kbcli.core.instrument.geometry import KeyShapes
from kbcli.core.instrument.notes import name_to_midi, scale_pitches
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: The keyboard config a layout builds from (:class:`kbcli.core.instrument.keyboard.KeyboardConfig`; not
#: imported here: the keyboard imports its layouts).
KeyboardConfig = Any
MAX_KEYS = 256
#: Where every layout's default origin puts the keyboard's centre (the default grid's centre).
DEFAULT_CENTRE = (400.0, 350.0)
#: Config fields that belong to some layouts only (the rest apply to every layout).
LAYOUT_FIELDS = ("rows", "cols", "key_size", "key_height", "black_width", "black_height",
                 "pad_radius", "keys")


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
    """A registered layout: the config fields it uses (with defaults) and its builder.

    The builder gets a validated config (whole ``rows``/``cols`` >= 1, positive sizes: the
    :class:`~kbcli.core.instrument.keyboard.KeyboardConfig` field constraints) and checks how its own fields
    relate (a pad's radius against the distance between pads, ...).

    ``build(config) -> LayoutGeometry`` places the keys in the keyboard's own frame (lower-left at
    (0, 0)) and raises :class:`~kbcli.errors.ConfigError` naming the key or option at fault.
    """

    name: str
    summary: str
    defaults: dict[str, Any]
    build: Callable[[KeyboardConfig], LayoutGeometry]
    uses_scale: bool = True
    default_origin: tuple[float, float] | None = None  # None: centre on DEFAULT_CENTRE
    fields: tuple[str, ...] = field(default=())
    #: ``(config, n_keys) -> str``: the keys in words, for :meth:`Keyboard.describe`.
    describe: Callable[[KeyboardConfig, int], str] = field(default=lambda cfg, n: f"{n} keys")
    #: ``() -> dict``: config fields of the layout's example keyboard (its polygons' keys).
    example_fields: Callable[[], dict[str, Any]] = field(default=dict)


#: The layouts by name (``kbcli keyboard --layout NAME``).
LAYOUTS: Registry[Layout] = Registry("layout")


def layout(name: str, summary: str, defaults: dict[str, Any], **kw: Any):
    """Decorator registering a builder as layout ``name`` in :data:`LAYOUTS`."""

    def deco(fn: Callable[[KeyboardConfig], LayoutGeometry]):
        LAYOUTS.register(name, Layout(name, summary, defaults, fn, fields=tuple(defaults), **kw),
                         summary=summary)
        return fn

    return deco


def rows_cols(cfg: KeyboardConfig) -> tuple[int, int]:
    """The config's ``rows`` and ``cols`` (ConfigError when ``rows * cols`` exceeds
    :data:`MAX_KEYS`)."""
    rows, cols = cfg.rows, cfg.cols
    if rows * cols > MAX_KEYS:
        raise ConfigError(f"rows x cols must be at most {MAX_KEYS} keys, got {rows * cols}")
    return rows, cols


def rowcol_geometry(cfg: KeyboardConfig, shapes: KeyShapes,
                    bounds: tuple[float, float, float, float],
                    pitches: np.ndarray | None = None) -> LayoutGeometry:
    """The geometry of ``rows`` x ``cols`` keys numbered row by row: their tempi by row and column
    (:func:`rowcol_tempo`) and, unless given, pitches climbing the config's ``scale`` from its
    ``base_note``."""
    rows, cols = cfg.rows, cfg.cols
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
