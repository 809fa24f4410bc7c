"""Samples of p(action | sound) for the KDE posterior (Algorithm 2, line 3) and their bandwidth.

:class:`ActionSamples` draws each sound's ``N`` actions once and reuses them (``kde_draw =
"shared"``); :class:`FreshSamples` draws them anew at every observation (``"fresh"``); both answer
``get(cls) -> (samples (N, 2), bandwidth px)``. :class:`SilentBeyond` adds the silent pad beyond
the working area to silence's samples (``kde_beyond = "silent"``). Bandwidth: Scott's rule
(:func:`scott_bandwidth`) clipped to ``[resolution, max_bandwidth]``.
"""

from __future__ import annotations

import math

import numpy as np

from kbcli.core.model.sounds import SILENCE

#: The widest kernel of the bandwidth rule (px) and its reach in kernel widths: how far beyond a
#: sample a KDE term is non-zero.
MAX_BANDWIDTH, KERNEL_REACH = 4.0, 4.0


def scott_bandwidth(samples: np.ndarray) -> float:
    """Scott's rule for a 2-D sample, ``sigma_hat * n^(-1/6)``, with Silverman's robust spread
    ``sigma_hat = min(std, IQR / 1.349)`` averaged over both axes; bit for bit numpy's ``std`` and
    ``percentile`` (the quartiles skipped where :func:`_iqr_exceeds` proves them unneeded).
    """
    s = np.asarray(samples, float)
    n = len(s)
    rows = np.ascontiguousarray(s.T)
    std = _std_rows(rows)
    if _iqr_exceeds(rows, std):
        sig = std  # np.minimum(std, iqr / 1.349) is std
    else:
        q75, q25 = _percentile_rows(rows, (0.75, 0.25))
        sig = np.minimum(std, (q75 - q25) / 1.349)
    sig = np.where(sig > 0, sig, std)
    return float(np.mean(sig) * n ** (-1 / 6))


def _iqr_exceeds(rows: np.ndarray, std: np.ndarray) -> bool:
    """Whether ``(q75 - q25) / 1.349 >= std`` holds for every row of ``rows`` (k, n), as
    :func:`_percentile_rows` computes the quartiles, proven by counting without them.

    Bounds ``L < U`` around each row's mean, 5 % further apart than ``1.349 std``: at least
    ``hi25 + 1`` values at or below ``L`` put ``x(hi25) <= L``, at least ``n - lo75`` at or above
    ``U`` put ``x(lo75) >= U``; where numpy's interpolation is monotone in floating point, then
    ``q75 - q25 >= U - L``. False when it cannot tell (the caller computes the quartiles).
    """
    n = rows.shape[1]
    v75, v25 = (n - 1) * 0.75, (n - 1) * 0.25
    lo75, lo25 = int(math.floor(v75)), int(math.floor(v25))
    g75, g25 = v75 - lo75, v25 - lo25
    if n < 4 or g75 >= 0.5 or 0 < g25 < 0.5:
        return False
    hi25 = min(lo25 + 1, n - 1)
    centre = rows.mean(axis=1)
    half = 0.525 * 1.349 * std
    low, high = centre - half, centre + half
    if not ((high - low) / 1.349 >= std).all():
        return False
    below = np.count_nonzero(rows <= low[:, None], axis=1)
    above = np.count_nonzero(rows >= high[:, None], axis=1)
    return bool(((below >= hi25 + 1) & (above >= n - lo75)).all())


def _std_rows(rows: np.ndarray) -> np.ndarray:
    """(k,) population std of each row of a (k, n) array, as ``rows.T.std(axis=0)`` gives it:
    numpy reduces a column by adding the rows in order, which a running sum repeats exactly
    (a row's own ``sum`` would add pairwise and differ in the last bit)."""
    n = rows.shape[1]
    x = rows - np.cumsum(rows, axis=1)[:, -1:] / n
    x *= x
    return np.sqrt(np.cumsum(x, axis=1)[:, -1] / n)


