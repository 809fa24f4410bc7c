"""Shared drawing helpers: saving in the format of the suffix, key colours, the keyboard."""

from __future__ import annotations

import functools
import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import hsv_to_rgb
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from kbcli.core.keyboard import Keyboard
from kbcli.io.atomic import atomic_path
from kbcli.io.paths import figure_format


def save(fig: Figure, path: str | os.PathLike, dpi: int = 110) -> None:
    """Save atomically (temporary file, then rename) and close the figure.

    The format is the suffix of ``path``: ``.png``, ``.pdf`` or ``.svg``
    (:func:`kbcli.io.paths.figure_format`); the files carry no creation date, so the same figure
    gives the same bytes.
    """
    fmt = figure_format(path)
    meta = {"png": {"Software": None}, "pdf": {"Creator": None, "Producer": None,
                                                "CreationDate": None},
            "svg": {"Date": None, "Creator": None}}[fmt]
    try:
        with atomic_path(path, suffix="." + fmt) as tmp:
            fig.savefig(tmp, format=fmt, dpi=dpi, bbox_inches="tight", metadata=meta)
    finally:
        plt.close(fig)


#: Keys up to this many get pairwise distinct colours (more keys reuse them in order).
DISTINCT_KEYS = 48


def _lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 1] (..., 3) -> CIELAB (D65), for colour distances."""
    c = np.where(rgb > 0.04045, ((rgb + 0.055) / 1.055) ** 2.4, rgb / 12.92)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = c @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16 / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]),
                     200 * (f[..., 1] - f[..., 2])], axis=-1)


@functools.lru_cache(maxsize=1)
def _palette() -> np.ndarray:
    """:data:`DISTINCT_KEYS` colours chosen greedily (each the candidate farthest, in CIELAB, from
    those already chosen: Glasbey's method) among light and mid tones, so black labels stay
    readable and neighbouring keys differ."""
    h, sat, val = np.meshgrid(np.arange(36) / 36, [0.3, 0.55, 0.8], [0.7, 0.85, 1.0],
                              indexing="ij")
    rgb = hsv_to_rgb(np.stack([h, sat, val], -1).reshape(-1, 3))
    lab = _lab(rgb)
    keep = (lab[:, 0] >= 52) & (lab[:, 0] <= 88)  # black text readable; never near-white silence
    rgb, lab = rgb[keep], lab[keep]
    chosen = [int(np.argmin(np.abs(lab[:, 0] - 70) + np.abs(lab[:, 1]) + np.abs(lab[:, 2] - 40)))]
    dist = np.linalg.norm(lab - lab[chosen[0]], axis=1)
    while len(chosen) < DISTINCT_KEYS:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(lab - lab[nxt], axis=1))
    return np.hstack([rgb[chosen], np.ones((len(chosen), 1))])


def key_colours(n: int) -> np.ndarray:
    """(n, 4) RGBA colours of keys 0..n-1: pairwise distinct up to :data:`DISTINCT_KEYS` keys."""
    pal = _palette()
    return pal[np.arange(n) % len(pal)]


def draw_keyboard(ax, kb: Keyboard, *, labels: bool = True, alpha: float = 1.0,
                  edge: str = "black", fill: bool = True, offset=(0.0, 0.0),
                  fontsize: float = 6.5) -> None:
    """Draw the keys at the reference pose (shifted by ``offset``) on ``ax``."""
    colours = key_colours(kb.n_keys)
    s = kb.config.key_size
    for k, (cx, cy) in enumerate(kb.key_centres()):
        x, y = cx - s / 2 + offset[0], cy - s / 2 + offset[1]
        ax.add_patch(Rectangle((x, y), s, s, facecolor=colours[k] if fill else "none",
                               edgecolor=edge, lw=0.8, alpha=alpha))
        if labels:
            pitch, tempo = kb.features[k]
            ax.text(x + s / 2, y + s / 2, f"{kb.names[k]}\n{tempo:.0f} bpm", ha="center",
                    va="center", fontsize=fontsize)
