"""Drawing actions from p(action | sound) (Algorithm 2, line 3; Algorithm 1's ``sampleAction``).

Two sources, both with ``sample_actions(cls, n, rng) -> (n, 2)`` (the model's own signature, so
either stands where a model's sampler is expected):

- the model itself (``model.sample_actions``: rejection sampling, exact, slow for a learned model);
- :class:`RasterSampler`: the model rasterised (a :class:`~kbcli.core.table.LikelihoodTable`, no
  floor): a raster cell drawn with weight p(sound | cell) (the uniform prior over actions makes
  p(action | sound) proportional to it), then a point uniform within the cell. It is the model's
  p(action | sound) to within one raster cell, at about 1 ms per 10,000 draws.

Silence is drawn like any sound over the raster (the model's working area, where it was learned);
so is the model's own sampler. Beyond the working area the pad is silent (the keyboard lies within
it at its reference pose: the likelihood table reads the outside as silence too), which neither
sampler knows: :class:`SilentBeyond` adds that ring to silence's samples, so that a hypothesis that
maps a silent touch beyond the working area is supported, not ruled out because the samples stop
there (``AdapterConfig.kde_beyond = "silent"``, kbcli's reading of what the paper leaves open).

:class:`FreshSamples` serves the KDE posterior's terms with new draws at every observation
(Algorithm 2 as written, ``AdapterConfig.kde_draw = "fresh"``), where
:class:`~kbcli.core.kde.ActionSamples` draws each class once and reuses it (``"shared"``).
"""

from __future__ import annotations

import numpy as np

from kbcli.core.kde import scott_bandwidth
from kbcli.core.sounds import SILENCE

#: Raster cells below this fraction of a class's largest p(sound | cell) are left out of its
#: support. A learned model is positive everywhere: the default model gives every class an
#: outlier floor of 3e-4 per cell, 1.7 % of a key's mass spread over the whole working area. The
#: model's own sampler leaves it out too (it proposes only within the box of the class's training
#: touches); kept, it would act as a random, patchy floor in every KDE term.
TAIL = 1e-2


