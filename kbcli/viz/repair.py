"""The lifelong section of ``kbcli bench repair`` (issue 42): a weak model carried from move to
move, repaired by each adaptation's touches."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np

from kbcli.viz.common import save

#: The three methods of the lifelong section: (label, Episode attribute prefix, line style).
METHODS = (("repair, model carried", "repair", "o-"),
           ("repair, model as learned", "learned", "^:"),
           ("plain infogain, model as learned", "plain", "s--"))


def plot_lifelong(start_error: float, episodes: list, path: str | os.PathLike, *,
                  touches: int, title: str = "") -> None:
    """Three panels over the moves: the carried model's boundary error (px, its learned model's
    before the first move); each method's final error (px); and the touches each needed to stay
    under 1 px (``touches + 1``: never). The methods: the repaired belief with the carried model,
    beside the repaired belief and plain infogain with the model as learned."""
    n = np.arange(len(episodes) + 1)
    berr = [start_error] + [e.boundary_error for e in episodes]
    ep = np.arange(1, len(episodes) + 1)
    fig, (a, f, b) = plt.subplots(1, 3, figsize=(13.5, 3.8))
    a.plot(n, berr, "o-", color="#2a6f97")
    a.set_xticks(n)
    a.set_xlabel("moves adapted to (0: as learned)")
    a.set_ylabel("boundary error of the carried model, px")
    a.set_ylim(0, max(berr) * 1.15)
    a.grid(alpha=0.3)
    finals = []
    for label, key, style in METHODS:
        finals += [getattr(e, f"{key}_final") for e in episodes]
        f.plot(ep, [getattr(e, f"{key}_final") for e in episodes], style, label=label)
        b.plot(ep, [getattr(e, f"{key}_stay") for e in episodes], style, label=label)
    f.axhline(1.0, color="0.6", lw=0.8)
    f.set_xticks(ep)
    f.set_xlabel("move")
    f.set_ylabel(f"final error after {touches} touches, px")
    f.set_ylim(0, max(1.2, max(finals) * 1.15))
    f.grid(alpha=0.3)
    b.axhline(touches + 0.5, color="0.6", lw=0.8)
    b.text(ep[-1], touches + 1.8, f"above the line: never (> {touches})", fontsize=8,
           color="0.4", ha="right", va="bottom")  # clear of the markers drawn at touches + 1
    b.set_xticks(ep)
    b.set_xlabel("move")
    b.set_ylabel("touches to stay under 1 px")
    b.set_ylim(0, touches + 5)
    b.grid(alpha=0.3)
    handles, labels = f.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(METHODS), fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.07, 1, 1))  # the legend below the panels
    save(fig, path)
