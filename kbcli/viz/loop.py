"""Figure of a closed-loop session: results over time, detector score, adaptation touches."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np

from kbcli.core.keyboard import Keyboard
from kbcli.viz.common import draw_keyboard, save


def plot_loop(steps: dict, attrs: dict, kb: Keyboard, path: str | os.PathLike, window: int = 20) -> None:
    """Top: success (running mean over ``window`` play touches), move, detection and adaptation.
    Middle: detector score (log). Right: the adaptation touches on the reference keyboard."""
    phase = steps["phase"]
    result = steps["result"].astype(float)
    t = np.arange(len(phase))
    play = phase == 0
    fig = plt.figure(figsize=(13, 6))
    gs = fig.add_gridspec(2, 2, width_ratios=(2.2, 1), height_ratios=(1.3, 1))
    ax = fig.add_subplot(gs[0, 0])
    ok = 1.0 - result[play]
    run = np.convolve(ok, np.ones(window) / window, mode="full")[: len(ok)]
    run[: window - 1] = np.cumsum(ok)[: window - 1] / np.arange(1, min(window, len(ok) + 1))[: window - 1]
    ax.plot(t[play], run, lw=1.2, label=f"success (mean of last {window} notes)")
    ax.scatter(t[play][ok == 0], np.zeros((ok == 0).sum()) - 0.04, marker="|", color="crimson",
               s=30, label="NO_MATCH")
    adapt_t = t[phase == 1]
    if len(adapt_t):
        ax.axvspan(adapt_t.min() - 0.5, adapt_t.max() + 0.5, color="orange", alpha=0.3,
                   label=f"adaptation ({len(adapt_t)} touches)")
    ax.axvline(attrs["perturbed_at"], color="k", ls="--", lw=1, label="keyboard moved")
    if attrs.get("detected_at") is not None:
        ax.axvline(attrs["detected_at"], color="crimson", lw=1,
                   label=f"detector fired (+{attrs['detection_delay']})")
    ax.set_ylim(-0.1, 1.05)
    ax.set_ylabel("success")

    def pct(v):
        return "n/a" if v is None else f"{100 * v:.0f}%"

    ax.set_title(f"success before {pct(attrs['success_before'])}, after the move "
                 f"{pct(attrs['success_after_perturbation'])}, after adaptation "
                 f"{pct(attrs['success_after_adaptation'])}", fontsize=10)
    ax.legend(fontsize=7, loc="lower left")
    ax2 = fig.add_subplot(gs[1, 0], sharex=ax)
    score = steps["score"]
    ax2.semilogy(t[play], np.clip(score[play], 1e-12, 1), lw=1)
    ax2.axvline(attrs["perturbed_at"], color="k", ls="--", lw=1)
    ax2.set_ylabel("detector score")
    ax2.set_xlabel("touch")
    ax3 = fig.add_subplot(gs[:, 1])
    draw_keyboard(ax3, kb, labels=False, alpha=0.35)
    truth = attrs["truth"]
    offset = (truth.get("dx", 0.0), truth.get("dy", 0.0))
    draw_keyboard(ax3, kb, labels=False, fill=False, edge="crimson", offset=offset)
    if len(adapt_t):
        pts = steps["landed"][phase == 1]
        ax3.plot(pts[:, 0], pts[:, 1], "k.-", lw=0.6, ms=5)
        for i, (x, y) in enumerate(pts, 1):
            ax3.annotate(str(i), (x, y), fontsize=7, xytext=(2, 2), textcoords="offset points")
    x0, y0, x1, y1 = kb.area
    ax3.set_xlim(x0, x1)
    ax3.set_ylim(y0, y1)
    ax3.set_aspect("equal")
    ax3.set_title("adaptation touches; red: moved keyboard", fontsize=10)
    save(fig, path)
