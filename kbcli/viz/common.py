"""Shared drawing helpers: saving in the format of the suffix (byte for byte the same each time),
the keyboard with legible key labels, labels of points that do not overlap."""

from __future__ import annotations

import io
import os
import textwrap

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon, Rectangle
from matplotlib.path import Path

from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.instrument.transforms import FAMILIES, apply
from kbcli.io.atomic import write_bytes
from kbcli.io.paths import figure_format
from kbcli.viz.palette import key_colours


def external(attrs: dict) -> bool:
    """Whether a run came from a robot in another process (``kbcli serve``): no ground truth."""
    return attrs.get("source") == "external"


def angle_note(family: str | None, world_family: str | None) -> str:
    """What a figure of the translation posterior says of the angle: "angle marginalised" when the
    estimated ``family`` has one (the panels show its sum over the angle), "angle not estimated"
    when only the keyboard's move (``world_family``) rotates, "" when nothing rotates."""
    def rotates(name: str | None) -> bool:
        return name in FAMILIES and FAMILIES.get(name).rotates

    if rotates(family):
        return "angle marginalised"
    return "angle not estimated" if rotates(world_family) else ""


def moved_outlines(polys: list[np.ndarray], family: str, params: np.ndarray,
                   centre: np.ndarray) -> list[np.ndarray]:
    """Key outlines ``polys`` moved by the transform ``params`` of ``family`` (rotation about
    ``centre``), any layout."""
    flat = apply(family, params, np.vstack(polys), np.asarray(centre, float))
    return np.split(flat, np.cumsum([len(p) for p in polys])[:-1])


def running_mean(x: np.ndarray, window: int) -> np.ndarray:
    """The mean of the last ``window`` values of ``x`` at each point (fewer at the start)."""
    c = np.concatenate([[0.0], np.cumsum(x)])
    i = np.arange(1, len(x) + 1)
    lo = np.maximum(i - window, 0)
    return (c[i] - c[lo]) / np.maximum(i - lo, 1)


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
    buf = io.BytesIO()
    try:  # a fixed salt: the SVG's clip-path and glyph ids are the same from run to run
        with matplotlib.rc_context({"svg.hashsalt": "kbcli"}):
            fig.savefig(buf, format=fmt, dpi=dpi, bbox_inches="tight", metadata=meta)
    finally:
        plt.close(fig)
    # drawn in memory, then written: a full disk fails as one write error, not a zlib traceback
    write_bytes(path, buf.getvalue(), suffix="." + fmt)


#: Font sizes (points) tried for the key labels, largest first: none smaller is ever used.
KEY_FONT_SIZES = (9.0, 8.0, 7.0)
_CHAR_W, _LINE_H = 0.62, 1.25  # a character's width and a line's height, in font sizes


def points_per_unit(ax) -> float:
    """Points per data unit along x of ``ax`` as laid out now (limits and aspect applied)."""
    ax.apply_aspect()
    fig = ax.figure
    width_pt = ax.get_position().width * fig.get_figwidth() * 72.0
    x0, x1 = ax.get_xlim()
    return width_pt / abs(x1 - x0)


#: The label's box probed for containment: corners, edge midpoints and centre (unit half-sizes).
_PROBES = np.array([(x, y) for x in (-1.0, 0.0, 1.0) for y in (-1.0, 0.0, 1.0)])


def _max_font(path: Path, pts: np.ndarray, text: str, ppu: float) -> np.ndarray:
    """(n,) the largest font size (points) at which ``text`` centred on each of ``pts`` stays
    inside ``path`` (10 % wider and taller than its estimated size, and one point clear of the
    edge, for a later re-layout of the figure); 0 where not even a dot would fit."""
    lines = text.split("\n")
    size = np.array([_CHAR_W * max(map(len, lines)), _LINE_H * len(lines)])
    lo, hi = np.zeros(len(pts)), np.full(len(pts), 40.0)
    for _ in range(14):  # bisection, every candidate point at once
        mid = (lo + hi) / 2
        half = (0.55 * mid[:, None] * size + 1.0) / ppu  # data units
        probe = pts[:, None, :] + _PROBES[None] * half[:, None, :]
        ok = path.contains_points(probe.reshape(-1, 2)).reshape(len(pts), -1).all(axis=1)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return lo


def _label_spot(poly: np.ndarray, centre: np.ndarray, text: str, ppu: float
                ) -> tuple[np.ndarray, float]:
    """Where in the key ``poly`` its label has the most room, and the font size that room allows:
    the key's own label point unless a point of an 11 x 11 grid over the key allows a font 10 %
    larger (a piano's white key: its wide lower part, below the black keys)."""
    path = Path(poly)
    (x0, y0), (x1, y1) = poly.min(axis=0), poly.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(x0, x1, 13)[1:-1], np.linspace(y0, y1, 13)[1:-1])
    pts = np.vstack([centre, np.column_stack([gx.ravel(), gy.ravel()])])
    fs = _max_font(path, pts, text, ppu)
    best = int(np.argmax(fs))
    pick = 0 if fs[0] >= fs[best] / 1.1 else best
    return pts[pick], float(fs[pick])


