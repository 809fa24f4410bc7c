"""The lifelong section of ``kbcli bench repair`` (issue 42): a weak model carried from move to
move, repaired by each adaptation's touches."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np

from kbcli.viz.common import save


def plot_lifelong(start_error: float, episodes: list, path: str | os.PathLike, *,
                  touches: int, title: str = "") -> None:
    """Two panels over the moves: the carried model's boundary error (px, its learned model's
    before the first move), and the touches each method needed to stay under 1 px (``touches +
    1``: never), the repaired belief with the carried model beside the repaired belief and plain
    infogain with the model as learned."""
    n = np.arange(len(episodes) + 1)
    berr = [start_error] + [e.boundary_error for e in episodes]
    ep = np.arange(1, len(episodes) + 1)
    fig, (a, b) = plt.subplots(1, 2, figsize=(9.5, 3.6))
    a.plot(n, berr, "o-", color="#2a6f97")
    a.set_xticks(n)
    a.set_xlabel("moves adapted to (0: as learned)")
    a.set_ylabel("boundary error of the carried model, px")
    a.set_ylim(0, max(berr) * 1.15)
    a.grid(alpha=0.3)
    for label, key, style in (("repair, model carried", "repair_stay", "o-"),
                              ("repair, model as learned", "learned_stay", "^:"),
                              ("plain infogain, model as learned", "plain_stay", "s--")):
        b.plot(ep, [getattr(e, key) for e in episodes], style, label=label)
    b.axhline(touches + 0.5, color="0.6", lw=0.8)
    b.text(ep[-1], touches + 1.8, f"above the line: never (> {touches})", fontsize=8,
           color="0.4", ha="right", va="bottom")  # clear of the markers drawn at touches + 1
    b.set_xticks(ep)
    b.set_xlabel("move")
    b.set_ylabel("touches to stay under 1 px")
    b.set_ylim(0, touches + 5)
    b.grid(alpha=0.3)
    b.legend(fontsize=8, loc="lower left")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save(fig, path)
