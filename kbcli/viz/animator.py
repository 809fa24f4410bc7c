"""The figure of an animation (:class:`Animator`): the pad, the posterior and the curves, drawn
once and updated in place for each frame (blitting: only what moves is redrawn)."""

from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.playing.loop import adaptation_blocks
from kbcli.viz.common import angle_note, external
from kbcli.viz.palette import BELIEF, TRUTH, key_colours
from kbcli.viz.replay import Replay

DYNAMIC_RANGE = 30.0  # nats of log-posterior shown
MIN_ZOOM = 4.0  # px, smallest half-width of the posterior panel
TRAIL = 25  # play touches of a closed loop shown on the pad


def _key_polys(kb: Keyboard) -> list[np.ndarray]:
    """The outline (m_k, 2) of each key at the reference pose, whatever the layout."""
    return kb.key_outlines()


def _moved(family: str, params: np.ndarray, polys: list[np.ndarray],
           centre: np.ndarray) -> list[np.ndarray]:
    flat = transforms.apply(family, params, np.vstack(polys), centre)
    return np.split(flat, np.cumsum([len(p) for p in polys])[:-1])


def _fmt(names: tuple[str, ...], v: np.ndarray) -> str:
    return ", ".join(f"{n} {x:+.1f}" + ("°" if n == "angle" else "") for n, x in
                     zip(names, v, strict=True))



class _Canvas(FigureCanvasAgg):
    """An Agg canvas whose idle redraw is a no-op: each frame is composed by :meth:`Animator.draw`
    (FuncAnimation asks for an idle redraw after every frame it saves)."""

    def draw_idle(self, *args, **kwargs) -> None:
        pass