class RasterSampler:
    """Draws of p(action | sound) from a rasterised model (see the module docstring).

    Rejection sampling over the class's support on the raster (cells holding at least ``TAIL``, 1 %,
    of its largest p(sound | cell)): a cell proposed uniformly among them is accepted with probability
    ``p(sound | cell) / max``, then a point is drawn uniformly within it. Exact for the raster, and
    O(n) (the support's acceptance rate is high: a key's cells are nearly sure of it).

    Parameters
    ----------
    table : LikelihoodTable
        The model raster; its raw probabilities (no outlier floor) weigh the cells.
    """

    def __init__(self, table) -> None:
        self.table = table
        self._support: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
        #: per class, the centres (k, 2) of its support's cells, pad px
        self._centres: dict[int, np.ndarray] = {}

    def support(self, cls: int) -> tuple[np.ndarray, np.ndarray, float]:
        """(flat cell indices, acceptance probabilities, acceptance rate) of class ``cls``
        (built once)."""
        if cls not in self._support:
            t = self.table
            if not 0 <= cls < t.n_classes:
                raise ValueError(f"class {cls} out of range 0..{t.n_classes - 1}")
            w = (t.classes == cls).reshape(-1).astype(np.float32) if t.hard else \
                t.probs[..., cls].reshape(-1)
            top = float(w.max()) if w.size else 0.0
            if top <= 0:
                raise ValueError(f"class {cls} has no support in the model raster")
            cells = np.flatnonzero(w >= TAIL * top)
            acc = w[cells] / np.float32(top)
            self._support[cls] = (cells, acc, float(acc.mean()))
        return self._support[cls]

    def sample_actions(self, cls: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) draws from p(action | sound class ``cls``), pad px.

        Raises
        ------
        ValueError
            If ``cls`` is not a class of the model, or has no support in the raster.
        """
        cls = int(cls)
        cells, acc, rate = self.support(cls)
        n = int(n)
        picked: list[np.ndarray] = []
        have = 0
        while have < n:
            m = int((n - have) / rate * 1.1) + 16
            idx = rng.integers(len(cells), size=m)
            ok = idx[rng.random(m) < np.take(acc, idx)]
            picked.append(ok)
            have += len(ok)
        pick = (picked[0] if len(picked) == 1 else np.concatenate(picked))[:n]
        # uniform within the cell: ``rng.uniform(-0.5, 0.5)`` computes ``-0.5 + 1.0 * random()``,
        # the same draws and bits as ``random() - 0.5``, without its broadcasting overhead
        jitter = rng.random((n, 2))
        jitter -= 0.5
        jitter *= self.table.step
        jitter += np.take(self.centres(cls), pick, axis=0)  # ``centres[pick]``, a faster gather
        return jitter

    def centres(self, cls: int) -> np.ndarray:
        """(k, 2) centres of the cells of class ``cls``'s support (in :meth:`support`'s order),
        pad px (built once)."""
        if cls not in self._centres:
            t = self.table
            row, col = np.divmod(self.support(cls)[0], t.shape[1])
            self._centres[cls] = np.column_stack([t.origin[0] + col * t.step,
                                                  t.origin[1] + row * t.step])
        return self._centres[cls]


class FreshSamples:
    """The KDE terms' samples drawn anew at every call (Algorithm 2 as written).

    Same interface as :class:`~kbcli.core.kde.ActionSamples` (``get(cls) -> (samples, bandwidth)``),
    but every :meth:`get` draws ``n_samples`` new actions from ``source`` with ``rng`` (the
    adapter's own generator: the samples depend on the experiment's seed alone, differ between
    experiments and between observations, and repeat exactly for the same seed).

    Parameters
    ----------
    source : object
        ``sample_actions(cls, n, rng)``: the model or a :class:`RasterSampler`.
    n_samples : int
        N, actions per term.
    rng : numpy.random.Generator
    bandwidth : float, optional
        Kernel std in px; None: Scott's rule on each draw, clipped to
        ``[resolution, max_bandwidth]`` (:mod:`kbcli.core.kde`).
    resolution, max_bandwidth : float
        The clip of the bandwidth rule, px.
    """

    def __init__(self, source, n_samples: int, rng: np.random.Generator, *,
                 bandwidth: float | None = None, resolution: float = 0.5,
                 max_bandwidth: float = 4.0) -> None:
        self.source = source
        self.n_samples = int(n_samples)
        self.rng = rng
        self.bandwidth = bandwidth
        self.resolution = float(resolution)
        self.max_bandwidth = float(max_bandwidth)
        #: draws made so far
        self.draws = 0

    def get(self, cls: int) -> tuple[np.ndarray, float]:
        """``(samples (N, 2), bandwidth px)``: N new draws of p(action | sound ``cls``)."""
        s = np.asarray(self.source.sample_actions(int(cls), self.n_samples, self.rng), float)
        self.draws += 1
        bw = self.bandwidth
        if bw is None:
            res = self.resolution
            bw = float(np.clip(scott_bandwidth(s), res, max(res, self.max_bandwidth)))
        return s, float(bw)


class SilentBeyond:
    """Draws of p(action | sound) where the pad beyond the working area is silent.

    With a uniform prior over actions, ``p(action | silence)`` is proportional to
    ``p(silence | action)``: the model's own answer inside its raster, 1 on the ring of width
    ``margin`` px around it (the pad beyond the keyboard, reached by the hypotheses that move a
    touch back by up to the prior's extent). Silence's ``n`` draws are split between the two by
    their masses (a binomial draw): the ring's area, and the sum of ``p(silence | cell)`` times the
    cell area over the raster. Every other sound is drawn by ``source`` unchanged.

    Parameters
    ----------
    source : object
        ``sample_actions(cls, n, rng)`` inside the working area: the model or a
        :class:`RasterSampler`.
    table : LikelihoodTable
        The model raster: its extent and silence's mass in it.
    margin : float
        Width of the silent ring beyond the raster, px (0: ``source`` alone).
    """

    def __init__(self, source, table, margin: float) -> None:
        self.source = source
        self.margin = max(0.0, float(margin))
        h, w = table.shape
        s = float(table.step)
        x0, y0 = (float(v) - s / 2 for v in table.origin)
        x1, y1 = x0 + w * s, y0 + h * s
        m = self.margin
        #: the ring as four rectangles (x0, y0, x1, y1): below, above, left, right
        self.strips = np.array([[x0 - m, y0 - m, x1 + m, y0], [x0 - m, y1, x1 + m, y1 + m],
                                [x0 - m, y0, x0, y1], [x1, y0, x1 + m, y1]])
        sizes = (self.strips[:, 2] - self.strips[:, 0]) * (self.strips[:, 3] - self.strips[:, 1])
        ring = float(sizes.sum())
        silent = (table.classes == SILENCE).sum() if table.hard else \
            float(np.sum(table.probs[..., SILENCE], dtype=np.float64))
        inside = float(silent) * s * s
        #: the share of silence's mass on the ring
        self.beyond = ring / (ring + inside) if ring > 0 else 0.0
        self._strip_p = sizes / ring if ring > 0 else sizes

    def sample_actions(self, cls: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) draws from p(action | sound ``cls``), pad px (silence: on the ring too)."""
        cls, n = int(cls), int(n)
        if cls != SILENCE or self.beyond <= 0:
            return self.source.sample_actions(cls, n, rng)
        k = int(rng.binomial(n, self.beyond))
        inside = np.asarray(self.source.sample_actions(cls, n - k, rng), float).reshape(-1, 2) \
            if k < n else np.zeros((0, 2))
        strip = self.strips[rng.choice(len(self.strips), size=k, p=self._strip_p)]
        u = rng.random((k, 2))
        ring = strip[:, :2] + u * (strip[:, 2:] - strip[:, :2])
        return np.concatenate([inside, ring])


def beyond_margin(grid, area: tuple[float, float, float, float], reach: float) -> float:
    """How far beyond ``area`` (px) a touch inside it can be moved back by a hypothesis of
    ``grid``, plus ``reach`` (a kernel's): the width of the silent ring :class:`SilentBeyond`
    needs. A translation moves a point by at most the prior's half-width per axis; a rotation of
    the rigid family by up to ``2 r sin(angle / 2)`` more, ``r`` the farthest corner from its
    centre."""
    shift = float(np.max(np.abs(np.concatenate([grid.dx, grid.dy]))))
    x0, y0, x1, y1 = area
    corners = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]], float)
    r = float(np.max(np.hypot(*(corners - np.asarray(grid.centre, float)).T)))
    turn = 2 * r * np.sin(np.radians(float(np.max(np.abs(grid.angles)))) / 2)
    return shift + float(turn) + float(reach)
