"""The figure of an animation (:class:`Animator`): the pad, the posterior and the curves
(:mod:`kbcli.viz.panels`), drawn once and updated in place for each frame (blitting: only what
moves is redrawn), under a title saying what happens at each touch."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from kbcli.core.instrument import transforms
from kbcli.viz.common import external
from kbcli.viz.panels import CurvesPanel, PadPanel, PosteriorPanel
from kbcli.viz.replay import Replay


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
        self.title = fig.text(0.5, 0.978, "", ha="center", va="top", fontsize=11, fontweight="bold")
        self.subtitle = fig.text(0.5, 0.938, "", ha="center", va="top", fontsize=9.5)
        self.pad = PadPanel(self.ax_pad, rep)
        self.post = PosteriorPanel(self.ax_post, rep)
        self.curves = CurvesPanel(rep, self.ax_c1, self.ax_c2)
        # Blitting: what moves is drawn over a background drawn once per pose of the keyboard
        # (a closed loop has two: before and after the move); the posterior panel is redrawn only
        # when what it shows changes.
        self.moving = [*self.pad.moving, *self.curves.moving, self.title, self.subtitle]
        self._backgrounds: dict[bool, object] = {}
        self._post_cache: tuple | None = None
        if blit:
            for a in (*self.moving, self.ax_post):
                a.set_animated(True)
            for moved in ((False, True) if closed else (True,)):
                self.pad.set_keys(moved)
                self.canvas.draw()  # animated artists are left out
                self._backgrounds[moved] = self.canvas.copy_from_bbox(fig.bbox)

    # -- titles -------------------------------------------------------------------------------------
    def _update_titles(self, k: int) -> None:
        rep = self.rep
        names = transforms.FAMILIES.get(rep.family).params
        belief = _fmt(names, rep.belief_at(k))
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
        self.pad.update(k)
        self.post.update(k)
        self.curves.update(k)
        self._update_titles(k)
        if not self.blit:
            return
        canvas = self.canvas
        canvas.restore_region(self._backgrounds[self.rep.moved_at(k)])
        renderer = canvas.get_renderer()
        shown = self.post.shown()
        if self._post_cache is not None and self._post_cache[0] == shown:
            canvas.restore_region(self._post_cache[1])
        else:
            self.ax_post.draw(renderer)
            box = self.ax_post.get_tightbbox(renderer).expanded(1.02, 1.02)
            self._post_cache = (shown, canvas.copy_from_bbox(box))
        for a in self.moving:
            a.draw(renderer)