class Animator:
    """One figure, updated in place for each frame.

    With ``blit``, the figure without its moving artists is drawn once (the background) and each
    frame restores it and draws the moving artists (and the whole posterior panel, whose zoom
    changes) into the canvas buffer, which :class:`_BlitGifWriter` takes as the frame.
    """

    def __init__(self, rep: Replay, dpi: int, blit: bool = False) -> None:
        self.rep = rep
        self.blit = blit
        closed = rep.kind == "closed_loop"
        self.fig = fig = Figure(figsize=(10.0, 6.2), dpi=dpi)
        self.canvas = _Canvas(fig)
        # the pad on the left, its legend below it (outside: inside, it covered touches)
        self.ax_pad = fig.add_subplot(fig.add_gridspec(1, 1, left=0.065, right=0.53, top=0.85,
                                                       bottom=0.22)[0])
        gs = fig.add_gridspec(2, 1, height_ratios=(1.45, 1.0), left=0.6, right=0.925, top=0.82,
                              bottom=0.075, hspace=0.38)
        self.ax_post = fig.add_subplot(gs[0])
        if closed:
            sub = gs[1].subgridspec(2, 1, hspace=0.15)
            self.ax_c1 = fig.add_subplot(sub[0])
            self.ax_c2 = fig.add_subplot(sub[1], sharex=self.ax_c1)
        else:
            self.ax_c1 = fig.add_subplot(gs[1])
            self.ax_c2 = None
        self.title = fig.text(0.5, 0.978, "", ha="center", va="top", fontsize=11,
                              fontweight="bold")
        self.subtitle = fig.text(0.5, 0.938, "", ha="center", va="top", fontsize=9.5)
        self._setup_pad()
        self._setup_posterior()
        self._setup_curves()
        # Blitting: what moves is drawn over a background drawn once per pose of the keyboard
        # (a closed loop has two: before and after the move); the posterior panel is redrawn only
        # when what it shows changes.
        self.moving = [self.belief, self.trail, self.arm_line, self.current, self.sound,
                       *self.cursors, self.dot, self.title, self.subtitle]
        self.moving = [a for a in self.moving if a is not None]
        self._backgrounds: dict[bool, object] = {}
        self._post_cache: tuple | None = None
        if blit:
            for a in (*self.moving, self.ax_post):
                a.set_animated(True)
            for moved in ((False, True) if closed else (True,)):
                self._set_keys(moved)
                self.canvas.draw()  # animated artists are left out
                self._backgrounds[moved] = self.canvas.copy_from_bbox(fig.bbox)

    # -- the pad ------------------------------------------------------------------------------------
    def _setup_pad(self) -> None:
        rep, ax = self.rep, self.ax_pad
        kb = rep.keyboard
        self.polys = _key_polys(kb)
        self.centre = kb.centre
        colors = key_colours(kb.n_keys)  # as in every plot
        known = rep.truth is not None
        self.keys = PolyCollection(self.polys, facecolors=colors if known else "0.85",
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
        handles = [
            Patch(
                fc=key_colours(1)[0] if known else "0.85", ec=TRUTH["color"] if known else "0.6",
                alpha=0.8, label="keyboard, true pose" if known else "keyboard, reference pose "
                "(true pose unknown)"),
            Line2D([], [], **BELIEF, label="robot's belief"),
        ]
        dot = {"marker": "o", "ls": "none", "ms": 5, "mec": "white"}
        if rep.kind == "closed_loop":
            handles += [Line2D([], [], mfc="forestgreen", label="touch: MATCH", **dot),
                        Line2D([], [], mfc="crimson", label="touch: NO_MATCH", **dot),
                        Line2D([], [], mfc="darkorange", label="adaptation touch", **dot)]
        else:
            handles += [Line2D([], [], mfc="black", label="touch: heard a sound", **dot),
                        Line2D([], [], **{**dot, "mfc": "white", "mec": "black"},
                               label="touch: silence")]
        self.arm_line = None
        if rep.arm is not None:
            self.arm_line, = ax.plot([], [], "-o", color="tab:gray", lw=5, ms=6, mfc="0.3",
                                     mec="0.3", solid_capstyle="round", alpha=0.85, zorder=5,
                                     label=rep.arm_note)
            handles.append(self.arm_line)
        for h in handles:  # two columns within the pad's width
            h.set_label(textwrap.fill(h.get_label(), 34))
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.1), fontsize=7,
                  frameon=False, ncol=2, columnspacing=1.0,
                  handlelength=2.4)
        x0, y0, x1, y1 = kb.area
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

    def _truth_at(self, k: int) -> np.ndarray | None:
        rep = self.rep
        if rep.truth is None:
            return None
        if rep.kind == "closed_loop":
            moved = rep.attrs.get("perturbed_at") or 0
            if k <= moved:  # the first `perturbed_at` touches are at the reference pose
                return np.zeros_like(rep.truth)
        return rep.truth

    def _belief_at(self, k: int) -> np.ndarray:
        rep = self.rep
        if k == 0:
            return np.zeros(len(transforms.FAMILIES.get(rep.family).params))
        return rep.belief[k - 1]

    def _moved_at(self, k: int) -> bool:
        """Whether the keyboard is at its true (moved) pose after ``k`` touches."""
        if self.rep.kind == "closed_loop":
            return k > (self.rep.attrs.get("perturbed_at") or 0)
        return True

    def _set_keys(self, moved: bool) -> None:
        """Put the drawn keys at the true pose (``moved``) or at the reference pose."""
        rep = self.rep
        if rep.truth is None:
            return
        pose = rep.truth if moved else np.zeros_like(rep.truth)
        self.keys.set_verts(_moved(rep.world_family, pose, self.polys, self.centre))
        centres = transforms.apply(rep.world_family, pose, rep.keyboard.key_centres(), self.centre)
        for t, (x, y) in zip(self.key_labels, centres, strict=True):
            t.set_position((x, y))

    def _update_pad(self, k: int) -> None:
        rep = self.rep
        self._set_keys(self._moved_at(k))
        b = _moved(rep.family, self._belief_at(k), self.polys, self.centre)
        self.belief.set_segments([np.vstack([p, p[:1]]) for p in b])
        if rep.kind == "closed_loop":
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
            col = np.where(phase[show] == 1, "darkorange",
                           np.where(result[show] == 0, "forestgreen", "crimson"))
        else:
            show = np.arange(k)
            col = np.where(rep.heard[show], "black", "white")
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

    # -- the posterior ------------------------------------------------------------------------------
    def _setup_posterior(self) -> None:
        rep, ax = self.rep, self.ax_post
        self.post_keys = sorted(rep.posteriors)
        if not self.post_keys:
            ax.text(0.5, 0.5, "no posterior recorded\n(closed_loop schema 1)", ha="center",
                    va="center", transform=ax.transAxes, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
            self.image = None
            return
        dx, dy = rep.dx, rep.dy
        self.extent = (dx[0], dx[-1], dy[0], dy[-1])
        first = rep.posteriors[self.post_keys[0]]
        self.image = ax.imshow(first, origin="lower", extent=self.extent, cmap="magma",
                               aspect="equal", interpolation="nearest")
        self.cross, = ax.plot([], [], "x", color="cyan", ms=10, mew=2.2,
                              label="truth" if rep.truth is not None else "_truth")
        self.est, = ax.plot([], [], "o", mfc="none", mec="lime", ms=11, mew=1.8,
                            label="estimate")
        ax.set_xlabel("dx (px)")
        ax.set_ylabel("dy (px)")
        ax.tick_params(labelsize=7.5)
        ax.legend(loc="lower left", fontsize=7.5, framealpha=0.7)
        self.post_title = ax.set_title("", fontsize=9)
        self.post_note = ax.text(0.5, 0.5, "", transform=ax.transAxes, ha="center", va="center",
                                 fontsize=9, visible=False)

    def _update_posterior(self, k: int) -> None:
        if self.image is None:
            return
        rep, ax = self.rep, self.ax_post
        avail = [j for j in self.post_keys if j <= k]
        self.post_note.set_visible(not avail)
        ax.get_legend().set_visible(bool(avail))
        if not avail:
            self.image.set_visible(False)
            self.est.set_data([], [])
            self.cross.set_data([], [])
            self.post_title.set_text(f"{self._post_head()}\nbefore any adaptation")
            self.post_note.set_text("no adaptation yet:\nthe robot plays its melody\nand "
                                    "its detector watches\nfor failures")
            ax.set_xlim(rep.dx[0], rep.dx[-1])
            ax.set_ylim(rep.dy[0], rep.dy[-1])
            return
        j = avail[-1]
        lp = rep.posteriors[j]
        top = float(np.max(lp))
        self.image.set_visible(True)
        self.image.set_data(lp)
        self.image.set_clim(top - DYNAMIC_RANGE, top)
        p = np.exp(lp - top)
        p /= p.sum()
        px, py = p.sum(axis=0), p.sum(axis=1)
        mx, my = float(px @ rep.dx), float(py @ rep.dy)
        sd = float(np.sqrt(px @ (rep.dx - mx) ** 2 + py @ (rep.dy - my) ** 2))
        half = float(np.clip(4 * sd + 1.5, MIN_ZOOM, (rep.dx[-1] - rep.dx[0]) / 2))
        if half >= (rep.dx[-1] - rep.dx[0]) / 2 - 1e-9:
            ax.set_xlim(rep.dx[0], rep.dx[-1])
            ax.set_ylim(rep.dy[0], rep.dy[-1])
        else:
            ax.set_xlim(mx - half, mx + half)
            ax.set_ylim(my - half, my + half)
        truth = self._truth_at(k)
        if truth is not None and (rep.kind == "run" or k > (rep.attrs.get("perturbed_at") or 0)):
            self.cross.set_data([truth[-2]], [truth[-1]])
        else:
            self.cross.set_data([], [])
        if j > 0:
            b = rep.belief[j - 1]
            self.est.set_data([b[-2]], [b[-1]])
        else:
            self.est.set_data([], [])
        if j == 0:
            what = "prior (flat)"
        elif rep.kind == "closed_loop":
            what = f"after touch {j}" + ("" if j == k else " (last adaptation)")
        else:
            what = f"after {j} touch{'es' if j > 1 else ''}" + \
                ("" if j == k else f" (touch {k} not stored)")
        self.post_title.set_text(f"{self._post_head()}\n{what}")

    def _post_head(self) -> str:
        """The posterior panel's first title line: what it shows, and of the angle."""
        note = angle_note(self.rep.family, self.rep.world_family)
        return "posterior of (dx, dy)" + (f", {note}" if note else "")

    # -- the curves ---------------------------------------------------------------------------------
    def _setup_curves(self) -> None:
        rep = self.rep
        if rep.kind == "run":
            ax = self.ax_c1
            t = np.arange(1, rep.n + 1)
            ent = np.asarray(rep.data["entropy"], float)
            ax.plot(t, ent, "-", color="tab:purple", lw=1.6, label="entropy (nats)")
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
            return
        st = rep.data
        phase = np.asarray(st["phase"])
        result = np.asarray(st["result"], float)
        t = np.arange(1, rep.n + 1)
        play = phase == 0
        ok = 1.0 - result[play]
        w = 20
        run = np.convolve(ok, np.ones(w), mode="full")[: len(ok)] / np.minimum(
            np.arange(1, len(ok) + 1), w)
        a1, a2 = self.ax_c1, self.ax_c2
        a1.plot(t[play], run, lw=1.3, color="tab:green", label=f"success (last {w} notes)")
        a1.set_ylim(-0.05, 1.05)
        a1.set_ylabel("success", fontsize=8)
        a2.semilogy(t[play], np.clip(np.asarray(st["score"], float)[play], 1e-12, 1), lw=1.0,
                    color="tab:red", label="detector score")
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
        self.dot = None

    def _update_curves(self, k: int) -> None:
        for c in self.cursors:
            c.set_xdata([k, k])
        if self.dot is not None:
            if k:
                self.dot.set_data([k], [self.rep.data["entropy"][k - 1]])
            else:
                self.dot.set_data([], [])

    # -- titles -------------------------------------------------------------------------------------
    def _update_titles(self, k: int) -> None:
        rep = self.rep
        names = transforms.FAMILIES.get(rep.family).params
        belief = _fmt(names, self._belief_at(k))
        if rep.kind == "run":
            src = " (external robot)" if external(rep.attrs) else ""
            self.title.set_text(f"adaptation{src}: {rep.attrs.get('strategy')} strategy, touch "
                                f"{k} of {rep.n}")
            if k == 0:
                sub = "before the first touch: a flat prior over the displacement"
            else:
                sub = f"heard {rep.labels[k - 1]}; estimate {belief}"
                err = rep.data["errors"][k - 1]
                if rep.truth is not None and np.isfinite(err):
                    sub += f" (truth {_fmt(transforms.FAMILIES.get(rep.world_family).params, rep.truth)}, " \
                           f"error {err:.2f} px)"
            self.subtitle.set_text(sub)
            return
        st = rep.data
        i = k - 1
        phase = int(st["phase"][i])
        moved = rep.attrs.get("perturbed_at")
        where = "keyboard at its reference pose" if moved is not None and k <= moved else \
            "keyboard moved"
        if phase == 1:
            what = f"adapting: heard {rep.labels[i]}; estimate {belief}"
        else:
            res = "MATCH" if int(st["result"][i]) == 0 else "NO_MATCH"
            fired = " — the detector fires" if bool(st["fired"][i]) else ""
            what = f"playing: heard {rep.labels[i]}, {res}{fired}; correction {belief}"
        self.title.set_text(f"closed loop: touch {k} of {rep.n} ({where})")
        self.subtitle.set_text(what)

    def draw(self, k: int) -> None:
        """Show the state after ``k`` touches."""
        self._update_pad(k)
        self._update_posterior(k)
        self._update_curves(k)
        self._update_titles(k)
        if not self.blit:
            return
        canvas = self.canvas
        canvas.restore_region(self._backgrounds[self._moved_at(k)])
        renderer = canvas.get_renderer()
        ax = self.ax_post
        shown = (ax.get_title(), tuple(ax.get_xlim()), tuple(ax.get_ylim()),
                 *(tuple(np.ravel(a.get_data())) for a in (self.cross, self.est))) \
            if self.image is not None else ()
        if self._post_cache is not None and self._post_cache[0] == shown:
            canvas.restore_region(self._post_cache[1])
        else:
            ax.draw(renderer)
            box = ax.get_tightbbox(renderer).expanded(1.02, 1.02)
            self._post_cache = (shown, canvas.copy_from_bbox(box))
        for a in self.moving:
            a.draw(renderer)
