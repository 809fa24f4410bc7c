"""Figure of one adaptation run: the posterior's evolution (the paper's Fig. 5) and the error and
entropy curves (Figs. 6, 7 for a single experiment).

Top row: the translation posterior (log scale over 30 nats; the angle summed out for the rigid
family) at the stored snapshot steps, the truth a cross and the estimate a circle; the last panel
zooms in on the estimate. Bottom: the translation error (px, log scale), the angle error (rigid
runs) and the entropy against the observations, the stopping rule marked. Without ground truth
(``kbcli serve``) there is no cross, and the error panel shows the posterior mass near the
estimate.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator

from kbcli.core.instrument.transforms import FAMILIES
from kbcli.stages.artifact import Artifact
from kbcli.viz.common import angle_note, external, save

MAX_PANELS = 6
DYNAMIC_RANGE = 30.0  # nats of log-posterior shown
ZOOM = 4.0  # px, least half-width of the last panel
MARGIN = 1.5  # px around the estimate and the truth in the zoomed panel
BRIGHT = 10.0  # nats below the maximum: the part of the posterior the zoomed panel keeps in view


def _plain(v: float, _pos=None) -> str:
    return f"{v:g}"


def _steps_axis(ax, n: int) -> None:
    """Whole-number ticks on the observation axis, sane for a run of one or two steps."""
    if n <= 12:
        ax.set_xticks(np.arange(1, max(n, 1) + 1))
    else:
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlim(0.5, max(n, 1) + 0.5)


@dataclass
class _Run:
    """What the figure of a run shows, read once from the artifact."""

    d: dict
    a: dict
    steps: np.ndarray
    snaps: object
    errors: np.ndarray
    entropy: np.ndarray
    tx: float
    ty: float
    has_truth: bool
    means: np.ndarray
    rigid: bool
    stop: object
    dx: np.ndarray
    dy: np.ndarray

    @property
    def angle_note(self) -> str:
        """What the posterior panels show of the angle (:func:`kbcli.viz.common.angle_note`)."""
        return angle_note(self.a.get("family"), self.a.get("world_family"))

    @property
    def three(self) -> bool:
        """A third curve panel: the angle error of a rigid run with ground truth."""
        return self.rigid and self.has_truth


def _read(run: Artifact) -> _Run:
    d, a = run.data, run.attrs
    errors = np.asarray(d["errors"], float)
    truth = a.get("truth") or {}
    tx, ty = float(truth.get("dx", np.nan)), float(truth.get("dy", np.nan))
    has_truth = bool(np.isfinite(tx) and np.isfinite(ty)) and bool(np.isfinite(errors).any())
    rigid = any(FAMILIES.get(f).rotates for f in (a.get("family"), a.get("world_family"))
                if f is not None)
    return _Run(d, a, np.asarray(d.get("snapshot_steps", np.zeros(0, int))), d.get("snapshots"),
                errors, np.asarray(d["entropy"], float), tx, ty, has_truth,
                np.asarray(d["means"], float), rigid, a.get("stop_step"),
                np.asarray(d["dx"], float), np.asarray(d["dy"], float))


def _zoom(r: _Run, lp: np.ndarray, top: float, est: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half-width of the zoomed panel: the estimate, the truth and the bright part."""
    lo = est.copy()
    hi = est.copy()
    if r.has_truth:
        lo, hi = np.minimum(lo, (r.tx, r.ty)), np.maximum(hi, (r.tx, r.ty))
    if lp.ndim == 2 and lp.shape == (len(r.dy), len(r.dx)):  # and the bright part
        rows, cols = np.nonzero(lp - top > -BRIGHT)
        if len(rows):
            lo = np.minimum(lo, (r.dx[cols].min(), r.dy[rows].min()))
            hi = np.maximum(hi, (r.dx[cols].max(), r.dy[rows].max()))
    return (lo + hi) / 2, max(ZOOM, float(np.max(hi - lo)) / 2 + MARGIN)


def _snapshot(fig, gs, r: _Run, i: int, j: int, last: bool):
    """Panel ``i``: the posterior at snapshot ``j`` (``last``: zoomed in on the estimate)."""
    ax = fig.add_subplot(gs[0, i])
    lp = np.asarray(r.snaps[j], float)
    top = float(np.max(lp)) if np.isfinite(lp).any() else 0.0
    image = ax.imshow(lp - top, origin="lower", extent=(r.dx[0], r.dx[-1], r.dy[0], r.dy[-1]),
                      cmap="magma", aspect="equal", vmin=-DYNAMIC_RANGE, vmax=0.0,
                      interpolation="nearest")
    if r.has_truth:
        ax.plot([r.tx], [r.ty], "x", color="cyan", ms=9, mew=2)
    t = int(r.steps[j])
    est = r.means[t - 1, -2:] if 1 <= t <= len(r.means) else None
    if est is not None:
        ax.plot([est[0]], [est[1]], "o", mfc="none", mec="lime", ms=9, mew=1.5)
    zoom = last and est is not None
    if zoom:  # the last panel zooms in on the estimate, keeping the truth in view
        centre, half = _zoom(r, lp, top, est)
        # a wide posterior (a weak model's, tempered) fills the panel: no zoom to show
        zoom = half < 0.8 * min(r.dx[-1] - r.dx[0], r.dy[-1] - r.dy[0]) / 2
        if zoom:
            ax.set_xlim(centre[0] - half, centre[0] + half)
            ax.set_ylim(centre[1] - half, centre[1] + half)
    after = f"after {t} observation{'s' if t != 1 else ''}" if t else "prior (t = 0)"
    notes = ([r.angle_note] if r.angle_note else []) + ([f"zoom +-{half:.3g} px"] if zoom else [])
    ax.set_title(after + (f"\n({'; '.join(notes)})" if notes else ""), fontsize=9)
    ax.set_xlabel("dx (px)", fontsize=8)
    if i == 0:
        ax.set_ylabel("dy (px)", fontsize=8)
    ax.tick_params(labelsize=7)
    return image