def _percentile_rows(rows: np.ndarray, qs: tuple[float, ...]) -> list[np.ndarray]:
    """Quantiles ``qs`` (fractions) of each row of a (k, n) array, as ``numpy.percentile``'s
    ``linear`` method computes them: the two order statistics around ``(n - 1) q`` (one
    ``partition`` at the lower ones, a ``min`` for the upper ones), then numpy's own
    interpolation."""
    n = rows.shape[1]
    where = []
    for q in qs:
        v = (n - 1) * q
        lo = int(math.floor(v))
        where.append((lo, min(lo + 1, n - 1), v - lo))
    # partition at the lower order statistics only; the one above each is the least of the block
    # that follows it (up to the next partition point): the same value, half the selections
    kth = sorted({lo for lo, _, _ in where})
    part = np.partition(rows, kth, axis=1)
    out = []
    for lo, hi, g in where:
        a = part[:, lo]
        if hi == lo or hi in kth:
            b = part[:, hi]
        else:
            b = part[:, hi:next((k for k in kth if k > lo), n)].min(axis=1)
        d = b - a
        out.append(b - d * (1 - g) if g >= 0.5 else a + d * g)  # numpy's ``_lerp``
    return out


class ActionSamples:
    """Samples of ``p(action | sound)`` per sound class, drawn once and reused (Algorithm 2, line 3).

    Each class's ``n_samples`` actions (and their bandwidth) are drawn the first time the class is
    heard, from its own generator ``default_rng(SeedSequence([*seed, cls]))``: the samples do not
    depend on the order classes are heard, so one cache can serve every run of a model.

    Parameters
    ----------
    model : SoundModel
        ``sample_actions(cls, n, rng)`` draws from p(action | sound).
    bandwidth : float, optional
        Kernel std in px for every class; None: the bandwidth rule per class, clipped to
        ``[resolution, max_bandwidth]``.
    """

    def __init__(self, model, n_samples: int, seed, *, bandwidth: float | None = None,
                 resolution: float = 0.5, max_bandwidth: float = 4.0) -> None:
        self.model = model
        self.n_samples = int(n_samples)
        self.seed = [int(v) for v in np.atleast_1d(seed)]
        self.bandwidth = bandwidth
        self.resolution = float(resolution)
        self.max_bandwidth = float(max_bandwidth)
        self._cache: dict[int, tuple[np.ndarray, float]] = {}

    def get(self, cls: int) -> tuple[np.ndarray, float]:
        """``(samples (N, 2), bandwidth px)`` of class ``cls`` (drawn on first use)."""
        cls = int(cls)
        if cls not in self._cache:
            rng = np.random.default_rng(np.random.SeedSequence([*self.seed, cls]))
            s = np.asarray(self.model.sample_actions(cls, self.n_samples, rng), float)
            self._cache[cls] = (s, _bandwidth(self, s))
        return self._cache[cls]

    def __len__(self) -> int:
        return len(self._cache)

    def draw(self, cls: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) actions resampled (with replacement) from class ``cls``'s samples: draws from
        the empirical p(action | sound) of N model samples, without calling the model again."""
        s, _ = self.get(cls)
        return s[rng.integers(len(s), size=int(n))]


class FreshSamples:
    """The KDE terms' samples drawn anew with ``rng`` at every :meth:`get` (Algorithm 2 as
    written); the interface and parameters of :class:`ActionSamples`, ``source`` being the model
    or a :class:`RasterSampler`."""

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
        return s, _bandwidth(self, s)


def _bandwidth(samples, s: np.ndarray) -> float:
    """``samples.bandwidth``, or the bandwidth rule on ``s`` clipped to ``[resolution,
    max_bandwidth]``."""
    if samples.bandwidth is not None:
        return float(samples.bandwidth)
    res = samples.resolution
    return float(np.clip(scott_bandwidth(s), res, max(res, samples.max_bandwidth)))


class SilentBeyond:
    """Draws of p(action | sound) where the pad beyond the working area is silent.

    With a uniform prior, ``p(action | silence)`` is proportional to ``p(silence | action)``: the
    model's inside its raster (``table``), 1 on the ring of width ``margin`` px around it. Silence's
    ``n`` draws are split between the two by their masses (a binomial draw); every other sound is
    drawn by ``source`` unchanged.
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


def beyond_source(source, options, table, grid, area: tuple[float, float, float, float]):
    """What the KDE posterior draws p(action | sound) from: ``source`` (the model or its raster
    sampler), with ``kde_beyond = "silent"`` (of the KDE's ``options``) wrapped so that silence
    covers the pad beyond the working area as far as the hypotheses of ``grid`` and a kernel reach
    (:class:`SilentBeyond`)."""
    if options.kde_beyond != "silent":
        return source
    bw = options.kde_bandwidth
    reach = KERNEL_REACH * (MAX_BANDWIDTH if bw is None else bw)
    return SilentBeyond(source, table, beyond_margin(grid, area, reach))
