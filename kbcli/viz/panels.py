"""The panels of an animation's figure (:class:`~kbcli.viz.animator.Animator`), each drawn once
and updated in place for the state after ``k`` touches: the pad (:class:`PadPanel`), the posterior
(:class:`PosteriorPanel`) and the curves (:class:`CurvesPanel`). Each lists the artists that move
(``moving``), which a blitting animator draws over a background drawn once."""

from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from kbcli.core.instrument import transforms
from kbcli.core.playing.loop import adaptation_blocks
from kbcli.viz.common import angle_note, moved_outlines, running_mean
from kbcli.viz.palette import BELIEF, TRUTH, key_colours
from kbcli.viz.replay import Replay

DYNAMIC_RANGE = 30.0  # nats of log-posterior shown
MIN_ZOOM = 4.0  # px, smallest half-width of the posterior panel
TRAIL = 25  # play touches of a closed loop shown on the pad
WINDOW = 20  # play touches of a closed loop's running success


class PadPanel:
    """The pad: the keys (at the true pose, or the reference pose before a closed loop's move),
    the robot's belief of where they are, the touches, the sound heard and the arm."""

    def __init__(self, ax, rep: Replay) -> None:
        self.ax, self.rep = ax, rep
        kb = rep.keyboard
        self.polys = kb.key_outlines()
        self.centre = kb.centre
        known = rep.truth is not None
        colours = key_colours(kb.n_keys)  # as in every plot
        self.keys = PolyCollection(self.polys, facecolors=colours if known else "0.85",
                                   edgecolors=TRUTH["color"] if known else "0.6",
                                   linewidths=0.8, alpha=0.8 if known else 0.6, zorder=1)
        ax.add_collection(self.keys)
        # note names on the keys (they move with the keyboard in a closed loop)
        self.key_labels = [ax.text(x, y, name, ha="center", va="center", fontsize=7,
                                   color="0.15", zorder=2, clip_on=True)
                           for (x, y), name in zip(kb.key_centres(), kb.names, strict=True)]
        outline = [np.vstack([p, p[:1]]) for p in self.polys]
        self.belief = LineCollection(outline, colors=BELIEF["color"], linewidths=BELIEF["lw"],
                                     linestyles=[BELIEF["ls"]], zorder=3)
        ax.add_collection(self.belief)
        self.trail = ax.scatter([], [], s=22, zorder=4, edgecolors="white", linewidths=0.6)
        self.current = ax.scatter([], [], s=150, marker="*", color="yellow", edgecolors="black",
                                  linewidths=1.0, zorder=7)
        self.sound = ax.annotate("", (0, 0), xytext=(12, 12), textcoords="offset points",
                                 fontsize=10, fontweight="bold", zorder=8,
                                 bbox=dict(boxstyle="round,pad=0.25", fc="white", ec="0.3",
                                           alpha=0.9))
        self.arm_line = None
        if rep.arm is not None:
            self.arm_line, = ax.plot([], [], "-o", color="tab:gray", lw=5, ms=6, mfc="0.3",
                                     mec="0.3", solid_capstyle="round", alpha=0.85, zorder=5,
                                     label=rep.arm_note)
        self._legend(known)
        self._limits()
        self.moving = [a for a in (self.belief, self.trail, self.arm_line, self.current,
                                   self.sound) if a is not None]

    def _legend(self, known: bool) -> None:
        """The legend below the pad (outside: inside, it covered touches), in two columns."""
        handles = [
            Patch(
                fc=key_colours(1)[0] if known else "0.85", ec=TRUTH["color"] if known else "0.6",
                alpha=0.8, label="keyboard, true pose" if known else "keyboard, reference pose "
                "(true pose unknown)"),
            Line2D([], [], **BELIEF, label="robot's belief"),
        ]
        dot = {"marker": "o", "ls": "none", "ms": 5, "mec": "white"}
        if self.rep.kind == "closed_loop":
            handles += [Line2D([], [], mfc="forestgreen", label="touch: MATCH", **dot),
                        Line2D([], [], mfc="crimson", label="touch: NO_MATCH", **dot),
                        Line2D([], [], mfc="darkorange", label="adaptation touch", **dot)]
        else:
            handles += [Line2D([], [], mfc="black", label="touch: heard a sound", **dot),
                        Line2D([], [], **{**dot, "mfc": "white", "mec": "black"},
                               label="touch: silence")]
        if self.arm_line is not None:
            handles.append(self.arm_line)
        for h in handles:  # two columns within the pad's width
            h.set_label(textwrap.fill(h.get_label(), 34))
        self.ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.1),
                       fontsize=7, frameon=False, ncol=2, columnspacing=1.0, handlelength=2.4)

    def _limits(self) -> None:
        """The working area (dotted) and the arm's every pose in view, at equal scales."""
        ax, rep = self.ax, self.rep
        x0, y0, x1, y1 = rep.keyboard.area
        lo = np.array([x0, y0], float)
        hi = np.array([x1, y1], float)
        if rep.arm is not None:
            pts = rep.arm.reshape(-1, 2)
            lo = np.minimum(lo, pts.min(axis=0))
            hi = np.maximum(hi, pts.max(axis=0))
        pad = 0.04 * (hi - lo).max()
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        ax.set_xlabel("pad x (px)")
        ax.set_ylabel("pad y (px)")
        ax.tick_params(labelsize=7.5)
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="0.6", lw=0.6, ls=":",
                               zorder=0))

    def set_keys(self, moved: bool) -> None:
        """Put the drawn keys at the true pose (``moved``) or at the reference pose."""
        rep = self.rep
        if rep.truth is None:
            return
        pose = rep.truth if moved else np.zeros_like(rep.truth)
        self.keys.set_verts(moved_outlines(self.polys, rep.world_family, pose, self.centre))
        centres = transforms.apply(rep.world_family, pose, rep.keyboard.key_centres(), self.centre)
        for t, (x, y) in zip(self.key_labels, centres, strict=True):
            t.set_position((x, y))

    def update(self, k: int) -> None:
        rep = self.rep
        self.set_keys(rep.moved_at(k))
        b = moved_outlines(self.polys, rep.family, rep.belief_at(k), self.centre)
        self.belief.set_segments([np.vstack([p, p[:1]]) for p in b])
        show, col = self._trail(k)
        self.trail.set_offsets(rep.landed[show] if len(show) else np.zeros((0, 2)))
        self.trail.set_facecolors(list(col) if len(show) else [])
        self.trail.set_edgecolors(["black" if c == "white" else "white" for c in col]
                                  if len(show) else [])
        if k:
            p = rep.landed[k - 1]
            self.current.set_offsets(p[None])
            self.sound.set_text(f"heard: {rep.labels[k - 1]}")
            self.sound.xy = (p[0], p[1])
            self.sound.set_visible(True)
        else:
            self.current.set_offsets(np.zeros((0, 2)))
            self.sound.set_visible(False)
        if self.arm_line is not None:
            pts = rep.arm[k - 1] if k else rep.arm[0]
            self.arm_line.set_data(pts[:, 0], pts[:, 1])
            self.arm_line.set_visible(k > 0)

    def _trail(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The touches shown after ``k`` touches and their colours: a run's every touch (black: a
        sound, white: silence); a closed loop's adaptation so far while adapting, else its last
        :data:`TRAIL` play touches (green: MATCH, red: NO_MATCH)."""
        rep = self.rep
        if rep.kind != "closed_loop":
            show = np.arange(k)
            return show, np.where(rep.heard[show], "black", "white")
        phase = np.asarray(rep.data["phase"])[:k]
        result = np.asarray(rep.data["result"])[:k]
        idx = np.arange(k)
        if k and phase[-1] == 1:  # adapting: every touch of this adaptation
            start = k - 1
            while start > 0 and phase[start - 1] == 1:
                start -= 1
            show = idx[start:]
        else:
            show = idx[phase == 0][-TRAIL:]
        return show, np.where(phase[show] == 1, "darkorange",
                              np.where(result[show] == 0, "forestgreen", "crimson"))


class PosteriorPanel:
    """The posterior of the translation after the last stored step, zoomed to where its mass is,
    with the truth and the estimate."""

    def __init__(self, ax, rep: Replay) -> None:
        self.ax, self.rep = ax, rep
        self.post_keys = sorted(rep.posteriors)
        if not self.post_keys:
            ax.text(0.5, 0.5, "no posterior recorded\n(closed_loop schema 1)", ha="center",
                    va="center", transform=ax.transAxes, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
            self.image = None
            return
        self.image = ax.imshow(rep.posteriors[self.post_keys[0]], origin="lower",
                               extent=(rep.dx[0], rep.dx[-1], rep.dy[0], rep.dy[-1]),
                               cmap="magma", aspect="equal", interpolation="nearest")
        self.cross, = ax.plot([], [], "x", color="cyan", ms=10, mew=2.2,
                              label="truth" if rep.truth is not None else "_truth")
        self.est, = ax.plot([], [], "o", mfc="none", mec="lime", ms=11, mew=1.8, label="estimate")
        ax.set_xlabel("dx (px)")
        ax.set_ylabel("dy (px)")
        ax.tick_params(labelsize=7.5)
        ax.legend(loc="lower left", fontsize=7.5, framealpha=0.7)
        self.title = ax.set_title("", fontsize=9)
        self.note = ax.text(0.5, 0.5, "", transform=ax.transAxes, ha="center", va="center",
                            fontsize=9, visible=False)

    def shown(self) -> tuple:
        """What the panel shows now (a blitting animator redraws it only when this changes)."""
        if self.image is None:
            return ()
        ax = self.ax
        return (ax.get_title(), tuple(ax.get_xlim()), tuple(ax.get_ylim()),
                *(tuple(np.ravel(a.get_data())) for a in (self.cross, self.est)))

    def update(self, k: int) -> None:
        if self.image is None:
            return
        rep, ax = self.rep, self.ax
        avail = [j for j in self.post_keys if j <= k]
        self.note.set_visible(not avail)
        ax.get_legend().set_visible(bool(avail))
        if not avail:
            self.image.set_visible(False)
            self.est.set_data([], [])
            self.cross.set_data([], [])
            self.title.set_text(f"{self._head()}\nbefore any adaptation")
            self.note.set_text("no adaptation yet:\nthe robot plays its melody\nand "
                               "its detector watches\nfor failures")
            self._zoom(None)
            return
        j = avail[-1]
        lp = rep.posteriors[j]
        top = float(np.max(lp))
        self.image.set_visible(True)
        self.image.set_data(lp)
        self.image.set_clim(top - DYNAMIC_RANGE, top)
        self._zoom(lp - top)
        if rep.truth is not None and rep.moved_at(k):
            self.cross.set_data([rep.truth[-2]], [rep.truth[-1]])
        else:
            self.cross.set_data([], [])
        if j > 0:
            b = rep.belief_at(j)
            self.est.set_data([b[-2]], [b[-1]])
        else:
            self.est.set_data([], [])
        self.title.set_text(f"{self._head()}\n{self._when(j, k)}")

    def _zoom(self, lp: np.ndarray | None) -> None:
        """Zoom to 4 sd of the posterior (log, its maximum 0) about its mean, at least
        :data:`MIN_ZOOM` px; the whole grid for ``lp`` None or a wide posterior."""
        rep, ax = self.rep, self.ax
        whole = (rep.dx[-1] - rep.dx[0]) / 2
        if lp is not None:
            p = np.exp(lp)
            p /= p.sum()
            px, py = p.sum(axis=0), p.sum(axis=1)
            mx, my = float(px @ rep.dx), float(py @ rep.dy)
            sd = float(np.sqrt(px @ (rep.dx - mx) ** 2 + py @ (rep.dy - my) ** 2))
            half = float(np.clip(4 * sd + 1.5, MIN_ZOOM, whole))
            if not half >= whole - 1e-9:
                ax.set_xlim(mx - half, mx + half)
                ax.set_ylim(my - half, my + half)
                return
        ax.set_xlim(rep.dx[0], rep.dx[-1])
        ax.set_ylim(rep.dy[0], rep.dy[-1])

    def _when(self, j: int, k: int) -> str:
        """The title's second line: after which touch the posterior shown (``j``) is, at ``k``."""
        if j == 0:
            return "prior (flat)"
        if self.rep.kind == "closed_loop":
            return f"after touch {j}" + ("" if j == k else " (last adaptation)")
        return f"after {j} touch{'es' if j > 1 else ''}" + \
            ("" if j == k else f" (touch {k} not stored)")

    def _head(self) -> str:
        """The title's first line: what it shows, and of the angle."""
        note = angle_note(self.rep.family, self.rep.world_family)
        return "posterior of (dx, dy)" + (f", {note}" if note else "")


