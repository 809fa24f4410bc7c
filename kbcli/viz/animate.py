"""Animated replay of an adaptation (``run``) or a closed-loop session (``closed_loop``).

One frame per touch (a closed loop keeps every adaptation touch and a subsample of the play
touches). Left, the pad: the keyboard where it really is (unknown for a real robot: the reference
pose in grey), the robot's current belief of where it is (dashed magenta outline), the arm, the
touches so far and the sound heard at the current one. Top right: the posterior over the
displacement (log scale over 30 nats, the truth a cyan cross). Bottom right: the entropy and the
error (or the posterior mass near the estimate) of an adaptation; the success rate and the
detector score of a closed loop.

Frames are written by :class:`~matplotlib.animation.PillowWriter` (GIF; the static parts drawn once
and only what moves redrawn, :class:`_BlitGifWriter`) or :class:`~matplotlib.animation.FFMpegWriter`
(MP4). What is shown: :mod:`kbcli.viz.replay`; the figure: :mod:`kbcli.viz.animator`.
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib import animation

from kbcli.errors import KbcliError
from kbcli.io.atomic import atomic_path
from kbcli.stages.artifact import Artifact
from kbcli.viz.animator import Animator
from kbcli.viz.replay import frame_plan, load_replay

HOLD_S = 2.0  # seconds the last frame is held
FORMATS = (".gif", ".mp4")


class _BlitGifWriter(animation.PillowWriter):
    """A PillowWriter that takes the frame :class:`~kbcli.viz.animator.Animator` composed in the canvas buffer
    (instead of redrawing the whole figure per frame), and holds the last frame ``hold_ms``."""

    def __init__(self, fps: float, hold_ms: int = 0) -> None:
        super().__init__(fps=fps)
        self.hold_ms = int(hold_ms)

    def grab_frame(self, **savefig_kwargs) -> None:
        from PIL import Image

        canvas = self.fig.canvas
        size = canvas.get_width_height(physical=True)
        im = Image.frombuffer("RGBA", size, bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1)
        self._frames.append(im.convert("RGB"))

    def finish(self) -> None:
        from PIL import Image

        # One palette for all frames (fast octree over a sample of them): no colour flicker, and
        # unchanged pixels stay identical from frame to frame, which keeps the GIF small.
        frames = self._frames
        pick = np.unique(np.linspace(0, len(frames) - 1, min(8, len(frames))).astype(int))
        w, h = frames[0].size
        sample = Image.new("RGB", (w, h * len(pick)))
        for j, i in enumerate(pick):
            sample.paste(frames[i], (0, j * h))
        palette = sample.quantize(256, method=Image.Quantize.FASTOCTREE)
        frames = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
        durations = [int(round(1000 / self.fps))] * len(frames)
        durations[-1] += self.hold_ms
        frames[0].save(self.outfile, save_all=True, append_images=frames[1:],
                       duration=durations, loop=0)


def animate(art: Artifact, path: str | os.PathLike, *, fps: float = 3.0, max_frames: int = 150,
            dpi: int = 80) -> int:
    """Write an animation of a ``run`` or ``closed_loop`` artifact; return the number of frames.

    ``path`` is ``.gif`` (Pillow) or ``.mp4`` (needs ffmpeg); ``fps`` touches per second; at most
    ``max_frames`` touch frames (a long closed loop is subsampled, :func:`frame_plan`). KbcliError
    for another format, no ffmpeg for ``.mp4`` or an artifact without touches.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    writer = make_writer(suffix, fps)
    rep = load_replay(art)
    if rep.n == 0:
        raise KbcliError(f"{art.path or 'artifact'}: holds no touches, nothing to animate")
    frames = frame_plan(rep, max_frames)
    blit = isinstance(writer, _BlitGifWriter)
    if not blit:  # a video holds the last frame by repeating it
        frames += [frames[-1]] * max(int(round(HOLD_S * fps)), 0)
    with matplotlib.rc_context({"font.size": 9}):
        anim = Animator(rep, dpi, blit=blit)
        fa = animation.FuncAnimation(anim.fig, anim.draw, frames=frames, init_func=lambda: None,
                                     blit=False, repeat=False, cache_frame_data=False)
        with atomic_path(path, suffix=suffix) as tmp:
            fa.save(tmp, writer=writer, dpi=dpi)
    return len(frames)


def make_writer(suffix: str, fps: float):
    """The matplotlib writer for ``suffix``; raises KbcliError when it cannot be used."""
    if suffix == ".gif":
        return _BlitGifWriter(fps=fps, hold_ms=int(1000 * HOLD_S))
    if suffix == ".mp4":
        if not animation.writers.is_available("ffmpeg"):
            raise KbcliError("writing .mp4 needs ffmpeg on the PATH, which is not installed "
                             "here: write a .gif instead")
        return animation.FFMpegWriter(fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"])
    raise KbcliError(f"cannot write {suffix or 'a file without an extension'}: animate writes "
                     f"{' or '.join(FORMATS)}")


__all__ = ["animate", "make_writer", "FORMATS"]
