"""Shared drawing helpers."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from kbcli.core.keyboard import Keyboard
from kbcli.io.atomic import atomic_path


def save(fig: Figure, path: str | os.PathLike, dpi: int = 110) -> None:
    """Save atomically (temporary file, then rename) and close the figure."""
    try:
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight", metadata={"Software": None})
    finally:
        plt.close(fig)


def draw_keyboard(ax, kb: Keyboard, *, labels: bool = True, alpha: float = 1.0,
                  edge: str = "black", fill: bool = True, offset=(0.0, 0.0)) -> None:
    """Draw the keys at the reference pose (shifted by ``offset``) on ``ax``, whatever the layout
    (each key's outline polygon; pads as circles)."""
    cmap = plt.get_cmap("tab20")
    off = np.asarray(offset, float)
    discs = kb.shapes.discs
    centres = kb.key_centres() + off
    box = kb.shapes.boxes
    small = float(np.median(np.minimum(box[:, 2] - box[:, 0], box[:, 3] - box[:, 1])))
    fontsize = float(np.clip(small / 7.5, 4.5, 6.5))
    for k, poly in enumerate(kb.key_outlines()):
        face = cmap(k % 20) if fill else "none"
        if discs is not None:
            patch = Circle(discs[k, :2] + off, discs[k, 2], facecolor=face, edgecolor=edge, lw=0.8,
                           alpha=alpha)
        else:
            patch = Polygon(poly + off, closed=True, facecolor=face, edgecolor=edge, lw=0.8,
                            alpha=alpha)
        ax.add_patch(patch)
        if labels:
            pitch, tempo = kb.features[k]
            ax.text(*centres[k], f"{kb.names[k]}\n{tempo:.0f}", ha="center", va="center",
                    fontsize=fontsize)