class CurvesPanel:
    """Below the posterior, with a cursor at the current touch: a run's entropy and error (or the
    mass near the estimate when the truth is unknown); a closed loop's running success and its
    detector's score, the move and each adaptation."""

    def __init__(self, rep: Replay, ax1, ax2=None) -> None:
        self.rep = rep
        self.dot = None
        if rep.kind == "run":
            self._run(ax1)
        else:
            self._loop(ax1, ax2)
        self.moving = [*self.cursors, *([self.dot] if self.dot is not None else [])]

    def _run(self, ax) -> None:
        rep = self.rep
        t = np.arange(1, rep.n + 1)
        ax.plot(t, np.asarray(rep.data["entropy"], float), "-", color="tab:purple", lw=1.6,
                label="entropy (nats)")
        ax.set_ylabel("posterior entropy (nats)", color="tab:purple")
        ax.set_xlabel("touch")
        ax.set_xlim(0.5, max(rep.n, 1) + 0.5)
        ax.grid(alpha=0.3)
        ax2 = ax.twinx()
        err = np.asarray(rep.data["errors"], float)
        if rep.truth is not None and np.isfinite(err).any():
            ax2.semilogy(t, np.maximum(err, 1e-2), "-", color="tab:blue", lw=1.4,
                         label="error (px)")
            ax2.axhline(1.0, color="tab:blue", ls=":", lw=0.8)
            ax2.set_ylabel("error of the estimate (px)", color="tab:blue")
        else:
            ax2.plot(t, np.asarray(rep.data["mass"], float), "-", color="tab:green",
                     lw=1.4, label="mass near the estimate")
            ax2.set_ylim(-0.02, 1.02)
            ax2.set_ylabel("posterior mass within 1 px", color="tab:green")
        ax2.tick_params(labelsize=7.5)
        ax.tick_params(labelsize=7.5)
        self.cursors = [ax.axvline(0, color="0.2", lw=1.0)]
        self.dot, = ax.plot([], [], "o", color="tab:purple", ms=6)

    def _loop(self, a1, a2) -> None:
        rep = self.rep
        phase = np.asarray(rep.data["phase"])
        t = np.arange(1, rep.n + 1)
        play = phase == 0
        ok = 1.0 - np.asarray(rep.data["result"], float)[play]
        a1.plot(t[play], running_mean(ok, WINDOW), lw=1.3, color="tab:green",
                label=f"success (last {WINDOW} notes)")
        a1.set_ylim(-0.05, 1.05)
        a1.set_ylabel("success", fontsize=8)
        a2.semilogy(t[play], np.clip(np.asarray(rep.data["score"], float)[play], 1e-12, 1),
                    lw=1.0, color="tab:red", label="detector score")
        thr = ((rep.config_loop.get("detector") or {}).get("threshold"))
        if thr is not None:
            a2.axhline(thr, color="tab:red", ls=":", lw=0.8)
        a2.set_ylabel("detector\nscore", fontsize=8)
        a2.set_xlabel("touch")
        for ax in (a1, a2):
            moved = rep.attrs.get("perturbed_at")
            if moved is not None:
                ax.axvline(moved + 0.5, color="k", ls="--", lw=0.9)
            for a, b in adaptation_blocks(phase):  # every adaptation, each its own band
                ax.axvspan(t[a] - 0.5, t[b] + 0.5, color="orange", alpha=0.3)
            ax.tick_params(labelsize=7.5)
            ax.grid(alpha=0.3)
        a1.tick_params(labelbottom=False)
        a1.legend(loc="lower left", fontsize=7, framealpha=0.8)
        a2.legend(loc="lower left", fontsize=7, framealpha=0.8)
        a1.set_xlim(0.5, rep.n + 0.5)
        self.cursors = [a1.axvline(0, color="0.2", lw=1.0), a2.axvline(0, color="0.2", lw=1.0)]

    def update(self, k: int) -> None:
        for c in self.cursors:
            c.set_xdata([k, k])
        if self.dot is not None and k:
            self.dot.set_data([k], [self.rep.data["entropy"][k - 1]])
        elif self.dot is not None:
            self.dot.set_data([], [])
