"""The robot's model of the instrument, M_INST: p(sound, action) (paper Sect. III-A).

Every model answers the same questions (the interface: :mod:`kbcli.core.model.classes`), so the
adaptation can use the exact geometry or a learned model interchangeably. This module holds the
interface's raster (:class:`ProbabilityRaster`, which the adaptation indexes instead of calling
the model in its inner loop) and the ``exact`` model; the learned classes derive from
:class:`~kbcli.core.model.pairwise.ModelBase`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.model.sounds import SILENCE, classify_features


@dataclass(frozen=True)
class ProbabilityRaster:
    """p(class | point) sampled on a regular grid over an area.

    Attributes
    ----------
    origin : (2,) ndarray
        Pad coordinates of the centre of cell (0, 0).
    step : float
        Cell size in px.
    probs : (H, W, C) float32 ndarray
        ``probs[i, j]`` is p(class | origin + (j, i) * step) (row i is y, column j is x).
    """

    origin: np.ndarray
    step: float
    probs: np.ndarray

    @property
    def n_classes(self) -> int:
        return self.probs.shape[-1]

    def cell_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest cell (row, col) of each point, and whether it is inside the raster.

        Parameters
        ----------
        points : (..., 2) ndarray

        Returns
        -------
        rows, cols : (...,) int ndarrays (clipped into range)
        inside : (...,) bool ndarray
        """
        u = (np.asarray(points, float) - self.origin) / self.step
        col = np.rint(u[..., 0]).astype(np.int64)
        row = np.rint(u[..., 1]).astype(np.int64)
        h, w = self.probs.shape[:2]
        inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        return np.clip(row, 0, h - 1), np.clip(col, 0, w - 1), inside

    def lookup(self, points: np.ndarray) -> np.ndarray:
        """p(class | point) at the nearest cell; outside the raster, silence with probability 1.

        Parameters
        ----------
        points : (..., 2) ndarray

        Returns
        -------
        (..., C) ndarray
        """
        row, col, inside = self.cell_of(points)
        p = self.probs[row, col]
        if not inside.all():
            p = np.where(inside[..., None], p, np.eye(self.n_classes, dtype=p.dtype)[SILENCE])
        return p

    def argmax(self) -> np.ndarray:
        """(H, W) most probable class of every cell."""
        return np.argmax(self.probs, axis=-1)


class SoundModel(Protocol):
    """What the rest of kbcli needs from a model of the instrument."""

    class_features_: np.ndarray
    match_threshold: float
    area: tuple[float, float, float, float]
    #: True only for the exact model: p(class | point) is the keyboard's own one-hot map.
    exact_map: bool

    def predict_proba(self, points: np.ndarray) -> np.ndarray: ...

    def sample_actions(self, cls: int, n: int, rng: np.random.Generator) -> np.ndarray: ...

    def classify(self, perceived: np.ndarray) -> np.ndarray: ...

    def raster(self, step: float = 1.0) -> ProbabilityRaster: ...


def grid_points(
    area: tuple[float, float, float, float], step: float
) -> tuple[np.ndarray, np.ndarray]:
    """Cell centres covering ``area`` at ``step``: origin (2,) and points (H, W, 2)."""
    x0, y0, x1, y1 = area
    xs = np.arange(x0 + step / 2, x1, step)
    ys = np.arange(y0 + step / 2, y1, step)
    gx, gy = np.meshgrid(xs, ys)
    return np.array([xs[0], ys[0]]), np.stack([gx, gy], axis=-1)


class ExactModel:
    """The keyboard's own geometry as a model: class ``k + 1`` is key ``k``, class 0 silence.

    Used for calibration experiments that separate the estimator's quality from the learned
    model's (``kbcli learn --strategy exact``). Follows the same interface as learned models.
    """

    #: The model is the map itself (callers that can use exact geometry ask this, not the type).
    exact_map = True

    def __init__(self, keyboard: Keyboard) -> None:
        self.keyboard = keyboard
        self.class_features_ = np.vstack([np.full((1, 2), np.nan), keyboard.features])
        self.match_threshold = keyboard.config.match_threshold
        self.area = keyboard.area

    @property
    def n_classes(self) -> int:
        return len(self.class_features_)

    def predict_class(self, points: np.ndarray) -> np.ndarray:
        """(n,) most probable class (here: the true one) at each point."""
        return self.keyboard.key_at(points) + 1

    def predict_proba(self, points: np.ndarray) -> np.ndarray:
        """(n, C) one-hot p(class | point)."""
        return np.eye(self.n_classes)[self.predict_class(points)]

    def classify(self, perceived: np.ndarray) -> np.ndarray:
        return classify_features(perceived, self.class_features_, self.match_threshold)

    def sample_actions(self, cls: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) uniform draws from the region of class ``cls`` within the working area."""
        kb = self.keyboard
        if cls == SILENCE:
            x0, y0, x1, y1 = self.area
            out = np.empty((0, 2))
            while len(out) < n:
                p = rng.uniform((x0, y0), (x1, y1), size=(2 * n + 16, 2))
                out = np.vstack([out, p[kb.key_at(p) < 0]])
            return out[:n]
        if not 1 <= cls < self.n_classes:
            raise ValueError(f"class {cls} out of range 0..{self.n_classes - 1}")
        return kb.sample_in_key(cls - 1, n, rng)

    def raster(self, step: float = 1.0) -> ProbabilityRaster:
        origin, pts = grid_points(self.area, step)
        cls = self.predict_class(pts.reshape(-1, 2)).reshape(pts.shape[:2])
        probs = np.eye(self.n_classes, dtype=np.float32)[cls]
        return ProbabilityRaster(origin=origin, step=float(step), probs=probs)
