"""Transform families of the action space (paper Sect. III-B, Eq. 3).

A displacement of the keyboard is a transform ``T`` of the pad: the key that was under ``x`` before
is under ``T(x)`` after. Two families share one code path, chosen by name:

- ``translation``: parameters ``(dx, dy)`` in px; ``T(x) = x + d`` (the paper's).
- ``rigid``: parameters ``(angle, dx, dy)``, angle in degrees counter-clockwise about the keyboard
  centre ``c``; ``T(x) = R(angle) (x - c) + c + d`` (the paper's "more complex parametrization").

Every function is vectorized over points, and :func:`apply_many` / :func:`inverse_many` over
hypotheses too (shapes in the docstrings).
"""

from __future__ import annotations

import numpy as np

from kbcli.errors import ConfigError

FAMILIES: dict[str, tuple[str, ...]] = {
    "translation": ("dx", "dy"),
    "rigid": ("angle", "dx", "dy"),
}


def check_family(family: str) -> tuple[str, ...]:
    """Parameter names of ``family``; raises ``ConfigError`` listing the valid ones."""
    try:
        return FAMILIES[family]
    except KeyError:
        raise ConfigError(
            f"unknown transform family {family!r}; valid: {', '.join(FAMILIES)}"
        ) from None


def wrap_degrees(angle: np.ndarray | float) -> np.ndarray | float:
    """Angles (degrees) wrapped to (-180, 180]: ``wrap_degrees(190) == -170``, ``wrap_degrees(-180)
    == 180``. A float in gives a float out."""
    a = np.asarray(angle, float)
    w = 180.0 - np.mod(180.0 - a, 360.0)
    return float(w) if np.ndim(angle) == 0 else w


def _split(family: str, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., P) params -> angle in radians (...,) and translation (..., 2)."""
    names = check_family(family)
    params = np.asarray(params, float)
    if params.shape[-1] != len(names):
        raise ConfigError(
            f"a {family} transform takes {len(names)} parameters ({', '.join(names)}), "
            f"got {params.shape[-1]}"
        )
    if family == "translation":
        return np.zeros(params.shape[:-1]), params
    return np.deg2rad(params[..., 0]), params[..., 1:]


def _rotate(points: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotate (..., n, 2) points by (...,) angles (radians)."""
    c = np.cos(angle)[..., None]
    s = np.sin(angle)[..., None]
    x, y = points[..., 0], points[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


def apply(family: str, params: np.ndarray, points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``T(points)`` for one transform.

    Parameters
    ----------
    params : (P,) ndarray
    points : (n, 2) ndarray
    centre : (2,) ndarray
        Rotation centre (the keyboard centre at its reference pose).

    Returns
    -------
    (n, 2) ndarray
    """
    return apply_many(family, np.asarray(params, float)[None], points, centre)[0]


def inverse(family: str, params: np.ndarray, points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``T^-1(points)`` for one transform; (n, 2) -> (n, 2)."""
    return inverse_many(family, np.asarray(params, float)[None], points, centre)[0]


def apply_many(
    family: str, params: np.ndarray, points: np.ndarray, centre: np.ndarray
) -> np.ndarray:
    """``T_h(points)`` for many transforms at once.

    Parameters
    ----------
    params : (H, P) ndarray
    points : (n, 2) or (H, n, 2) ndarray

    Returns
    -------
    (H, n, 2) ndarray
    """
    angle, d = _split(family, params)
    centre = np.asarray(centre, float)
    p = np.asarray(points, float)
    if p.ndim == 2:
        p = np.broadcast_to(p, (len(angle),) + p.shape)
    return _rotate(p - centre, angle) + centre + d[:, None, :]


def inverse_many(
    family: str, params: np.ndarray, points: np.ndarray, centre: np.ndarray
) -> np.ndarray:
    """``T_h^-1(points)`` for many transforms; params (H, P), points (n, 2) or (H, n, 2) -> (H, n, 2)."""
    angle, d = _split(family, params)
    centre = np.asarray(centre, float)
    p = np.asarray(points, float)
    if p.ndim == 2:
        p = np.broadcast_to(p, (len(angle),) + p.shape)
    return _rotate(p - centre - d[:, None, :], -angle) + centre


def translation_mapping(
    family: str,
    angle_deg: float,
    source: np.ndarray,
    target: np.ndarray,
    centre: np.ndarray,
) -> np.ndarray:
    """Translations that, with rotation ``angle_deg``, map each ``source`` point onto ``target``.

    This is Algorithm 2's ``computeTransform(a_i, a_t)``: for translation (angle 0) it is
    ``a_t - a_i``; for rigid moves, ``a_t - c - R(angle)(a_i - c)``.

    Parameters
    ----------
    source : (n, 2) ndarray
    target : (2,) or (n, 2) ndarray

    Returns
    -------
    (n, 2) ndarray
    """
    check_family(family)
    src = np.asarray(source, float)
    centre = np.asarray(centre, float)
    rot = _rotate(src - centre, np.asarray(np.deg2rad(angle_deg)))
    return np.asarray(target, float) - centre - rot
