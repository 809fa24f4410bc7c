"""Figure of one adaptation run: the posterior's evolution (the paper's Fig. 5) and the error and
entropy curves (Figs. 6, 7 for a single experiment).

Top row: the translation posterior (log scale over 30 nats, the angle summed out for the rigid
family) at the stored snapshot steps, the true displacement marked with a cross and the estimate
(posterior mean) with a circle; the last panel zooms in to +-4 px around the estimate.
Bottom: the estimation error (px, log scale) and the entropy (nats) against the observations. A
session with a robot in another process (``kbcli serve``) has no ground truth: no cross, and the
error panel shows the robot's own confidence instead (the posterior mass near the estimate).
"""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import MaxNLocator

from kbcli.stages.artifact import Artifact
from kbcli.viz.common import save

MAX_PANELS = 6
DYNAMIC_RANGE = 30.0  # nats of log-posterior shown
ZOOM = 4.0  # px, half-width of the last panel


def plot_adapt(run: Artifact, path: str | os.PathLike) -> None:
    """Draw a ``run`` artifact to a PNG."""
    d = run.data
    steps = np.asarray(d.get("snapshot_steps", np.zeros(0, int)))
    snaps = d.get("snapshots")
    errors = np.asarray(d["errors"], float)
    entropy = np.asarray(d["entropy"], float)
    truth = run.attrs.get("truth") or {}
    tx, ty = truth.get("dx", np.nan), truth.get("dy", np.nan)
    known = bool(truth) and bool(np.isfinite(errors).any())
    means = np.asarray(d["means"], float)
    pick = np.arange(len(steps))
    if len(pick) > MAX_PANELS:
        pick = np.unique(np.rint(np.linspace(0, len(steps) - 1, MAX_PANELS)).astype(int))
    n = max(len(pick), 1)
    fig = plt.figure(figsize=(2.6 * n + 0.6, 6.4))
    gs = fig.add_gridspec(2, n, height_ratios=[1.15, 1.0])
    dx, dy = np.asarray(d["dx"]), np.asarray(d["dy"])
    extent = (dx[0], dx[-1], dy[0], dy[-1])
    for i, j in enumerate(pick):
        ax = fig.add_subplot(gs[0, i])
        lp = np.asarray(snaps[j], float)
        top = float(np.max(lp))
        ax.imshow(lp, origin="lower", extent=extent, cmap="magma", aspect="equal",
                  vmin=top - DYNAMIC_RANGE, vmax=top, interpolation="nearest")
        if known:
            ax.plot([tx], [ty], "x", color="cyan", ms=9, mew=2, label="truth")
        t = int(steps[j])
        if t >= 1:
            ax.plot([means[t - 1, -2]], [means[t - 1, -1]], "o", mfc="none", mec="lime", ms=9,
                    mew=1.5, label="estimate")
        zoom = i == len(pick) - 1 and t >= 1 and len(pick) > 1
        if zoom:  # the last panel zooms in on the estimate
            cx, cy = means[t - 1, -2], means[t - 1, -1]
            ax.set_xlim(cx - ZOOM, cx + ZOOM)
            ax.set_ylim(cy - ZOOM, cy + ZOOM)
        ax.set_title(f"t = {t}" + (" (prior)" if t == 0 else "")
                     + (f" (zoom +-{ZOOM:g} px)" if zoom else ""), fontsize=9)
        ax.set_xlabel("dx (px)", fontsize=8)
        if i == 0:
            ax.set_ylabel("dy (px)", fontsize=8)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(loc="lower left", fontsize=7, framealpha=0.6)
        ax.tick_params(labelsize=7)
    t = np.arange(1, len(errors) + 1)
    half = max(n // 2, 1)
    ax = fig.add_subplot(gs[1, :half])
    if known:
        ax.semilogy(t, np.maximum(errors, 1e-3), "-o", ms=3, label="translation error")
        ang = np.asarray(d.get("angle_errors", np.zeros_like(errors)), float)
        if run.attrs.get("family") == "rigid":
            ax.semilogy(t, np.maximum(ang, 1e-3), "-s", ms=3, label="angle error (deg)")
        ax.axhline(1.0, color="0.5", ls="--", lw=0.8)
        ax.set_ylabel("error (px)")
    else:  # a real robot: no ground truth, show the robot's own confidence
        ax.plot(t, np.asarray(d.get("mass", np.full_like(errors, np.nan)), float), "-o", ms=3,
                color="tab:green", label="posterior mass near the estimate")
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("mass within the stop radius")
        ax.set_title("ground truth unknown (external robot): no error", fontsize=8)
    ax.set_xlabel("observations")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax2 = fig.add_subplot(gs[1, half:] if n > 1 else gs[1, :])
    if n == 1:
        ax2 = ax.twinx()
    ax2.plot(t, entropy, "-", color="tab:purple", label="entropy")
    ax2.set_xlabel("observations")
    ax2.set_ylabel("posterior entropy (nats)")
    stop = run.attrs.get("stop_step")
    if stop:
        for a in (ax, ax2):
            a.axvline(stop, color="tab:green", lw=0.8, ls=":")
    ax2.grid(alpha=0.3)
    for a in (ax, ax2):
        a.xaxis.set_major_locator(MaxNLocator(integer=True))
    a = run.attrs
    if known:
        result = f"final error {a.get('final_error_px', np.nan):.2f} px"
    else:
        est = a.get("estimate") or {}
        result = "estimate " + ", ".join(f"{k} {v:+.2f}" for k, v in est.items()) + \
            " (truth unknown)"
    source = " (external robot)" if a.get("source") == "external" else ""
    fig.suptitle(f"adaptation{source}: {a.get('strategy')} strategy, {a.get('posterior')} "
                 f"posterior, {a.get('family')} family; {result}"
                 + (f", stopping rule at t = {stop}" if stop else ""), fontsize=10)
    fig.tight_layout()
    save(fig, path)
