"""The report's figures from an ``evaluation`` artifact: :func:`plot_posterior` (Fig. 5, the
posterior after successive observations of one example run per method and strategy),
:func:`plot_entropy` (Fig. 6) and :func:`plot_error` (Fig. 7, RMSE per category and method).
"""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from kbcli.stages.artifact import Artifact  # noqa: E402
from kbcli.stages.report.source import exact_mode  # noqa: E402
from kbcli.viz.common import angle_note, save  # noqa: E402

COLOURS = {"random": "tab:gray", "active": "tab:blue", "paper-active": "tab:cyan",
           "infogain": "tab:red"}


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


def _shown_mode(modes: list[str]) -> str:
    """The sim mode whose examples are shown by default: ``ideal`` when measured, else the first
    (the one place this module names a sim mode)."""
    return exact_mode(modes) or modes[0]


def _rows(art: Artifact, mode: str, key: str = "curves") -> list[tuple[str, str]]:
    """(method, strategy) pairs present in ``mode``, in method order."""
    out = []
    from kbcli.stages.report import method_names

    tree = art.data[key].get(mode, {})
    for x in [x for x in method_names(art) if x in tree]:
        by = tree[x]
        strategies = art.attrs["methods"][x]["strategies"]
        present = {s for by_s in by.values() for s in by_s} if key == "curves" else set(by)
        out += [(x, s) for s in strategies if s in present]
    return out


LINESTYLES = ("-", "--", ":", "-.")


#: Fig. 5's panels zoom on the posterior: cells above this share of the panel's maximum (the
#: colour scale's floor) and the truth, padded, at least ZOOM_MIN_HALF px either side.
ZOOM_FLOOR = 1e-3
ZOOM_MIN_HALF = 4.0


def zoom_window(p: np.ndarray, ext: tuple[float, float, float, float], truth: np.ndarray,
                floor: float = ZOOM_FLOOR,
                min_half: float = ZOOM_MIN_HALF) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) px a Fig. 5 panel shows: the cells of ``p`` (rows = dy) at or above
    ``floor`` of its maximum and the true displacement, with a margin of a fifth of the span, at
    least ``min_half`` px either side of the centre, within the grid's extent ``ext``."""
    h, w = p.shape
    xs = np.linspace(ext[0], ext[1], w + 1)
    ys = np.linspace(ext[2], ext[3], h + 1)
    rows, cols = np.nonzero(p >= floor * max(float(p.max()), 1e-300))
    if len(rows) == 0:
        return ext
    lo = np.array([min(xs[cols.min()], truth[0]), min(ys[rows.min()], truth[1])])
    hi = np.array([max(xs[cols.max() + 1], truth[0]), max(ys[rows.max() + 1], truth[1])])
    centre, half = (lo + hi) / 2, np.maximum((hi - lo) / 2 * 1.2, min_half)
    half = np.full(2, half.max())  # square panels
    return (max(centre[0] - half[0], ext[0]), min(centre[0] + half[0], ext[1]),
            max(centre[1] - half[1], ext[2]), min(centre[1] + half[1], ext[3]))


