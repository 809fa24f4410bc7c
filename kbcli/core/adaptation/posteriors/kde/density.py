"""The KDE term of one observation (the paper's Eq. 7, Algorithm 2).

Draw ``N`` actions ``a_i ~ p(action | s_t)``, map each onto ``a_t`` with ``computeTransform``
(:func:`kbcli.core.instrument.transforms.translation_mapping`; rigid family: once per grid angle),
bin the hypotheses onto the grid, convolve with a Gaussian kernel by FFT (:func:`binned_kde`), mix
with a uniform floor of weight ``eps`` (:func:`floored_log`) and take the log. As in Algorithm 2,
silence's actions come from the working area only: hypotheses that put the touch beyond it get the
floor.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as sfft

from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.kde.samples import (
    ActionSamples,
    scott_bandwidth,
)
from kbcli.core.instrument import transforms


def _kernel_spectra(sig: np.ndarray, pad: int, size: int) -> np.ndarray:
    """(b, size // 2 + 1) rFFTs of 1-D Gaussian kernels of std ``sig`` (b,) cells, truncated to
    ``|offset| <= pad`` taps and laid out circularly on ``size`` cells (offset 0 at index 0), as a
    density per cell (the caller divides by ``res^2``)."""
    off = np.arange(-pad, pad + 1)
    sig = np.asarray(sig, float)[:, None]
    k1 = np.zeros((len(sig), size))
    k1[:, off % size] = np.exp(-0.5 * (off / sig) ** 2) / (math.sqrt(2 * math.pi) * sig)
    return sfft.rfft(k1, axis=1).astype(np.complex64)


def binned_kde(points: np.ndarray, x0: float, y0: float, res: float, n: int,
               bandwidth: float | np.ndarray) -> np.ndarray:
    """Gaussian KDE of 2-D points on an ``n x n`` grid by linear binning and FFT convolution.

    ``density[..., i, j] ~= mean_k N((x0 + j res, y0 + i res); points[..., k, :], bandwidth^2 I)``
    (Eq. 7 with a Gaussian ``K``), the kernel truncated at 4 standard deviations; points just
    outside the grid still count. Sets of points that share a kernel reach are binned and
    transformed together, each with its own bandwidth: the same numbers as one call per set.

    Parameters
    ----------
    points : (..., N, 2) ndarray
        One or more (leading axes) sets of points, px.
    x0, y0 : float
        Coordinates of grid cell (0, 0) (column 0 is ``x0``, row 0 is ``y0``).
    res : float
        Grid step, px.
    n : int
        Cells per axis.
    bandwidth : float or ndarray of the leading shape
        Kernel std, px: one for every set, or one per set.

    Returns
    -------
    (..., n, n) ndarray
        Density per px^2 (rows y, columns x).
    """
    pts = np.asarray(points, float)
    lead = pts.shape[:-2]
    pts = pts.reshape((-1,) + pts.shape[-2:])
    sig = np.broadcast_to(np.asarray(bandwidth, float).reshape(-1) if np.ndim(bandwidth) else
                          float(bandwidth), (pts.shape[0],)) / res
    pads = np.ceil(4 * sig).astype(np.int64)
    reaches = np.unique(pads)
    if len(reaches) == 1:  # one kernel reach: no gathering of the sets
        return _binned_kde_reach(pts, x0, y0, res, n, int(reaches[0]), sig).reshape(lead + (n, n))
    out = np.empty((pts.shape[0], n, n))
    for pad in reaches:  # one pass per kernel reach (fresh draws: one or two)
        sel = np.flatnonzero(pads == pad)
        out[sel] = _binned_kde_reach(pts[sel], x0, y0, res, n, int(pad), sig[sel])
    return out.reshape(lead + (n, n))


def _binned_kde_reach(pts: np.ndarray, x0: float, y0: float, res: float, n: int, pad: int,
                      sig: np.ndarray) -> np.ndarray:
    """:func:`binned_kde` of (b, N, 2) point sets sharing the kernel reach ``pad`` (cells), each
    with its own kernel std ``sig`` (b,) in cells: (b, n, n) density per px^2."""
    b, npts = pts.shape[0], pts.shape[1]
    m = n + 2 * pad  # widened grid
    # a circular convolution of period >= m gives the inner n x n cells without wrap-around
    size = sfft.next_fast_len(m, real=True)
    # the bin of each point and its offsets in it, in place (the numbers of
    # ``u = (x - x0) / res + pad; iu = floor(u); fu = u - iu``, fewer buffers)
    u = pts[..., 0] - x0
    u /= res
    u += pad
    v = pts[..., 1] - y0
    v /= res
    v += pad
    fu, fv = np.floor(u), np.floor(v)
    ok = (fu >= 0) & (fu < m - 1) & (fv >= 0) & (fv < m - 1)
    iu, base = fu.astype(np.int64), fv.astype(np.int64)
    np.subtract(u, fu, out=fu)
    np.subtract(v, fv, out=fv)
    base += (np.arange(b) * m)[:, None]  # (set * m + iv) * m + iu
    base *= m
    base += iu
    if not ok.all():
        base, fu, fv = base[ok], fu[ok], fv[ok]
    else:
        base, fu, fv = base.ravel(), fu.ravel(), fv.ravel()
    gu, gv = 1 - fu, 1 - fv
    k = len(base)
    idx = np.empty(4 * k, np.int64)
    w = np.empty(4 * k)
    for j, (shift, wa, wb) in enumerate(((0, gu, gv), (1, fu, gv), (m, gu, fv), (m + 1, fu, fv))):
        np.add(base, shift, out=idx[j * k:(j + 1) * k])
        np.multiply(wa, wb, out=w[j * k:(j + 1) * k])
    counts = np.bincount(idx, w, b * m * m).reshape(b * m, m).astype(np.float32)
    # the kernel is separable: convolve the rows, then the columns, each by real 1-D FFTs (single
    # precision: the density's rounding, ~1e-7 of its peak, is far below the outlier floor); only
    # rows holding points are transformed, and only the n inner columns are kept
    spec = _kernel_spectra(sig, pad, size)
    rows = np.flatnonzero(counts.any(axis=1))
    dens = np.zeros((b, n, n))
    if not len(rows):
        return dens
    # (``np.take``: the rows of ``a[rows]``, gathered faster)
    conv = sfft.rfft(np.take(counts, rows, axis=0), n=size, axis=1)
    conv *= np.take(spec, rows // m, axis=0)
    inner = np.zeros((b * m, n), np.float32)
    inner[rows] = sfft.irfft(conv, n=size, axis=1)[:, pad:pad + n]
    sets = np.unique(rows // m)  # sets with a point on the widened grid (the others stay 0)
    inner = inner.reshape(b, m, n)
    cols = sfft.rfft(inner if len(sets) == b else np.take(inner, sets, axis=0), n=size, axis=1)
    cols *= np.take(spec, sets, axis=0)[:, :, None]
    full = sfft.irfft(cols, n=size, axis=1)
    scale = npts * res * res
    for j, i in enumerate(sets):  # one set at a time (it stays in cache)
        np.maximum(full[j, pad:pad + n, :], 0.0, out=dens[i], dtype=np.float64)
        dens[i] /= scale
    return dens


def kde_term(grid: HypothesisGrid, model, action: np.ndarray, cls: int,
             rng: np.random.Generator | None = None, *, n_samples: int, eps: float,
             bandwidth: float | None = None, max_bandwidth: float = 4.0,
             samples: ActionSamples | None = None) -> tuple[np.ndarray, float]:
    """``log KDE_t(h)`` of Algorithm 2 / Eq. 7 on the grid, with the floor ``eps`` (0: none;
    :func:`floored_log`), and the bandwidth used (px).

    The samples are ``samples``' (per-class, drawn once) or, without them, ``n_samples`` fresh
    draws of ``model.sample_actions`` with ``rng``; ``bandwidth`` None: Scott's rule.
    """
    res = grid.resolution
    if samples is not None:
        drawn, bw = samples.get(int(cls))
        bandwidth = bw if bandwidth is None else bandwidth
    else:
        if rng is None:
            raise ValueError("kde_term needs an rng or an ActionSamples cache")
        drawn = np.asarray(model.sample_actions(int(cls), int(n_samples), rng), float)
        if bandwidth is None:
            bandwidth = float(np.clip(scott_bandwidth(drawn), res, max(res, max_bandwidth)))
    term = kde_terms(grid, np.asarray(action, float)[None], drawn[None], [float(bandwidth)], eps)
    return term[0], float(bandwidth)


def kde_terms(grid: HypothesisGrid, actions: np.ndarray, drawn: np.ndarray,
              bandwidths, eps: float) -> np.ndarray:
    """(k, *grid.shape): the log KDE terms of touches at ``actions`` (k, 2), each with its
    samples ``drawn`` (k, N, 2) and kernel std ``bandwidths`` (k,): the same numbers as one
    :func:`kde_term` per touch."""
    a = np.asarray(actions, float)
    drawn = np.asarray(drawn, float)
    k = len(a)
    # computeTransform(a_i, a_t) for every grid angle: (k, A, N, 2)
    if grid.rigid:
        hyp = np.stack([np.stack([transforms.translation_mapping(grid.family, float(th), d, ai,
                                                                 grid.centre)
                                  for th in grid.angles]) for ai, d in zip(a, drawn, strict=True)])
    else:
        hyp = (a[:, None, :] - drawn)[:, None]
    lead = hyp.shape[1]
    bws = np.repeat(np.asarray(bandwidths, float), lead).reshape(k, lead)
    dens = binned_kde(hyp, float(grid.dx[0]), float(grid.dy[0]), grid.resolution, len(grid.dx),
                      bws)
    return floored_log(dens, grid, eps, batch=True, overwrite=True).reshape((k,) + grid.shape)


#: Without a floor, densities below this fraction of a term's peak are read as zero: the
#: single-precision FFT's rounding (:func:`binned_kde`) is about 1e-7 of the peak.
ZERO_RTOL = 1e-6
#: The density a ruled-out hypothesis gets without a floor: a stand-in for zero that keeps the
#: posterior defined when every cell has been ruled out by some touch (those ruled out by the
#: fewest touches then lead; log(1e-300) = -690.8 per ruling-out).
ZERO_DENSITY = 1e-300


def floored_log(dens: np.ndarray, grid: HypothesisGrid, eps: float, *,
                batch: bool = False, overwrite: bool = False) -> np.ndarray:
    """``log((1 - eps) KDE + eps / |prior box|)``; with ``eps`` 0, ``log KDE`` with densities
    below ``ZERO_RTOL`` of the peak read as ``ZERO_DENSITY`` (Eq. 7 without a floor).
    ``batch``: the first axis of ``dens`` holds several terms, each read against its own peak.
    ``overwrite``: compute in ``dens`` (a float64 array of the caller's own; the same numbers)."""
    if eps > 0:
        prior_density = 1.0 / (float(grid.dx[-1] - grid.dx[0]) + grid.resolution) ** 2
        return np.log((1 - eps) * dens + eps * prior_density)
    if not dens.size:
        return np.log(dens)
    if not overwrite:
        axes = tuple(range(1, dens.ndim)) if batch else None
        peak = np.max(dens, axis=axes, keepdims=True)
        return np.log(np.where(dens > ZERO_RTOL * peak, dens, ZERO_DENSITY))
    # in place, one term at a time (it stays in cache); densities are never NaN
    dens = np.ascontiguousarray(dens, dtype=np.float64)
    for term in dens.reshape((len(dens), -1)) if batch else dens.reshape(1, -1):
        np.copyto(term, ZERO_DENSITY, where=term <= ZERO_RTOL * np.max(term))
        np.log(term, out=term)
    return dens
