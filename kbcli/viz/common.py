"""Shared drawing helpers: saving in the format of the suffix, key colours, the keyboard."""

from __future__ import annotations

import functools
import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import hsv_to_rgb
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from kbcli.core.keyboard import Keyboard
from kbcli.io.atomic import atomic_path
from kbcli.io.paths import figure_format


def external(attrs: dict) -> bool:
    """Whether a run came from a robot in another process (``kbcli serve``): no ground truth."""
    return attrs.get("source") == "external"


def save(fig: Figure, path: str | os.PathLike, dpi: int = 110) -> None:
    """Save atomically (temporary file, then rename) and close the figure.

    The format is the suffix of ``path``: ``.png``, ``.pdf`` or ``.svg``
    (:func:`kbcli.io.paths.figure_format`); the files carry no creation date, so the same figure
    gives the same bytes.
    """
    fmt = figure_format(path)
    meta = {"png": {"Software": None}, "pdf": {"Creator": None, "Producer": None,
                                                "CreationDate": None},
            "svg": {"Date": None, "Creator": None}}[fmt]
    try:
        with atomic_path(path, suffix="." + fmt) as tmp:
            fig.savefig(tmp, format=fmt, dpi=dpi, bbox_inches="tight", metadata=meta)
    finally:
        plt.close(fig)


#: Keys up to this many get pairwise distinct colours (more keys reuse them in order).
DISTINCT_KEYS = 48


def _lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 1] (..., 3) -> CIELAB (D65), for colour distances."""
    c = np.where(rgb > 0.04045, ((rgb + 0.055) / 1.055) ** 2.4, rgb / 12.92)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = c @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16 / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]),
                     200 * (f[..., 1] - f[..., 2])], axis=-1)


@functools.lru_cache(maxsize=1)
def _palette() -> np.ndarray:
    """:data:`DISTINCT_KEYS` colours chosen greedily (each the candidate farthest, in CIELAB, from
    those already chosen: Glasbey's method) among light and mid tones, so black labels stay
    readable and neighbouring keys differ."""
    h, sat, val = np.meshgrid(np.arange(36) / 36, [0.3, 0.55, 0.8], [0.7, 0.85, 1.0],
                              indexing="ij")
    rgb = hsv_to_rgb(np.stack([h, sat, val], -1).reshape(-1, 3))
    lab = _lab(rgb)
    keep = (lab[:, 0] >= 52) & (lab[:, 0] <= 88)  # black text readable; never near-white silence
    rgb, lab = rgb[keep], lab[keep]
    chosen = [int(np.argmin(np.abs(lab[:, 0] - 70) + np.abs(lab[:, 1]) + np.abs(lab[:, 2] - 40)))]
    dist = np.linalg.norm(lab - lab[chosen[0]], axis=1)
    while len(chosen) < DISTINCT_KEYS:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(lab - lab[nxt], axis=1))
    return np.hstack([rgb[chosen], np.ones((len(chosen), 1))])


def key_colours(n: int) -> np.ndarray:
    """(n, 4) RGBA colours of keys 0..n-1: pairwise distinct up to :data:`DISTINCT_KEYS` keys."""
    pal = _palette()
    return pal[np.arange(n) % len(pal)]


def draw_keyboard(ax, kb: Keyboard, *, labels: bool = True, alpha: float = 1.0,
                  edge: str = "black", fill: bool = True, offset=(0.0, 0.0),
                  fontsize: float | None = None) -> None:
    """Draw the keys at the reference pose (shifted by ``offset``) on ``ax``, whatever the layout
    (each key's outline polygon; pads as circles). ``fontsize`` None: from the keys' size (at most
    6.5 pt)."""
    colours = key_colours(kb.n_keys)
    off = np.asarray(offset, float)
    discs = kb.shapes.discs
    centres = kb.key_centres() + off
    box = kb.shapes.boxes
    small = float(np.median(np.minimum(box[:, 2] - box[:, 0], box[:, 3] - box[:, 1])))
    if fontsize is None:
        fontsize = float(np.clip(small / 7.5, 4.5, 6.5))
    unit = " bpm" if small >= 45 else ""
    for k, poly in enumerate(kb.key_outlines()):
        face = colours[k] if fill else "none"
        if discs is not None:
            patch = Circle(discs[k, :2] + off, discs[k, 2], facecolor=face, edgecolor=edge, lw=0.8,
                           alpha=alpha)
        else:
            patch = Polygon(poly + off, closed=True, facecolor=face, edgecolor=edge, lw=0.8,
                            alpha=alpha)
        ax.add_patch(patch)
        if labels:
            pitch, tempo = kb.features[k]
            ax.text(*centres[k], f"{kb.names[k]}\n{tempo:.0f}{unit}", ha="center", va="center",
                    fontsize=fontsize)


#: Offsets (points, from the point to the label's lower-left corner; ``None``: the label's width
#: to the left) tried in turn by :func:`place_labels`.
_LABEL_OFFSETS = ((4, 4), (4, -11), (None, 4), (None, -11), (4, 13), (4, -20), (None, 13),
                  (None, -20))


def place_labels(ax, xy: np.ndarray, texts: list[str], fontsize: float = 6.5,
                 avoid: np.ndarray | None = None, **kw) -> int:
    """Label points without letting two labels overlap or cover a point.

    Each label takes the first offset of :data:`_LABEL_OFFSETS` whose box is clear of the labels
    placed before it and of every point (``xy`` and ``avoid``, as a marker of about 8 points);
    a label with no free place, or of a point that is not finite, is left out. Call once the axes'
    limits are final.

    Returns
    -------
    int
        How many labels were left out.
    """
    fig = ax.figure
    fig.canvas.draw()  # the final limits and axes position
    scale = fig.dpi / 72.0  # pixels per point
    pts = np.asarray(xy, float).reshape(-1, 2)
    every = pts if avoid is None else np.vstack([pts, np.asarray(avoid, float).reshape(-1, 2)])
    every = every[np.isfinite(every).all(axis=1)]  # (a point not drawn is no obstacle)
    disp = ax.transData.transform(pts)
    marks = ax.transData.transform(every)
    r = 4.0 * scale
    taken: list[tuple[float, float, float, float]] = [
        (mx - r, my - r, mx + r, my + r) for mx, my in marks]
    skipped = 0
    for (px, py), (x, y), text in zip(disp, pts, texts, strict=True):
        if not (np.isfinite(px) and np.isfinite(py)):
            skipped += 1
            continue
        w, h = 0.62 * fontsize * len(text) * scale, fontsize * scale
        for ox, oy in _LABEL_OFFSETS:
            ox = -4 - w / scale if ox is None else ox
            box = (px + ox * scale, py + oy * scale, px + ox * scale + w, py + oy * scale + h)
            if all(box[2] <= a or box[0] >= c or box[3] <= b or box[1] >= d
                   for a, b, c, d in taken):
                taken.append(box)
                ax.annotate(text, (x, y), textcoords="offset points", xytext=(ox, oy),
                            fontsize=fontsize, **kw)
                break
        else:
            skipped += 1
    return skipped
