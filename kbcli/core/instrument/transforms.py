"""Transform families of the action space (paper Sect. III-B, Eq. 3).

A displacement of the keyboard is a transform ``T`` of the pad: the key that was under ``x`` before
is under ``T(x)`` after. The families are a registry (:data:`FAMILIES`) of :class:`Family`
entries that share one code path:

- ``translation``: parameters ``(dx, dy)`` in px; ``T(x) = x + d`` (the paper's).
- ``rigid``: parameters ``(angle, dx, dy)``, angle in degrees counter-clockwise about the keyboard
  centre ``c``; ``T(x) = R(angle) (x - c) + c + d`` (the paper's "more complex parametrization").

Every function is vectorized over points, and :func:`apply_many` / :func:`inverse_many` over
hypotheses too (shapes in the docstrings).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kbcli.core.registry import Registry
from kbcli.errors import ConfigError


@dataclass(frozen=True)
class Family:
    """A registered transform family: its parameters and how they split into a rotation and a
    shift.

    Attributes
    ----------
    name : str
    params : tuple of str
        Parameter names, in the order every array of this family's parameters uses.
    rotates : bool
        Whether the first parameter is an angle (degrees, counter-clockwise about the centre).
    """

    name: str
    params: tuple[str, ...]
    rotates: bool

    @property
    def size(self) -> int:
        """Number of parameters."""
        return len(self.params)

    def angle(self, params: np.ndarray) -> float:
        """The rotation (degrees) of one parameter vector (0 for a family that does not rotate)."""
        return float(np.asarray(params, float)[0]) if self.rotates else 0.0

    def shift(self, params: np.ndarray) -> np.ndarray:
        """(..., 2) the translation part of (..., P) parameters."""
        p = np.asarray(params, float)
        return p[..., 1:] if self.rotates else p

    def compose(self, angle: float, shift: np.ndarray) -> np.ndarray:
        """(P,) this family's parameters for a rotation ``angle`` (deg; dropped by a family that
        does not rotate) and a translation ``shift`` (2,)."""
        d = [float(v) for v in np.asarray(shift, float)]
        return np.array([float(angle), *d] if self.rotates else d, float)

    def as_dict(self, params: np.ndarray) -> dict[str, float]:
        """``{name: value}`` of one parameter vector."""
        return {k: float(v) for k, v in zip(self.params, np.asarray(params, float), strict=True)}

    def split(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(..., P) params -> angle in radians (...,) and translation (..., 2)."""
        params = np.asarray(params, float)
        if params.shape[-1] != self.size:
            raise ConfigError(
                f"a {self.name} transform takes {self.size} parameters ({', '.join(self.params)}), "
                f"got {params.shape[-1]}"
            )
        if not self.rotates:
            return np.zeros(params.shape[:-1]), params
        return np.deg2rad(params[..., 0]), params[..., 1:]


#: The transform families (``--family``), read with ``FAMILIES.get(name)``.
FAMILIES: Registry[Family] = Registry("transform family")
FAMILIES.register("translation", Family("translation", ("dx", "dy"), rotates=False),
                  summary="a shift (dx, dy) in px: the paper's")
FAMILIES.register("rigid", Family("rigid", ("angle", "dx", "dy"), rotates=True),
                  summary="a rotation (deg) about the keyboard centre and a shift (dx, dy)")
#: The family a config chooses when it names none (the paper's).
DEFAULT_FAMILY = "translation"


def family_for(params: dict[str, float]) -> Family:
    """The largest family whose parameters are all keys of ``params`` (a stored truth such as
    ``{"angle": 2, "dx": 3, "dy": 0}``)."""
    fits = [fam for _, fam in FAMILIES.items() if set(fam.params) <= set(params)]
    if not fits:
        raise ConfigError(f"no transform family has the parameters {', '.join(params)}")
    return max(fits, key=lambda f: f.size)


def check_family(family: str) -> tuple[str, ...]:
    """Parameter names of ``family``; raises ``ConfigError`` listing the valid ones."""
    return FAMILIES.get(family).params


def wrap_degrees(angle: np.ndarray | float) -> np.ndarray | float:
    """Angles (degrees) wrapped to (-180, 180]: ``wrap_degrees(190) == -170``, ``wrap_degrees(-180)
    == 180``. A float in gives a float out."""
    a = np.asarray(angle, float)
    w = 180.0 - np.mod(180.0 - a, 360.0)
    return float(w) if np.ndim(angle) == 0 else w


def _split(family: str, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., P) params -> angle in radians (...,) and translation (..., 2)."""
    return FAMILIES.get(family).split(params)


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


def translation_mapping(family: str, angle_deg: float, source: np.ndarray, target: np.ndarray,
                        centre: np.ndarray) -> np.ndarray:
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