def _posteriors(fig, gs, r: _Run, pick: np.ndarray, n: int) -> None:
    """The top row: the posterior at the picked snapshots, and its colour bar."""
    image = None
    for i, j in enumerate(pick):
        image = _snapshot(fig, gs, r, i, j, i == len(pick) - 1 and len(pick) > 1)
    if image is not None:
        cax = fig.add_subplot(gs[0, n])
        cb = fig.colorbar(image, cax=cax)
        cb.set_label("log posterior - max (nats)", fontsize=8)
        cb.ax.tick_params(labelsize=7)


def _error_panel(ax, r: _Run, t: np.ndarray) -> None:
    if r.has_truth:
        ax.semilogy(t, np.maximum(r.errors, 1e-3), "-o", ms=3, color="tab:blue")
        ax.axhline(1.0, color="0.5", ls="--", lw=0.8)
        ax.set_ylabel("translation error (px)")
        ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(FuncFormatter(_plain))
        ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _p: ""))
    else:  # a real robot: no ground truth, show the robot's own confidence
        ax.plot(t, np.asarray(r.d.get("mass", np.full_like(r.errors, np.nan)), float), "-o",
                ms=3, color="tab:green")
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("posterior mass near the estimate")
        ax.set_title("ground truth unknown (external robot): no error", fontsize=8)
    ax.set_xlabel("observations")


def _curves(fig, gs, r: _Run, n: int) -> None:
    """The bottom row: the error (or the mass near the estimate), the angle error, the entropy."""
    T = len(r.errors)
    t = np.arange(1, T + 1)
    cols = [(0, n // 3 if r.three else n // 2), (n // 3, 2 * n // 3),
            (2 * n // 3 if r.three else n // 2, n)]
    ax = fig.add_subplot(gs[1, cols[0][0]:cols[0][1]])
    _error_panel(ax, r, t)
    axes = [ax]
    if r.three:
        ang = np.asarray(r.d.get("angle_errors", np.full(T, np.nan)), float)
        ax_a = fig.add_subplot(gs[1, cols[1][0]:cols[1][1]])
        ax_a.plot(t, ang, "-s", ms=3, color="tab:orange")
        ax_a.set_xlabel("observations")
        ax_a.set_ylabel("angle error (degrees)")
        ax_a.set_ylim(bottom=0)
        axes.append(ax_a)
    ax2 = fig.add_subplot(gs[1, cols[2][0]:cols[2][1]])
    ax2.plot(t, r.entropy, "-", color="tab:purple", marker="." if T < 15 else None)
    ax2.set_xlabel("observations")
    ax2.set_ylabel("posterior entropy (nats)")
    axes.append(ax2)
    for axx in axes:
        axx.grid(alpha=0.3)
        _steps_axis(axx, T)
        if r.stop:
            axx.axvline(r.stop, color="tab:green", lw=1.0, ls=":")


def _legend(fig, r: _Run) -> None:
    """One legend naming every mark."""
    handles = [Line2D([], [], ls="", marker="o", mfc="none", mec="lime", mew=1.5,
                      label="estimate (posterior mean)")]
    if r.has_truth:
        handles.insert(0, Line2D([], [], ls="", marker="x", color="cyan", mew=2,
                                 label="true displacement"))
        handles.append(Line2D([], [], color="0.5", ls="--", lw=0.8, label="1 px"))
    if r.stop:
        handles.append(Line2D([], [], color="tab:green", ls=":", lw=1.0,
                              label=f"stopping rule met (t = {r.stop})"))
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.965),
               ncol=len(handles), fontsize=8, frameon=False)


def _title(r: _Run) -> str:
    a = r.a
    if r.has_truth:
        final = a.get("final_error_px", np.nan)
        final = np.nan if final is None else final
        angle = (f", angle error {a.get('final_angle_error_deg', np.nan):.2f} deg"
                 if r.rigid and isinstance(a.get("final_angle_error_deg"), (int, float)) else "")
        result = f"final error {final:.2f} px{angle}"
    else:
        est = a.get("estimate") or {}
        result = "estimate " + ", ".join(f"{k} {v:+.2f}" for k, v in est.items()) + \
            " (truth unknown)"
    T = len(r.errors)
    source = " (external robot)" if external(a) else ""
    return (f"adaptation{source}: {a.get('strategy')} strategy, {a.get('posterior')} "
            f"posterior, {a.get('family')} family, {T} observation{'s' if T != 1 else ''}; "
            f"{result}")


def plot_adapt(run: Artifact, path: str | os.PathLike) -> None:
    """Draw a ``run`` artifact to a figure file (format from the suffix)."""
    r = _read(run)
    pick = np.arange(len(r.steps)) if r.snaps is not None else np.arange(0)
    if len(pick) > MAX_PANELS:
        pick = np.unique(np.rint(np.linspace(0, len(r.steps) - 1, MAX_PANELS)).astype(int))
    n = max(len(pick), 3 if r.three else 2)
    fig = plt.figure(figsize=(2.7 * n + 1.2, 6.9))
    gs = fig.add_gridspec(2, n + 1, height_ratios=[1.15, 1.0], width_ratios=[1] * n + [0.07])
    _posteriors(fig, gs, r, pick, n)
    _curves(fig, gs, r, n)
    _legend(fig, r)
    fig.suptitle(_title(r), fontsize=10, y=0.995)
    fig.tight_layout(rect=(0, 0, 1, 0.945))
    save(fig, path)
