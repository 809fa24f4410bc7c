"""Figure of a closed-loop session (``kbcli run``): success over time, the detector's score against
its threshold, and the adaptation touches on the keyboard.

Top left: success (running mean over ``window`` play touches), each NO_MATCH, the move, the
detection and the adaptation (shaded). Bottom left: the detector's score (log) with its threshold.
Right: the keyboard at its reference pose (faded), where it really is (solid) and where the robot
believes it is after adapting (dashed, magenta), with the adaptation touches numbered in order.
The title gives the success rates exactly, with their counts.
"""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon

from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.playing.loop import adaptation_blocks
from kbcli.viz.common import draw_keyboard, moved_outlines, place_labels, running_mean, save
from kbcli.viz.palette import BELIEF, TRUTH

PLAY, ADAPT = 0, 1


def _pct(v: float | None, count: tuple[int, int] | None = None) -> str:
    """A rate as an exact percentage: one decimal, never rounded up to 100 % (nor down to 0 %)."""
    if v is None:
        return "n/a"
    txt = f"{100 * v:.1f}"
    if (txt == "100.0" and v < 1) or (txt == "0.0" and v > 0):
        txt = f"{100 * v:.3g}"
    txt = txt.removesuffix(".0")
    return f"{txt}%" + (f" ({count[0]}/{count[1]})" if count else "")


