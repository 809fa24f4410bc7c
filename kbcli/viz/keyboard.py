"""Figure of the instrument, whatever its layout: keys labelled with note and tempo (bpm), the
working area dashed."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
from matplotlib.patches import Rectangle

from kbcli.core.instrument.keyboard import Keyboard
from kbcli.viz.common import draw_keyboard, fit_title, save


def plot_keyboard(kb: Keyboard, path: str | os.PathLike) -> None:
    x0, y0, x1, y1 = kb.area
    fig, ax = plt.subplots(figsize=(9, 5.2))
    ax.set_xlim(x0 - 10, x1 + 10)  # limits and aspect first: the labels are sized to the keys
    ax.set_ylim(y0 - 10, y1 + 10)
    ax.set_aspect("equal")
    draw_keyboard(ax, kb)
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", ec="grey", lw=1))
    ax.set_xlabel("pad x (px)")
    ax.set_ylabel("pad y (px)")
    fit_title(ax, f"{kb.layout} layout: {kb.describe()}\nlabels: note, tempo (bpm); "
                  f"dashed: working area (margin {kb.config.margin:g} px); outside the keys is "
                  "silence")
    save(fig, path)
