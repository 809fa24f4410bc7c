"""Shared drawing helpers."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
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


def draw_keyboard(ax, kb: Keyboard, *, labels: bool = True, alpha: float = 1.0,
                  edge: str = "black", fill: bool = True, offset=(0.0, 0.0)) -> None:
    """Draw the keys at the reference pose (shifted by ``offset``) on ``ax``."""
    cmap = plt.get_cmap("tab20")
    s = kb.config.key_size
    for k, (cx, cy) in enumerate(kb.key_centres()):
        x, y = cx - s / 2 + offset[0], cy - s / 2 + offset[1]
        ax.add_patch(Rectangle((x, y), s, s, facecolor=cmap(k % 20) if fill else "none",
                               edgecolor=edge, lw=0.8, alpha=alpha))
        if labels:
            pitch, tempo = kb.features[k]
            ax.text(x + s / 2, y + s / 2, f"{kb.names[k]}\n{tempo:.0f} bpm", ha="center",
                    va="center", fontsize=6.5)