def _gaps(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaN between points whose x are not consecutive, so no line crosses a gap."""
    if len(x) < 2:
        return x.astype(float), y.astype(float)
    cut = np.flatnonzero(np.diff(x) > 1) + 1
    return (np.insert(x.astype(float), cut, np.nan), np.insert(y.astype(float), cut, np.nan))


def _counts(phase: np.ndarray, result: np.ndarray, attrs: dict) -> dict[str, tuple[int, int]]:
    """Counts behind the three success rates (the closed loop's own definitions)."""
    t = np.arange(len(phase))
    play = phase == PLAY
    ok = result == 0
    moved = int(attrs["perturbed_at"])
    fire = attrs.get("detected_at")
    out = {"success_before": play & (t < moved)}
    out["success_after_perturbation"] = play & (t >= moved) & (
        t <= (fire if fire is not None else t[-1] if len(t) else 0))
    if fire is not None:
        nxt = t[(t > fire) & play]
        adapt_t = t[(phase == ADAPT) & (t > fire)]
        end = int(nxt[0]) - 1 if len(nxt) else (int(adapt_t.max()) if len(adapt_t) else None)
        if end is not None:
            out["success_after_adaptation"] = play & (t > end)
    return {k: (int((ok & m).sum()), int(m.sum())) for k, m in out.items()}


def _pose(d: dict) -> tuple[str, np.ndarray]:
    """(family, params) of a pose given as a dict of named parameters (absent ones are 0)."""
    fam = transforms.family_for({"dx": 0.0, "dy": 0.0, **d})
    return fam.name, np.array([d.get(k, 0.0) for k in fam.params], float)


#: Colours of the adaptations' touches on the keyboard, in order (then they repeat).
ADAPT_COLOURS = ("black", "tab:orange", "tab:green", "tab:purple", "tab:brown")


def _fired_lines(ax, phase: np.ndarray, attrs: dict, label: bool) -> None:
    """A line at each touch the detector fired on and an adaptation followed."""
    fired = [first - 1 for first, _ in adaptation_blocks(phase)]
    if not fired and attrs.get("detected_at") is not None:  # (a session cut before adapting)
        fired = [int(attrs["detected_at"])]
    for i, f in enumerate(fired):
        text = None
        if label and i == 0:
            moved = int(attrs["perturbed_at"])
            text = ("detector fired (touch " if len(fired) == 1 else "detector fired (touches ")
            text += ", ".join(map(str, fired[:6])) + (", ..." if len(fired) > 6 else "")
            text += f"; {fired[0] - moved + 1} after the move)" if fired[0] >= moved else ")"
        ax.axvline(f, color="crimson", lw=1, label=text)


def _success_panel(ax, t: np.ndarray, phase: np.ndarray, result: np.ndarray, attrs: dict,
                   window: int) -> None:
    """Top left: the running success, each NO_MATCH, the adaptations, the move, the detection."""
    play = phase == PLAY
    ok = 1.0 - result[play]
    ax.plot(*_gaps(t[play], running_mean(ok, window)), lw=1.4, color="tab:blue",
            label=f"success (mean of the last {window} notes)")
    miss = t[play][ok == 0]
    ax.plot(miss, np.full(len(miss), -0.05), ls="", marker="|", color="crimson", ms=9,
            label=f"NO_MATCH ({len(miss)})")
    blocks = adaptation_blocks(phase)
    for a, b in blocks:
        ax.axvspan(a - 0.5, b + 0.5, color="orange", alpha=0.3, lw=0)
    if blocks:
        sizes = [b - a + 1 for a, b in blocks]
        what = (f"adaptation ({sizes[0]} touches)" if len(sizes) == 1 else
                f"{len(sizes)} adaptations ({' + '.join(map(str, sizes))} touches)")
        ax.plot([], [], color="orange", alpha=0.5, lw=8, label=what)
    moved = attrs["perturbed_at"]
    ax.axvline(moved, color="k", ls="--", lw=1, label=f"keyboard moved (touch {moved})")
    _fired_lines(ax, phase, attrs, label=True)
    ax.set_ylim(-0.12, 1.05)
    ax.set_ylabel("success")
    ax.tick_params(labelbottom=False)
    ax.legend(fontsize=8, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=3, frameon=False)


def _score_panel(ax2, t: np.ndarray, phase: np.ndarray, score: np.ndarray, attrs: dict,
                 config: dict | None) -> None:
    """Bottom left: the detector's score (log) with its threshold."""
    play = phase == PLAY
    ax2.semilogy(*_gaps(t[play], np.clip(score[play], 1e-12, 1)), lw=1, color="tab:purple",
                 label="detector score")
    thr = None
    if config is not None:
        thr = ((config.get("loop") or {}).get("detector") or {}).get("threshold")
    if isinstance(thr, (int, float)) and thr > 0:
        ax2.axhline(thr, color="crimson", ls=":", lw=1.2, label=f"threshold {thr:g} (fires below)")
    ax2.axvline(attrs["perturbed_at"], color="k", ls="--", lw=1)
    _fired_lines(ax2, phase, attrs, label=False)
    for a, b in adaptation_blocks(phase):
        ax2.axvspan(a - 0.5, b + 0.5, color="orange", alpha=0.3, lw=0)
    ax2.set_ylabel("detector score (log)")
    ax2.set_xlabel("touch")
    ax2.legend(fontsize=8, loc="lower left")
    ax2.set_xlim(-1, max(len(t), 1))


def _named(d: dict) -> str:
    return ", ".join(f"{k} {v:+.2f}" for k, v in d.items())


def _touches(ax3, pts: np.ndarray, sizes: list[int]) -> tuple[list[Line2D], np.ndarray, list[str]]:
    """The adaptation touches on the keyboard in order, numbered on through the session's
    adaptations (``sizes`` touches each), each adaptation in its own colour; their labels'
    points and texts (touches within 3 px share one label), to place once the figure is laid out
    (:func:`place_labels`)."""
    handles, start = [], 0
    for i, n in enumerate(sizes):
        p, colour = pts[start:start + n], ADAPT_COLOURS[i % len(ADAPT_COLOURS)]
        ax3.plot(p[:, 0], p[:, 1], "-", color=colour, lw=0.6, alpha=0.6, zorder=4)
        ax3.plot(p[:, 0], p[:, 1], "o", color=colour, ms=4, zorder=4)
        span = f"{start + 1}-{start + n}" if n > 1 else f"{start + 1}"
        handles.append(Line2D([], [], color=colour, marker="o", ms=4, lw=0.6,
                              label=(f"adaptation touches, in order ({span})" if len(sizes) == 1
                                     else f"adaptation {i + 1}: touches {span}")))
        start += n
    groups: dict[tuple[int, int], list[int]] = {}
    for k, (x, y) in enumerate(pts, 1):
        if np.isfinite(x) and np.isfinite(y):
            groups.setdefault((int(round(x / 3)), int(round(y / 3))), []).append(k)
    at = np.array([pts[ks[0] - 1] for ks in groups.values()]).reshape(-1, 2)
    return handles, at, [",".join(map(str, ks)) for ks in groups.values()]


def _keyboard_panel(ax3, kb: Keyboard, steps: dict, phase: np.ndarray, attrs: dict
                    ) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Right: the keyboard where the robot learned it, where it is, where the robot believes it
    is, and the adaptation touches; the keys (both poses) and the touches fill the panel. Returns
    the touch labels' points and texts, and every touch (for :func:`place_labels`)."""
    fam, params = _pose(attrs.get("truth") or {})
    moved_keys = moved_outlines(kb.key_outlines(), fam, params, kb.centre)
    for poly in moved_keys:
        ax3.add_patch(Polygon(poly, closed=True, fill=False, zorder=2, **TRUTH))
    shown = [np.vstack(moved_keys), np.vstack(moved_outlines(kb.key_outlines(), "translation", np.zeros(2), kb.centre))]
    handles = [Patch(facecolor="0.85", edgecolor="0.4", label="where the robot learned it"),
               Line2D([], [], **TRUTH, label="where it is: " + _named(attrs.get("truth") or {}))]
    corr = attrs.get("correction") or {}
    if attrs.get("detected_at") is not None and corr:
        cf, cp = _pose(corr)
        for poly in moved_outlines(kb.key_outlines(), cf, cp, kb.centre):
            ax3.add_patch(Polygon(poly, closed=True, fill=False, zorder=3, **BELIEF))
        handles.append(Line2D([], [], **BELIEF,
                              label="where the robot believes it is: " + _named(corr)))
    at, texts, pts = np.empty((0, 2)), [], np.empty((0, 2))
    if (phase == ADAPT).any():
        pts = np.asarray(steps["landed"], float)[phase == ADAPT]
        shown.append(pts[np.isfinite(pts).all(axis=1)])
        sizes = [b - a + 1 for a, b in adaptation_blocks(phase)]
        more, at, texts = _touches(ax3, pts, sizes)
        handles += more
    x0, y0, x1, y1 = kb.area
    box = np.vstack(shown)
    lo = np.maximum(box.min(axis=0) - 12, (x0, y0))
    hi = np.minimum(box.max(axis=0) + 12, (x1, y1))
    ax3.set_xlim(lo[0], hi[0])
    ax3.set_ylim(lo[1], hi[1])
    ax3.set_aspect("equal")
    draw_keyboard(ax3, kb, labels=False, alpha=0.3)
    ax3.set_xlabel("pad x (px)")
    ax3.set_ylabel("pad y (px)")
    ax3.legend(handles=handles, fontsize=8.5, loc="lower center", bbox_to_anchor=(0.5, 1.01),
               frameon=False, title="the keyboard and the adaptation touches",
               title_fontsize=10, handlelength=3.0)
    return at, texts, pts


def _title(phase: np.ndarray, result: np.ndarray, attrs: dict) -> str:
    """The three success rates, exactly, with their counts when they match them."""
    counts = _counts(phase, result, attrs)

    def rate(key: str) -> str:
        v, n = attrs.get(key), counts.get(key)
        exact = n is not None and v is not None and n[1] and abs(n[0] / n[1] - v) < 1e-9
        return _pct(v, n if exact else None)

    return (f"closed loop: success before the move {rate('success_before')}, after it "
            f"{rate('success_after_perturbation')}, after adaptation "
            f"{rate('success_after_adaptation')}")


def plot_loop(steps: dict, attrs: dict, kb: Keyboard, path: str | os.PathLike, window: int = 20,
              config: dict | None = None) -> None:
    """Draw a closed-loop session (the artifact's ``steps`` group, attrs and config, which holds
    the detector's threshold) to a figure file (format from the suffix)."""
    phase = np.asarray(steps["phase"]).astype(int)
    result = np.asarray(steps["result"]).astype(int)
    score = np.asarray(steps["score"], float)
    t = np.arange(len(phase))
    fig = plt.figure(figsize=(16, 7.6))
    gs = fig.add_gridspec(2, 2, width_ratios=(1.25, 1.0), height_ratios=(1.25, 1.0))
    ax = fig.add_subplot(gs[0, 0])
    _success_panel(ax, t, phase, result, attrs, window)
    _score_panel(fig.add_subplot(gs[1, 0], sharex=ax), t, phase, score, attrs, config)
    ax3 = fig.add_subplot(gs[:, 1])
    at, texts, touches = _keyboard_panel(ax3, kb, steps, phase, attrs)
    fig.suptitle(_title(phase, result, attrs), fontsize=11)
    fig.tight_layout()
    place_labels(ax3, at, texts, fontsize=8.5, avoid=touches, inside=True, margin=1.6, zorder=5,
                 bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
                 arrowprops={"arrowstyle": "-", "color": "0.3", "lw": 0.6, "shrinkA": 0,
                             "shrinkB": 2.5})  # a leader to its touch
    save(fig, path)
