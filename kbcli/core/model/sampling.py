"""Drawing actions from p(action | sound) (Algorithm 2, line 3; Algorithm 1's ``sampleAction``).

Two sources with the model's own signature ``sample_actions(cls, n, rng) -> (n, 2)``: the model
itself (rejection sampling, exact, slow for a learned model) and :class:`RasterSampler`, the model
rasterised (no floor): a cell drawn with weight p(sound | cell), then a point uniform within it,
exact to within one raster cell. Silence is drawn over the model's working area, as by the model's
own sampler; the KDE posterior's samples are :mod:`kbcli.core.adaptation.posteriors.kde.samples`.
"""

from __future__ import annotations

import numpy as np

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






