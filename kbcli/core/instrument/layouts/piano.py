"""The ``piano`` layout: white keys and narrower black keys in the upper row.

``cols`` white keys of ``key_size`` x ``key_height`` from ``base_note`` (a natural) up; black keys of
``black_width`` x ``black_height`` stand in the upper row between the white keys that have a sharp
between them, so the white keys are L- or T-shaped. Keys are numbered by pitch (chromatic). Tempo:
``tempo_base + i * tempo_col_step`` for the i-th white key (a black key takes its left neighbour's
i) plus ``tempo_row_step`` for black keys.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kbcli.core.config import Count
from kbcli.core.instrument.geometry import KeyShapes
from kbcli.core.instrument.layouts.base import (
    MAX_KEYS,
    KeyboardConfig,
    LayoutGeometry,
    Length,
    base_midi,
    layout,
)
from kbcli.core.instrument.notes import BLACK, NATURAL, midi_to_name
from kbcli.core.options import Options
from kbcli.errors import ConfigError


class PianoOptions(Options):
    """The piano's options: ``cols`` white keys of ``key_size`` x ``key_height`` px, black keys
    of ``black_width`` x ``black_height`` px."""

    what: ClassVar[str] = "layout piano"
    cols: Count = 12
    key_size: Length = 36.0
    key_height: Length = 160.0
    black_width: Length = 20.0
    black_height: Length = 100.0


def _describe(cfg: KeyboardConfig, n_keys: int) -> str:
    o = cfg.layout
    return (f"{o.cols} white keys ({o.key_size:g} x {o.key_height:g} px) and "
            f"{n_keys - o.cols} black keys ({o.black_width:g} x {o.black_height:g} px)")


def _white_pitches(cfg: KeyboardConfig, n: int) -> list[int]:
    """MIDI notes of the ``n`` white keys from ``base_note`` (ConfigError on a black key)."""
    base = base_midi(cfg)
    if base % 12 not in NATURAL:
        raise ConfigError(f"a piano starts on a white key: base_note {cfg.base_note!r} "
                          f"({midi_to_name(base)}) is a black key")
    whites = [base]
    while len(whites) < n:
        p = whites[-1] + 1
        whites.append(p + 1 if p % 12 in BLACK else p)
    return whites


def _white_outline(i: int, w: float, h: float, bw: float, bh: float, left: bool,
                   right: bool) -> np.ndarray:
    """White key ``i``: a rectangle notched at the top by the black keys beside it."""
    x0, x1 = i * w, (i + 1) * w
    v = [(x0, 0.0), (x1, 0.0)]
    v += [(x1, h - bh), (x1 - bw / 2, h - bh), (x1 - bw / 2, h)] if right else [(x1, h)]
    v += [(x0 + bw / 2, h), (x0 + bw / 2, h - bh), (x0, h - bh)] if left else [(x0, h)]
    return np.array(v)


@layout("piano", "white keys and narrower black keys in the upper row", PianoOptions,
        uses_scale=False, describe=_describe)
def build(cfg: KeyboardConfig) -> LayoutGeometry:
    """The white and black keys, numbered by pitch, and their tempi."""
    o = cfg.layout
    n = o.cols
    w, h = o.key_size, o.key_height
    bw, bh = o.black_width, o.black_height
    if bw >= w:
        raise ConfigError(f"black_width ({bw:g}) must be below key_size ({w:g}), the white keys' "
                          "width: black keys would overlap")
    if bh >= h:
        raise ConfigError(f"black_height ({bh:g}) must be below key_height ({h:g})")
    whites = _white_pitches(cfg, n)
    # a black key between white keys i and i + 1 when a sharp lies between them
    black_after = [i for i in range(n - 1) if whites[i + 1] - whites[i] == 2]
    if n + len(black_after) > MAX_KEYS:
        raise ConfigError(f"a piano of {n} white keys has more than {MAX_KEYS} keys")
    keys: list[tuple[int, np.ndarray, float]] = []
    left, right = {i + 1 for i in black_after}, set(black_after)
    for i, p in enumerate(whites):
        keys.append((p, _white_outline(i, w, h, bw, bh, i in left, i in right),
                     cfg.tempo_base + i * cfg.tempo_col_step))
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
