"""Figure of a model artifact: the learned map beside the true layout, and the learning curve.

Left: the key the model predicts in each 2 px cell, its uncertainty (the confusion factor
1 - (p1 - p2), Sect. III-E) shaded, the fitted boundary lines, the explored points and the wrong
cells in red. Middle: the true layout. Right: the learning curve, with the model's own estimate of
its reliability (:mod:`kbcli.core.model.reliability`) beside the measured values. An exact-model
artifact shows its map and the layout.
"""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import LinearSegmentedColormap, ListedColormap
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.model import accuracy as scoring
from kbcli.core.model.base import grid_points
from kbcli.io.schema.rules import learned, model_class_of
from kbcli.stages.artifact import Artifact
from kbcli.viz.common import draw_layout, save
from kbcli.viz.palette import map_colours

MAP_STEP = 2.0  # px


#: the shading of uncertainty: white (sure) to near black (a coin flip between two keys)
SHADE = LinearSegmentedColormap.from_list("confusion", [(0, 0, 0, 0), (0.1, 0.1, 0.1, 0.85)])


def _map(model, kb: Keyboard) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per 2 px cell: the predicted key, the confusion 1 - (p1 - p2), and whether it is wrong."""
    _, pts = grid_points(kb.area, MAP_STEP)
    flat = pts.reshape(-1, 2)
    proba = model.predict_proba(flat)
    cls = np.argmax(proba, axis=1)
    keys = scoring.class_keys(model.class_features_, kb)[cls].reshape(pts.shape[:2])
    top2 = np.sort(proba, axis=1)[:, -2:] if proba.shape[1] > 1 else np.ones((len(flat), 2))
    confusion = (1.0 - (top2[:, 1] - top2[:, 0])).reshape(pts.shape[:2])
    wrong = keys != kb.key_at(flat).reshape(pts.shape[:2])
    return keys, confusion, wrong


def boundary_segments(lines: np.ndarray, keys: np.ndarray, area, step: float = MAP_STEP
                      ) -> np.ndarray:
    """(n, 2) points, 1 px apart, where each fitted boundary line ``n . x = c`` separates two
    different predicted keys on the map (``keys``: the key per ``step`` px cell of ``area``); NaN
    where the cells 2 px either side agree or fall off the map, and one NaN row between lines
    (to plot as one broken line)."""
    x0, y0, x1, y1 = (float(v) for v in area)
    half = np.hypot(x1 - x0, y1 - y0)
    t = np.arange(-half, half, 1.0)
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    out = []
    for nx, ny, c in np.asarray(lines, float).reshape(-1, 3):
        n = np.array([nx, ny]) / max(np.hypot(nx, ny), 1e-12)
        foot = centre + (c / max(np.hypot(nx, ny), 1e-12) - centre @ n) * n
        pts = foot + np.outer(t, (-n[1], n[0]))
        sides = [_cell_keys(pts + d * n, keys, (x0, y0), step) for d in (2.0, -2.0)]
        differ = (sides[0] != sides[1]) & (sides[0] != _OFF) & (sides[1] != _OFF)
        pts[~differ] = np.nan
        out += [pts, np.full((1, 2), np.nan)]
    return np.vstack(out) if out else np.empty((0, 2))


_OFF = -99  # a point off the map


def _cell_keys(pts: np.ndarray, keys: np.ndarray, origin, step: float) -> np.ndarray:
    col = np.floor((pts[:, 0] - origin[0]) / step).astype(int)
    row = np.floor((pts[:, 1] - origin[1]) / step).astype(int)
    inside = (row >= 0) & (row < keys.shape[0]) & (col >= 0) & (col < keys.shape[1])
    out = np.full(len(pts), _OFF)
    out[inside] = keys[row[inside], col[inside]]
    return out


def _samples_and_lines(ax, art: Artifact, handles: list, keys: np.ndarray, area) -> str:
    """A learned model's reaches and fitted boundary lines (where they separate two keys of its
    map) on the map; the map's title."""
    d = art.data
    landed = np.asarray(d["samples"]["landed"], float)
    ax.plot(landed[:, 0], landed[:, 1], ".", color="black", ms=1.6, alpha=0.7)
    handles.append(Line2D([], [], ls="", marker=".", color="black",
                          label=f"reaches ({len(landed)})"))
    lines = np.asarray(d["model"].get("lines", np.empty((0, 3))), float)
    if len(lines):
        seg = boundary_segments(lines, keys, area)
        ax.plot(seg[:, 0], seg[:, 1], color="0.25", lw=0.5, alpha=0.7)
        handles.append(Line2D([], [], color="0.25", lw=0.6,
                              label=f"fitted boundaries ({len(lines)} lines)"))
    a = art.attrs
    sel = a.get("model_selection")
    chosen = " (auto: chosen by cross-validation)" if sel else ""
    return (f"learned {model_class_of(art)} model{chosen}\n{a.get('strategy')} "
            f"exploration, {a.get('mode')} mode, "
            f"{a.get('n_reaches')} reaches\naccuracy {100 * _num(a.get('accuracy')):.2f} %, "
            f"boundary error {_num(a.get('boundary_error_px')):.2f} px")


