"""The hypothesis grid: a regular grid over the transform parameters (paper Sect. III-D).

``dx, dy`` in ``[-prior_halfwidth, +prior_halfwidth]`` at ``resolution`` px (default +-45 px at
0.5 px: 181 x 181 = 32,761 cells), and for a family that rotates (``rigid``) an extra angle axis in
``[-max_angle, +max_angle]`` at ``angle_resolution`` degrees (default +-5 deg at 0.25 deg: 41 angles,
1,343,201 cells). Array layout is ``[angle,] dy, dx`` (image order: row = dy, column = dx). The
prior is uniform over the grid (:class:`kbcli.core.adaptation.posteriors.posterior.Posterior`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kbcli.core.instrument import transforms

#: Working bytes per hypothesis cell: posterior log-probabilities and probabilities (float64), one
#: update term, and the float / int index temporaries of a gather.
BYTES_PER_CELL = 56


@dataclass(frozen=True)
class HypothesisGrid:
    """A regular grid over the transform parameters of ``family`` (the uniform prior's support).

    Attributes
    ----------
    family : str
        ``translation`` or ``rigid``.
    dx, dy : (n,) ndarray
        Translation values, px (the same for both axes).
    angles : (A,) ndarray
        Angle values, degrees (``[0.0]`` for translation).
    centre : (2,) ndarray
        Rotation centre of the family (the keyboard centre at its reference pose).
    """

    family: str
    dx: np.ndarray
    dy: np.ndarray
    angles: np.ndarray
    centre: np.ndarray

    @classmethod
    def build(
        cls,
        family: str,
        *,
        prior_halfwidth: float,
        resolution: float,
        centre: np.ndarray,
        max_angle: float = 0.0,
        angle_resolution: float = 0.5,
    ) -> HypothesisGrid:
        """A grid of ``+-prior_halfwidth`` px at ``resolution`` (and ``+-max_angle`` degrees)."""
        transforms.check_family(family)
        n = grid_cells_per_axis(prior_halfwidth, resolution)
        t = (np.arange(n) - (n - 1) / 2) * resolution
        if transforms.FAMILIES.get(family).rotates:
            na = grid_cells_per_axis(max_angle, angle_resolution)
            angles = (np.arange(na) - (na - 1) / 2) * angle_resolution
        else:
            angles = np.zeros(1)
        return cls(family, t, t.copy(), angles, np.asarray(centre, float))

    @property
    def resolution(self) -> float:
        return float(self.dx[1] - self.dx[0]) if len(self.dx) > 1 else 1.0

    @property
    def rigid(self) -> bool:
        return transforms.FAMILIES.get(self.family).rotates

    @property
    def shape(self) -> tuple[int, ...]:
        """``(dy, dx)`` or ``(angle, dy, dx)``."""
        s = (len(self.dy), len(self.dx))
        return (len(self.angles),) + s if self.rigid else s

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def n_params(self) -> int:
        return 3 if self.rigid else 2

    def params(self, index: np.ndarray) -> np.ndarray:
        """Parameters of flat cell indices, (k,) -> (k, P) in family order (``[angle,] dx, dy``)."""
        idx = np.unravel_index(np.asarray(index, dtype=np.int64), self.shape)
        if self.rigid:
            return np.column_stack([self.angles[idx[0]], self.dx[idx[2]], self.dy[idx[1]]])
        return np.column_stack([self.dx[idx[1]], self.dy[idx[0]]])

    def index_of(self, params: np.ndarray) -> int:
        """Flat index of the cell nearest to ``params`` (P,) (clipped into the grid)."""
        p = np.asarray(params, float)
        res = self.resolution

        def near(values: np.ndarray, v: float, step: float) -> int:
            return int(np.clip(np.rint((v - values[0]) / step), 0, len(values) - 1))

        ix = near(self.dx, p[-2], res)
        iy = near(self.dy, p[-1], res)
        if self.rigid:
            step = float(self.angles[1] - self.angles[0]) if len(self.angles) > 1 else 1.0
            ia = near(self.angles, p[0], step)
            return int(np.ravel_multi_index((ia, iy, ix), self.shape))
        return int(np.ravel_multi_index((iy, ix), self.shape))


    def around(self, params: np.ndarray) -> tuple[slice, ...]:
        """Index of the block of cells that brackets ``params`` (P,) on every axis (two cells
        per axis, one at the grid's edge or on an axis of one cell): where a point between the
        cells gets its value by interpolation."""
        p = np.asarray(params, float)

        def bracket(values: np.ndarray, v: float) -> slice:
            if len(values) < 2:
                return slice(0, 1)
            step = float(values[1] - values[0])
            i = int(np.clip(np.floor((v - values[0]) / step), 0, len(values) - 2))
            return slice(i, i + 2)

        xy = (bracket(self.dy, p[-1]), bracket(self.dx, p[-2]))
        return (bracket(self.angles, p[0]), *xy) if self.rigid else xy


def grid_cells_per_axis(halfwidth: float, step: float) -> int:
    """Cells of a symmetric axis ``[-halfwidth, +halfwidth]`` at ``step`` (odd, centred on 0)."""
    return 2 * int(math.floor(halfwidth / step + 1e-9)) + 1


def grid_bytes(family: str, prior_halfwidth: float, resolution: float, max_angle: float,
               angle_resolution: float) -> tuple[int, int]:
    """(cells, working bytes) of the hypothesis grid a config asks for."""
    n = grid_cells_per_axis(prior_halfwidth, resolution)
    cells = n * n
    if transforms.FAMILIES.get(family).rotates:
        cells *= grid_cells_per_axis(max_angle, angle_resolution)
    return cells, cells * BYTES_PER_CELL