def plot_posterior(art: Artifact, path: str | os.PathLike, mode: str | None = None,
                   max_columns: int = 6) -> None:
    """Fig. 5: one row per method and strategy, one column per snapshot step, in px coordinates
    (the displacement dx, dy), each panel scaled to its own maximum on a log colour scale (one
    colour bar) and zoomed on its mass and the truth (:func:`zoom_window`), the true displacement
    an outline that never hides a posterior collapsed onto one cell."""
    from kbcli.stages.report import upgrade

    art = upgrade(art)
    modes = art.attrs["modes"]
    mode = mode or _shown_mode(modes)
    examples = art.data["examples"].get(mode, {})
    rows = [(x, s) for x, s in _rows(art, mode, "examples") if "snapshots" in examples[x][s]]
    if not rows:
        raise ValueError("no posterior snapshots in this evaluation")
    data = {r: _snapshot_arrays(examples[r[0]][r[1]]) for r in rows}
    ncol = min(max_columns, max(len(d[1]) for d in data.values()))
    fig, axes = plt.subplots(len(rows), ncol, figsize=(1.9 * ncol + 1.2, 2.05 * len(rows) + 0.6),
                             squeeze=False)
    params = art.array("experiments/params")
    norm = LogNorm(vmin=ZOOM_FLOOR, vmax=1.0)
    im = None
    for r, (x, s) in enumerate(rows):
        snaps, steps, ext = data[(x, s)]
        truth = params[int(examples[x][s]["row"])][-2:]
        for c in range(ncol):
            ax = axes[r, c]
            if c >= len(snaps):
                ax.axis("off")
                continue
            im = _posterior_panel(ax, snaps[c], ext, truth, norm)
            ax.set_title(f"t = {int(steps[c])}", fontsize=8)
            if r == len(rows) - 1:
                ax.set_xlabel("dx (px)", fontsize=8)
            if c == 0:
                ax.set_ylabel(f"{x}\n{s}\ndy (px)", fontsize=8)
    notes = sorted({_angle_note(art, mode, x, s) for x, s in rows} - {""})
    fig.suptitle(f"Posterior over the displacement, {mode} mode (circle: the truth, "
                 f"({truth[0]:g}, {truth[1]:g}) px; each panel zoomed on its mass"
                 + "".join(f"; {n}" for n in notes) + ")", fontsize=10)
    fig.tight_layout(rect=(0, 0, 0.92, 0.97))
    cax = fig.add_axes((0.93, 0.15, 0.015, 0.7))
    cb = fig.colorbar(im, cax=cax)
    cb.set_label("posterior / its maximum (log)", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    save(fig, path)


def _angle_note(art: Artifact, mode: str, method: str, strategy: str) -> str:
    """What a Fig. 5 row shows of the angle (:func:`kbcli.viz.common.angle_note`)."""
    opts = ((art.attrs["methods"][method].get("options") or {}).get(mode) or {}).get(strategy)
    robot = (opts or {}).get("robot") or {}
    return angle_note(robot.get("family"), art.config.get("family"))


def _posterior_panel(ax, snap: np.ndarray, ext: tuple, truth: np.ndarray, norm):
    """One Fig. 5 panel: the posterior over its own maximum, zoomed, the truth as an outline."""
    p = snap / max(snap.max(), 1e-300)
    im = ax.imshow(np.maximum(p, ZOOM_FLOOR), origin="lower", extent=ext, cmap="magma",
                   norm=norm, interpolation="nearest")
    x0, x1, y0, y1 = zoom_window(p, ext, truth)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.plot(*truth, marker="o", ms=11, mfc="none", mec="cyan", mew=1.3, ls="none")
    ax.tick_params(labelsize=7)
    return im


def _style(art: Artifact, x: str, s: str, i: int) -> dict:
    from kbcli.stages.report import method_names

    meths = method_names(art)
    j = meths.index(x) if x in meths else 0
    return {"color": _colour(s, i), "ls": LINESTYLES[j % len(LINESTYLES)]}


def plot_entropy(art: Artifact, path: str | os.PathLike) -> None:
    """Fig. 6: mean posterior entropy per step from t = 0 (the uniform prior's entropy), one panel
    per mode (rows) and size category (columns), method (line style) and strategy (colour),
    interquartile range shaded."""
    from kbcli.stages.report import prior_entropy, upgrade

    art = upgrade(art)
    modes, cats = art.attrs["modes"], art.attrs["categories"]
    fig, axes = plt.subplots(len(modes), len(cats), figsize=(4.2 * len(cats), 3.4 * len(modes)),
                             squeeze=False, sharex=True, sharey=True)
    for r, m in enumerate(modes):
        for ax, c in zip(axes[r], cats, strict=True):
            for i, (x, s) in enumerate(_rows(art, m, "entropy")):
                cur = art.data["curves"][m].get(x, {}).get(c, {}).get(s)
                if cur is None or "entropy_mean" not in cur:
                    continue
                h0 = prior_entropy(art, x)
                mean, q25, q75 = (np.asarray(cur[f"entropy_{k}"], float)
                                  for k in ("mean", "q25", "q75"))
                if h0 is not None:  # every run starts from the uniform prior
                    mean, q25, q75 = (np.r_[h0, v] for v in (mean, q25, q75))
                t = np.arange(len(mean)) + (0 if h0 is not None else 1)
                st = _style(art, x, s, i)
                ax.plot(t, mean, label=f"{x} / {s}", **st)
                ax.fill_between(t, q25, q75, color=st["color"], alpha=0.12, lw=0)
            limit = art.config["categories"][c]["limit"]
            ax.set_title(f"{m} mode, {c} (up to {limit:g} px)", fontsize=9)
            ax.grid(alpha=0.3)
            if r == len(modes) - 1:
                ax.set_xlabel("observations")
        axes[r, 0].set_ylabel("posterior entropy (nats)")
    handles, labels = axes[0, -1].get_legend_handles_labels()  # beside the panels, never on a curve
    fig.legend(handles, labels, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8,
               frameon=False)
    fig.tight_layout()
    save(fig, path)


def plot_error(art: Artifact, path: str | os.PathLike, mode: str) -> None:
    """Fig. 7: RMSE against observations per strategy, one panel per category (columns) and
    method (rows), log scale."""
    from kbcli.stages.report import upgrade

    art = upgrade(art)
    cats = art.attrs["categories"]
    from kbcli.stages.report import method_names

    meths = [x for x in method_names(art) if x in art.data["curves"][mode]]
    fig, axes = plt.subplots(len(meths), len(cats), figsize=(4.2 * len(cats), 3.0 * len(meths)),
                             squeeze=False, sharey=True, sharex=True)
    for r, x in enumerate(meths):
        for ax, c in zip(axes[r], cats, strict=True):
            by_s = art.data["curves"][mode][x].get(c)
            if by_s is None:
                ax.text(0.5, 0.5, "not run", ha="center", va="center", transform=ax.transAxes)
            else:
                order = [s for s in art.attrs["methods"][x]["strategies"] if s in by_s]
                for i, (s, cur) in enumerate((s, by_s[s]) for s in order):
                    t = np.arange(1, len(cur["rmse"]) + 1)
                    floor = 1e-2
                    ax.plot(t, np.maximum(cur["rmse"], floor), color=_colour(s, i), label=s)
                    ax.fill_between(t, np.maximum(cur["q25"], floor),
                                    np.maximum(cur["q75"], floor), color=_colour(s, i),
                                    alpha=0.18, lw=0)
                ax.legend(fontsize=7, title=x, title_fontsize=8)
            limit = art.config["categories"][c]["limit"]
            if r == 0:
                ax.set_title(f"{c} (up to {limit:g} px)", fontsize=10)
            ax.set_yscale("log")
            ax.grid(alpha=0.3, which="both")
            if r == len(meths) - 1:
                ax.set_xlabel("observations")
        axes[r, 0].set_ylabel(f"{x}: RMSE (px)")
    height = 3.0 * len(meths)  # the title half an inch above the panels' titles, whatever the rows
    fig.subplots_adjust(top=1 - 0.55 / height)
    fig.suptitle(f"Estimation error, {mode} mode", fontsize=10, y=1 - 0.12 / height)
    save(fig, path)
