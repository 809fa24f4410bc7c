"""Figure of the instrument, whatever its layout: keys labelled with note and tempo (bpm), the
working area dashed."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt

from kbcli.core.instrument.keyboard import Keyboard
from kbcli.viz.common import draw_layout, fit_title, save


def plot_keyboard(kb: Keyboard, path: str | os.PathLike) -> None:
    fig, ax = plt.subplots(figsize=(9, 5.2))
    draw_layout(ax, kb, 10)
    ax.set_xlabel("pad x (px)")
    ax.set_ylabel("pad y (px)")
    fit_title(ax, f"{kb.layout} layout: {kb.describe()}\nlabels: note, tempo (bpm); "
                  f"dashed: working area (margin {kb.config.margin:g} px); outside the keys is "
                  "silence")
    save(fig, path)
