"""The colours every figure and animation shares: one colour per key, and the styles of the
keyboard's true pose and of the robot's belief.

:func:`key_colours` gives key ``k`` the same colour in ``kbcli plot keyboard``, ``plot model``,
``plot run``, the layouts' figures and ``kbcli animate``. :data:`TRUTH` and :data:`BELIEF` draw the
keyboard where it really is (solid, dark) and where the robot believes it is (dashed, magenta, on
top): when the two coincide, the dark line still shows between the dashes.
"""

from __future__ import annotations

import functools

import numpy as np
from matplotlib.colors import hsv_to_rgb

#: Keys up to this many get pairwise distinct colours (more keys reuse them in order).
DISTINCT_KEYS = 48

#: The keyboard where it really is: solid and dark.
TRUTH = {"color": "0.1", "ls": "-", "lw": 1.8}
#: Where the robot believes it is: dashed, magenta (darker than any key colour), drawn on top.
BELIEF = {"color": "#d0007a", "ls": (0, (4, 3)), "lw": 1.3}


def _lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 1] (..., 3) -> CIELAB (D65), for colour distances."""
    c = np.where(rgb > 0.04045, ((rgb + 0.055) / 1.055) ** 2.4, rgb / 12.92)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = c @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16 / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]),
                     200 * (f[..., 1] - f[..., 2])], axis=-1)


@functools.lru_cache(maxsize=1)
def _palette() -> np.ndarray:
    """:data:`DISTINCT_KEYS` colours chosen greedily (each the candidate farthest, in CIELAB, from
    those already chosen: Glasbey's method) among light and mid tones, so black labels stay
    readable and neighbouring keys differ."""
    h, sat, val = np.meshgrid(np.arange(36) / 36, [0.3, 0.55, 0.8], [0.7, 0.85, 1.0], indexing="ij")
    rgb = hsv_to_rgb(np.stack([h, sat, val], -1).reshape(-1, 3))
    lab = _lab(rgb)
    keep = (lab[:, 0] >= 52) & (lab[:, 0] <= 88)  # black text readable; never near-white silence
    rgb, lab = rgb[keep], lab[keep]
    chosen = [int(np.argmin(np.abs(lab[:, 0] - 70) + np.abs(lab[:, 1]) + np.abs(lab[:, 2] - 40)))]
    dist = np.linalg.norm(lab - lab[chosen[0]], axis=1)
    while len(chosen) < DISTINCT_KEYS:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(lab - lab[nxt], axis=1))
    return np.hstack([rgb[chosen], np.ones((len(chosen), 1))])


def key_colours(n: int) -> np.ndarray:
    """(n, 4) RGBA colours of keys 0..n-1: pairwise distinct up to :data:`DISTINCT_KEYS` keys."""
    pal = _palette()
    return pal[np.arange(n) % len(pal)]


def map_colours(n: int) -> np.ndarray:
    """RGBA per key index + 2 of a predicted map: -2 (a sound that is no key) grey, -1 (silence)
    white, then the keys' :func:`key_colours`."""
    return np.vstack([(0.6, 0.6, 0.6, 1.0), (1, 1, 1, 1), key_colours(n)])