def _map_panel(fig, ax, art: Artifact, model, kb: Keyboard) -> None:
    """Left: the predicted key per cell, its uncertainty, wrong cells red; a learned model's
    reaches and boundary lines."""
    x0, y0, x1, y1 = kb.area
    extent = (x0, x1, y0, y1)
    keys, confusion, wrong = _map(model, kb)
    colours = map_colours(kb.n_keys)
    ax.imshow(keys + 2, origin="lower", extent=extent, interpolation="nearest",
              cmap=ListedColormap(colours), vmin=-0.5, vmax=len(colours) - 0.5)
    shade = ax.imshow(confusion, origin="lower", extent=extent, interpolation="nearest",
                      cmap=SHADE, vmin=0.0, vmax=1.0)
    red = np.zeros((*wrong.shape, 4))
    red[wrong] = (0.9, 0.0, 0.0, 0.9)
    ax.imshow(red, origin="lower", extent=extent, interpolation="nearest")
    handles = [Patch(facecolor="white", edgecolor="0.5", label="silence")]
    if wrong.any():
        handles.append(Patch(facecolor=(0.9, 0, 0), label=f"wrong key ({100 * wrong.mean():.2f} % "
                                                           f"of cells)"))
    if learned(art):
        title = _samples_and_lines(ax, art, handles, keys, kb.area)
    else:
        title = "exact model: the keyboard's own geometry\n(no learning; predicted key per 2 px cell)"
    ax.set_title(title, fontsize=11)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("pad x (px)")
    ax.set_ylabel("pad y (px)")
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2,
              fontsize=9, frameon=False)
    if np.nanmax(confusion) > 0:  # an exact model is never unsure
        cb = fig.colorbar(shade, cax=ax.inset_axes([1.03, 0.0, 0.035, 1.0]))
        cb.set_label("uncertainty: 1 - (p1 - p2)", fontsize=9)
        cb.ax.tick_params(labelsize=8)


def _layout_panel(ax, kb: Keyboard) -> None:
    """Middle: the true layout."""
    draw_layout(ax, kb, 0, area=False)
    ax.set_title(f"true layout ({kb.layout}): {kb.n_keys} keys (note, tempo)", fontsize=11)
    ax.set_xlabel("pad x (px)")


def _reliability_text(rel: dict, a: dict) -> str:
    """What the model estimates of itself from its samples (model schema 2), beside what was
    measured."""
    cal = ", ".join(f"{k} {v:g}" for k, v in sorted(rel.get("calibration", {}).items()))
    wrong = 100 * (1 - _num(a.get("accuracy")))
    expects = (f"mislabel rate expected on the pad {100 * rel['expected_error']:.1f} % "
               f"(measured {wrong:.1f} %)\n" if rel.get("expected_error") is not None
               else "")  # (models learned before it was estimated)
    return (f"the model's own estimate, from its samples\n"
            f"({rel.get('folds', 'k')}-fold cross-validation, calibrated p):\n"
            f"boundary error ~{rel['boundary_error']:.2f} px "
            f"(measured {_num(a.get('boundary_error_px')):.2f})\n"
            + expects
            + f"held-out touches mislabelled {100 * rel['cv_error']:.1f} %"
            + ("\n" if expects else f" (pad: {wrong:.1f} %)\n")
            + f"calibration error {rel['cv_ece']:.3f}" + (f"; {cal}" if cal else ""))


def _curve_panel(ax, art: Artifact) -> None:
    """Right: the learning curve with the 99 % level, and the model's own estimate below it."""
    n = np.asarray(art.data["curve"]["reaches"])
    acc = np.asarray(art.data["curve"]["accuracy"], float)
    ax.plot(n, 100 * acc, "o-", ms=3, color="tab:blue", label="accuracy")
    ax.axhline(99.0, ls="--", color="grey", lw=1, label="99 % (the target)")
    # below the line, inside the axes
    ax.text(0.02, 99.0, "99 %", transform=ax.get_yaxis_transform(), ha="left", va="top",
            fontsize=9, color="0.35", gid="target-label",
            bbox={"boxstyle": "square,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
    ax.set_xlabel("reaches")
    ax.set_ylabel("accuracy (%, 2 px grid)")
    lo = 100 * float(np.nanmin(acc)) if len(acc) and np.isfinite(acc).any() else 0.0
    ax.set_ylim(max(0.0, min(lo, 99.0) - 5), 100.5)
    to99 = art.attrs.get("reaches_to_99")
    ax.set_title("learning curve: " + (f"99 % after {to99} reaches" if to99 is not None
                                       else "99 % not reached"), fontsize=11)
    ax.legend(fontsize=9, loc="lower right")
    ax.grid(alpha=0.3)
    rel = art.attrs.get("reliability")
    if rel:
        ax.text(0.5, -0.13,  # below the axes: inside, it hid a weak model's curve
                _reliability_text(rel, art.attrs),
                transform=ax.transAxes, ha="center", va="top", fontsize=9,
                bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})


def plot_model(art: Artifact, model, kb: Keyboard, path: str | os.PathLike) -> None:
    """Draw a ``model`` artifact (with its loaded model and keyboard) to a figure file."""
    ncols = 3 if learned(art) else 2
    fig, axes = plt.subplots(1, ncols, figsize=(5.6 * ncols, 5.8),
                             gridspec_kw={"width_ratios": [1.3, 1.2, 1.0][:ncols]})
    _map_panel(fig, axes[0], art, model, kb)
    _layout_panel(axes[1], kb)
    if learned(art):
        _curve_panel(axes[2], art)
    fig.tight_layout()
    save(fig, path)


def _num(v) -> float:
    """A summary number, NaN when it was not recorded (None)."""
    return np.nan if v is None else float(v)
