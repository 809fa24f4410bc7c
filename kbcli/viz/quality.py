"""Figure of a model-quality sweep: each strategy's advantage over random against the model's
boundary error, and the final error against it (the paper's Sect. IV-C hypothesis, issue 9)."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FixedLocator, NullFormatter, ScalarFormatter  # noqa: E402

from kbcli.stages.artifact import Artifact  # noqa: E402
from kbcli.stages.quality.config import baseline_of, compared_rows  # noqa: E402
from kbcli.viz.common import place_labels, save  # noqa: E402

MARKERS = {"active": "o", "random": "s"}


def plot_advantage(art: Artifact, path: str | os.PathLike) -> None:
    """Left panels: touches saved over the baseline (median of paired differences, all categories)
    against the model's boundary error, one panel per row; filled markers: p < 0.01. Right panel:
    the median final error of every row against the boundary error, with the line y = max(1, x)."""
    a = art.attrs
    info, summ = a["models"], a["summary"]
    rows = compared_rows(a)
    n = len(rows) + 1
    ncol = min(n, 3)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.0 * ncol, 4.2 * nrow), squeeze=False)
    axes = axes.ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    axes = axes[:n]
    names = list(info)
    berr = np.array([info[m]["boundary_error"] for m in names])
    lims = max(0.05, berr.min() / 1.5), berr.max() * 1.5
    for ax, r in zip(axes[:-1], rows, strict=True):
        _advantage_panel(ax, a, r, berr, lims)
    _final_panel(axes[-1], a, berr, lims)
    fig.suptitle(f"{a['n_experiments']} adaptations, {art.config['mode']} mode, arm "
                 f"{art.config['arm']['preset']}: does a better model make active adaptation pay?",
                 fontsize=10)
    fig.tight_layout()
    for ax, r in zip(axes[:-1], rows, strict=True):  # budgets, once the layout is final
        adv = [summ[m]["all"][r]["advantage"] for m in names]
        place_labels(ax, np.column_stack([berr, adv]), [str(info[m]["budget"]) for m in names],
                     color="0.3")
    save(fig, path)


def _advantage_panel(ax, a: dict, r: str, berr: np.ndarray, lims: tuple[float, float]) -> None:
    """Row ``r``'s touches saved over its baseline against each model's boundary error ``berr``,
    a line per exploration; filled markers: p < 0.01."""
    info, summ = a["models"], a["summary"]
    names = list(info)
    for explo, mk in MARKERS.items():
        sel = [i for i, m in enumerate(names) if info[m]["exploration"] == explo]
        if not sel:
            continue
        adv = np.array([summ[names[i]]["all"][r]["advantage"] for i in sel])
        p = np.array([summ[names[i]]["all"][r]["pvalue"] for i in sel])
        xb = berr[sel]
        order = np.argsort(xb)
        ax.plot(xb[order], adv[order], "-", color="0.7", lw=0.8, zorder=1)
        sig = p < 0.01
        ax.scatter(xb[sig], adv[sig], marker=mk, s=42, color="tab:blue", zorder=3,
                   label=f"{explo} exploration, p < 0.01")
        ax.scatter(xb[~sig], adv[~sig], marker=mk, s=42, facecolors="white",
                   edgecolors="tab:blue", zorder=3, label=f"{explo} exploration, p >= 0.01")
    ax.axhline(0, color="black", lw=0.8)
    _px_axis(ax, *lims)
    ax.set_ylabel(f"touches saved over {baseline_of(a, r)} (median of pairs)")
    ax.set_title(f"{r} vs {baseline_of(a, r)}", fontsize=10)
    ax.legend(fontsize=7, loc="best")


def _final_panel(ax, a: dict, berr: np.ndarray, lims: tuple[float, float]) -> None:
    """Every row's median final error against each model's boundary error ``berr``, with the line
    y = max(1 px, boundary error)."""
    colours = plt.get_cmap("tab10")
    names = list(a["models"])
    order = np.argsort(berr)
    for j, r in enumerate(a["rows"]):
        fin = np.array([a["summary"][m]["all"][r]["final_median"] for m in names])
        ax.plot(berr[order], fin[order], "o-", ms=3.5, lw=1, color=colours(j), label=r)
    xs = np.geomspace(*lims, 50)
    ax.plot(xs, np.maximum(1.0, xs), "--", color="black", lw=1, label="max(1 px, boundary error)")
    _px_axis(ax, *lims)
    ax.set_yscale("log")
    ax.yaxis.set_major_locator(FixedLocator([0.2, 0.5, 1, 2, 3, 5, 10, 20, 50, 100]))
    ax.yaxis.set_major_formatter(ScalarFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_ylabel(f"final error after {a['max_steps']} touches (median px)")
    ax.set_title("final error against model quality", fontsize=10)
    ax.legend(fontsize=7)


def _px_axis(ax, lo: float, hi: float) -> None:
    """A log-scale px axis of the model's boundary error from ``lo`` to ``hi``, labelled at 0.5,
    1, 2, 3, 5, 10, 20... px, and a grid."""
    ax.set_xscale("log")
    ax.set_xlim(lo, hi)
    ticks = [t for t in (0.1, 0.2, 0.5, 1, 2, 3, 5, 10, 20, 30, 50, 100) if lo <= t <= hi]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("model's boundary error (px, log scale)")
    ax.grid(alpha=0.3, which="both")