def key_labels(kb: Keyboard, ppu: float, offset=(0.0, 0.0)) -> tuple[list[str], np.ndarray, float]:
    """Each key's label, where to centre it and the font size to draw them at, ``ppu`` points per
    data unit.

    The largest of :data:`KEY_FONT_SIZES` at which every key holds "note / tempo bpm" (then "note /
    tempo") inside its outline (:func:`_label_spot`); at the smallest size, a key too small for
    that holds its note alone, or no label (an empty string): no label is ever smaller than 7
    points or crosses its key's edge.
    """
    off = np.asarray(offset, float)
    polys = [p + off for p in kb.key_outlines()]
    centres = kb.key_centres() + off
    forms = [[f"{n}\n{t:.0f}{unit}" for n, (_, t) in zip(kb.names, kb.features, strict=True)]
             for unit in (" bpm", "")]
    for texts in forms:
        spots = [_label_spot(p, c, t, ppu) for p, c, t in zip(polys, centres, texts, strict=True)]
        room = min(fs for _, fs in spots)
        fits = [fs for fs in KEY_FONT_SIZES if fs <= room]
        if fits:
            return texts, np.array([xy for xy, _ in spots]), fits[0]
    fs = KEY_FONT_SIZES[-1]
    out, where = [], []
    for p, c, t, name in zip(polys, centres, forms[1], kb.names, strict=True):
        for text in (t, name, ""):
            xy, room = _label_spot(p, c, text or name, ppu)
            if room >= fs or not text:
                out.append(text)
                where.append(xy)
                break
    return out, np.array(where), fs


def draw_layout(ax, kb: Keyboard, pad: float, area: bool = True) -> None:
    """The keys, labelled, in the working area widened by ``pad`` px (dashed with ``area``)."""
    x0, y0, x1, y1 = kb.area
    ax.set_xlim(x0 - pad, x1 + pad)  # limits and aspect first: the labels are sized to the keys
    ax.set_ylim(y0 - pad, y1 + pad)
    ax.set_aspect("equal")
    draw_keyboard(ax, kb)
    if area:
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", ec="grey", lw=1))


def draw_keyboard(ax, kb: Keyboard, *, labels: bool = True, alpha: float = 1.0,
                  edge: str = "black", fill: bool = True, offset=(0.0, 0.0)) -> list:
    """Draw the keys at the reference pose (shifted by ``offset``) on ``ax``, whatever the layout
    (each key's outline polygon; pads as circles), in the colours of
    :func:`kbcli.viz.palette.key_colours`.

    With ``labels``, each key's note and tempo at a legible size that fits the key
    (:func:`key_labels`): set the axes' limits and aspect first. Returns the label texts drawn.
    """
    colours = key_colours(kb.n_keys)
    off = np.asarray(offset, float)
    discs = kb.shapes.discs
    for k, poly in enumerate(kb.key_outlines()):
        face = colours[k] if fill else "none"
        if discs is not None:
            patch = Circle(discs[k, :2] + off, discs[k, 2], facecolor=face, edgecolor=edge, lw=0.8,
                           alpha=alpha)
        else:
            patch = Polygon(poly + off, closed=True, facecolor=face, edgecolor=edge, lw=0.8,
                            alpha=alpha)
        ax.add_patch(patch)
    if not labels:
        return []
    texts, where, fontsize = key_labels(kb, points_per_unit(ax), off)
    return [ax.text(*xy, t, ha="center", va="center", fontsize=fontsize)
            for xy, t in zip(where, texts, strict=True) if t]


def fit_title(ax, text: str, fontsize: float = 9.5) -> None:
    """Title ``ax`` with ``text``, each line wrapped at word boundaries to the axes' width (as laid
    out now), so that a long title never runs past the axes' edges."""
    ax.apply_aspect()
    width_pt = ax.get_position().width * ax.figure.get_figwidth() * 72.0
    chars = max(int(width_pt / (0.53 * fontsize)), 20)  # (an average character: ~0.5 em)
    lines = [w for line in text.split("\n") for w in textwrap.wrap(line, chars) or [""]]
    ax.set_title("\n".join(lines), fontsize=fontsize)


#: Offsets (points, from the point to the label's lower-left corner; ``None``: the label's width
#: to the left) tried in turn by :func:`place_labels`.
_LABEL_OFFSETS = ((4, 4), (4, -11), (None, 4), (None, -11), (4, 13), (4, -20), (None, 13),
                  (None, -20))


def place_labels(ax, xy: np.ndarray, texts: list[str], fontsize: float = 6.5,
                 avoid: np.ndarray | None = None, inside: bool = False, margin: float = 0.5,
                 **kw) -> int:
    """Label points without letting two labels overlap or cover a point.

    Each label takes the first offset of :data:`_LABEL_OFFSETS` whose box is clear of the labels
    placed before it and of every point (``xy`` and ``avoid``, as a marker of about 8 points);
    a label with no free place, or of a point that is not finite, is left out; with ``inside``, a
    place must also lie inside the axes. Each label's box counts ``margin`` points wider on every
    side (at least the pad of a background box given in ``bbox``). Call once the axes' limits
    and position are final (after ``tight_layout``). Returns how many labels were left out.
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
    m = margin * scale
    frame = ax.bbox
    taken: list[tuple[float, float, float, float]] = [
        (mx - r, my - r, mx + r, my + r) for mx, my in marks]
    skipped = 0
    for (px, py), (x, y), text in zip(disp, pts, texts, strict=True):
        if not (np.isfinite(px) and np.isfinite(py)):
            skipped += 1
            continue
        w, h = 0.64 * fontsize * len(text) * scale, fontsize * scale
        for ox, oy in _LABEL_OFFSETS:
            ox = -4 - w / scale if ox is None else ox
            x0, y0 = px + ox * scale, py + oy * scale
            box = (x0 - m, y0 - m, x0 + w + m, y0 + h + m)
            if inside and not (frame.x0 <= box[0] and box[2] <= frame.x1 and frame.y0 <= box[1]
                               and box[3] <= frame.y1):
                continue
            if all(box[2] <= a or box[0] >= c or box[3] <= b or box[1] >= d
                   for a, b, c, d in taken):
                taken.append(box)
                ax.annotate(text, (x, y), textcoords="offset points", xytext=(ox, oy),
                            fontsize=fontsize, va="bottom", **kw)
                break
        else:
            skipped += 1
    return skipped
