"""Figure of the instrument: keys labelled with note and tempo, the working area dashed."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
from matplotlib.patches import Rectangle

from kbcli.core.keyboard import Keyboard
from kbcli.viz.common import draw_keyboard, save


def plot_keyboard(kb: Keyboard, path: str | os.PathLike) -> None:
    fig, ax = plt.subplots(figsize=(9, 5))
    draw_keyboard(ax, kb)
    x0, y0, x1, y1 = kb.area
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", ec="grey", lw=1))
    ax.set_xlim(x0 - 10, x1 + 10)
    ax.set_ylim(y0 - 10, y1 + 10)
    ax.set_aspect("equal")
    ax.set_xlabel("pad x (px)")
    ax.set_ylabel("pad y (px)")
    c = kb.config
    ax.set_title(f"{c.rows} x {c.cols} keys of {c.key_size:g} px; dashed: working area "
                 f"(margin {c.margin:g} px); outside the keys is silence")
    save(fig, path)
