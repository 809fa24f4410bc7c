"""The report's figures from an ``evaluation`` artifact (paper Figs. 5, 6 and 7).

- :func:`plot_posterior` (Fig. 5): the posterior over the displacement after successive
  observations of one example run per strategy (Eq. 8, the product of the per-observation terms);
- :func:`plot_entropy` (Fig. 6): posterior entropy against observations per strategy;
- :func:`plot_error` (Fig. 7): RMSE of the estimate against observations, one panel per category.
"""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from kbcli.stages.artifact import Artifact  # noqa: E402
from kbcli.viz.common import save  # noqa: E402

COLOURS = {"random": "tab:gray", "active": "tab:blue", "infogain": "tab:red"}


def _colour(s: str, i: int) -> str:
    return COLOURS.get(s, f"C{i + 3}")


def _snapshot_arrays(ex: dict) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]:
    """(S, H, W) posterior probabilities, (S,) steps and the (dx0, dx1, dy0, dy1) extent of an
    example run's snapshots (``snapshots`` (S, n_dy, n_dx) log translation marginals, rows = dy;
    ``dx``, ``dy`` the cell centres)."""
    snaps = np.asarray(ex["snapshots"], float)
    if snaps.ndim == 4:  # rigid family: (S, A, H, W), marginalise the angle
        snaps = snaps.sum(axis=1) if snaps.min() >= 0 else np.log(np.exp(
            snaps - snaps.max(axis=(1, 2, 3), keepdims=True)).sum(axis=1))
    if snaps.min() < 0 or ex.get("snapshot_log", False):  # log posterior
        snaps = np.exp(snaps - snaps.max(axis=(1, 2), keepdims=True))
    steps = np.asarray(ex.get("snapshot_steps", np.arange(1, len(snaps) + 1)))
    if "dx" in ex and "dy" in ex and len(ex["dx"]) > 1 and len(ex["dy"]) > 1:  # cell centres
        dx, dy = np.asarray(ex["dx"], float), np.asarray(ex["dy"], float)
        hx, hy = (dx[1] - dx[0]) / 2, (dy[1] - dy[0]) / 2
        ext = (dx[0] - hx, dx[-1] + hx, dy[0] - hy, dy[-1] + hy)
    else:
        n = snaps.shape[-1]
        ext = (-n / 2, n / 2, -n / 2, n / 2)
    return snaps, steps, ext


def plot_posterior(art: Artifact, path: str | os.PathLike, mode: str | None = None,
                   max_columns: int = 6) -> None:
    """Fig. 5: one row per strategy, one column per snapshot step, the true displacement crossed."""
    modes = art.attrs["modes"]
    mode = mode or ("ideal" if "ideal" in modes else modes[0])
    examples = art.data["examples"][mode]
    rows = [s for s in art.attrs["strategies"] if s in examples and "snapshots" in examples[s]]
    if not rows:
        raise ValueError("no posterior snapshots in this evaluation")
    data = {s: _snapshot_arrays(examples[s]) for s in rows}
    ncol = min(max_columns, max(len(d[1]) for d in data.values()))
    fig, axes = plt.subplots(len(rows), ncol, figsize=(2.1 * ncol, 2.2 * len(rows)), squeeze=False)
    params = art.array("experiments/params")
    for r, s in enumerate(rows):
        snaps, steps, ext = data[s]
        truth = params[int(examples[s]["row"])][-2:]
        for c in range(ncol):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            if c >= len(snaps):
                ax.axis("off")
                continue
            p = snaps[c] / max(snaps[c].max(), 1e-300)
            ax.imshow(p, origin="lower", extent=ext, cmap="magma", vmin=0, vmax=1,
                      interpolation="nearest")
            ax.plot(*truth, marker="+", color="cyan", ms=9, mew=1.2)
            ax.set_title(f"t = {int(steps[c])}", fontsize=8)
            if c == 0:
                ax.set_ylabel(s, fontsize=9)
    fig.suptitle(f"Posterior over the displacement (dx, dy), {mode} mode", fontsize=10)
    save(fig, path)


def plot_entropy(art: Artifact, path: str | os.PathLike) -> None:
    """Fig. 6: mean posterior entropy per step and strategy, interquartile range shaded."""
    modes = art.attrs["modes"]
    fig, axes = plt.subplots(1, len(modes), figsize=(4.6 * len(modes), 3.4), squeeze=False)
    for ax, m in zip(axes[0], modes, strict=True):
        for i, s in enumerate(art.attrs["strategies"]):
            e = art.data["entropy"][m][s]
            t = np.arange(1, len(e["mean"]) + 1)
            ax.plot(t, e["mean"], color=_colour(s, i), label=s)
            ax.fill_between(t, e["q25"], e["q75"], color=_colour(s, i), alpha=0.2, lw=0)
        ax.set_xlabel("observations")
        ax.set_ylabel("posterior entropy (nats)")
        ax.set_title(f"{m} mode", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    save(fig, path)


def plot_error(art: Artifact, path: str | os.PathLike, mode: str) -> None:
    """Fig. 7: RMSE against observations per strategy, one panel per category (log scale)."""
    cats = art.attrs["categories"]
    fig, axes = plt.subplots(1, len(cats), figsize=(4.2 * len(cats), 3.4), squeeze=False,
                             sharey=True)
    for ax, c in zip(axes[0], cats, strict=True):
        for i, s in enumerate(art.attrs["strategies"]):
            cur = art.data["curves"][mode][c][s]
            t = np.arange(1, len(cur["rmse"]) + 1)
            floor = 1e-2
            ax.plot(t, np.maximum(cur["rmse"], floor), color=_colour(s, i), label=s)
            ax.fill_between(t, np.maximum(cur["q25"], floor), np.maximum(cur["q75"], floor),
                            color=_colour(s, i), alpha=0.18, lw=0)
        limit = art.config["categories"][c]["limit"]
        ax.set_title(f"{c} (up to {limit:g} px)", fontsize=10)
        ax.set_yscale("log")
        ax.set_xlabel("observations")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].set_ylabel("RMSE of the displacement (px)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"Estimation error, {mode} mode", fontsize=10, y=1.03)
    save(fig, path)
