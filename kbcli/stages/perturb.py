"""Stage ``perturb``: move the keyboard to a new pose (paper Sect. III-B, Eq. 3).

A ``scene`` artifact holds the keyboard, the transform family (``translation``: ``(dx, dy)``;
``rigid``: ``(angle, dx, dy)``, :mod:`kbcli.core.instrument.transforms`) and the true parameters,
given or drawn at random by category. It is ground truth: only the simulated world and the
evaluation read it, never the robot's side.

Size categories (one definition for ``perturb``, the adapt benchmark and ``evaluate``; the paper's
"displacements up to 10, 20 and 40 pixels"): ``small``, ``medium`` and ``large`` hold the
translations whose Euclidean norm is in (0, 10], (10, 20] or (20, 40] px (:data:`CATEGORIES`,
:func:`size_category`). A random draw is uniform over the category's ring; a rigid draw also turns
the keyboard by an angle uniform in [-5, 5] degrees about its centre. A displacement that carries
any key outside the arm's workspace is refused with :class:`~kbcli.errors.OutOfReachError`.
"""

from __future__ import annotations

import numpy as np
from pydantic import field_validator, model_validator

from kbcli.core.config import Config, Name, Number, between
from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.errors import ConfigError, OutOfReachError
from kbcli.sim import SimConfig, workspace_check
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import Artifact, ref

#: category -> (exclusive lower, inclusive upper) bound of the displacement's size, px: the Euclidean
#: norm of its translation (see the module docstring).
CATEGORIES: dict[str, tuple[float, float]] = {
    "small": (0.0, 10.0),
    "medium": (10.0, 20.0),
    "large": (20.0, 40.0),
}


#: Largest rotation (degrees) a rigid draw may be given (``max_angle``).
MAX_ANGLE = 180.0


class PerturbConfig(Config):
    """How to move the keyboard: explicit ``params`` of ``family`` (``(dx, dy)`` or
    ``(angle, dx, dy)``, px and degrees) or a random draw of ``category`` (needs a seed), rigid
    draws rotating by at most ``max_angle`` degrees."""

    what = "perturb"

    family: Name = "translation"
    params: tuple[Number, ...] | None = None
    category: Name | None = None
    max_angle: between(Number, 0.0, MAX_ANGLE) = 5.0

    @field_validator("family")
    @classmethod
    def _family(cls, v: str) -> str:
        transforms.check_family(v)
        return v

    @field_validator("category")
    @classmethod
    def _category(cls, v: str | None) -> str | None:
        if v is not None and v not in CATEGORIES:
            raise ConfigError(f"unknown category {v!r}; valid: {', '.join(CATEGORIES)}")
        return v

    @model_validator(mode="after")
    def _one_source(self) -> PerturbConfig:
        if (self.params is None) == (self.category is None):
            raise ConfigError("give either explicit displacement parameters or a category, not both")
        names = transforms.check_family(self.family)
        if self.params is not None and len(self.params) != len(names):
            raise ConfigError(f"a {self.family} displacement takes {len(names)} parameters "
                              f"({', '.join(names)}), got {len(self.params)}")
        return self


def draw(
    category: str, family: str, n: int, *, rng: np.random.Generator, max_angle: float = 5.0
) -> np.ndarray:
    """(n, P) displacements of a category: ``(dx, dy)`` rows, ``(angle, dx, dy)`` for ``rigid``."""
    names = transforms.check_family(family)
    if category not in CATEGORIES:
        raise ConfigError(f"unknown category {category!r}; valid: {', '.join(CATEGORIES)}")
    lo, hi = CATEGORIES[category]
    # uniform over the ring lo < |d| <= hi: the squared radius is uniform on (lo^2, hi^2]
    r = np.sqrt(lo * lo + (hi * hi - lo * lo) * (1.0 - rng.random(n)))
    phi = rng.uniform(0.0, 2 * np.pi, size=n)
    d = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    if len(names) == 3:
        angle = rng.uniform(-max_angle, max_angle, size=(n, 1))
        return np.hstack([angle, d])
    return d


def displacement_size(params: np.ndarray) -> np.ndarray:
    """The size (px) of displacements: the Euclidean norm of the translation, the last two
    parameters ``(dx, dy)`` of any family. ``(..., P) -> (...)``."""
    p = np.asarray(params, float)
    return np.hypot(p[..., -2], p[..., -1])


def size_category(params: np.ndarray) -> str | None:
    """The category (:data:`CATEGORIES`) of one displacement's size, None beyond the largest."""
    size = float(displacement_size(np.asarray(params, float)))
    for name, (lo, hi) in CATEGORIES.items():
        if lo < size <= hi:
            return name
    return None


def key_outline(kb: Keyboard, spacing: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """(m, 2) points along every key's outline at the reference pose (vertices and at most
    ``spacing`` px apart) and (m,) the key of each."""
    return kb.key_outline_points(spacing)


def check_reach(kb: Keyboard, family: str, params: np.ndarray, sim: SimConfig) -> None:
    """Raise OutOfReachError if the displaced keyboard has a key outside the arm's workspace."""
    outline, keys = key_outline(kb)
    pts = transforms.apply(family, np.asarray(params, float), outline, kb.centre)
    ok = workspace_check(sim, pts)
    if not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        key = kb.key_label(int(keys[i]))
        x, y = pts[i]
        shown = ", ".join(f"{n}={v:g}" for n, v in zip(transforms.FAMILIES.get(family).params, params, strict=True))
        raise OutOfReachError(
            f"displacement ({shown}) moves key {key} to ({x:.0f}, {y:.0f}), outside the arm's reach"
        )


def run(cfg: PerturbConfig, keyboard_art: Artifact, *, rng: np.random.Generator,
        seed: int | None = None, sim: SimConfig | None = None) -> Artifact:
    """The scene artifact: the keyboard at its displaced pose.

    ``keyboard_art`` is any artifact whose config holds a ``keyboard`` table; ``rng`` is used only
    for a category draw (``seed``, recorded, is what it was made from). OutOfReachError if a key
    would leave the workspace of the arm ``sim`` (default: ``SimConfig()``).
    """
    sim = SimConfig() if sim is None else sim
    kb = keyboard_stage.load(keyboard_art)
    if cfg.params is not None:
        params = np.asarray(cfg.params, float)
    else:
        params = draw(cfg.category, cfg.family, 1, rng=rng, max_angle=cfg.max_angle)[0]
    check_reach(kb, cfg.family, params, sim)
    names = transforms.FAMILIES.get(cfg.family).params
    moved = transforms.apply(cfg.family, params, kb.key_centres(), kb.centre)
    return Artifact(
        kind="scene",
        config={
            **cfg.to_dict(),
            "params": [float(v) for v in params],
            "keyboard": kb.config.to_dict(),
            "sim": sim.to_dict(),
        },
        seed=seed if cfg.category is not None else None,
        data={"params": params, "key_centres": moved},
        attrs={
            "family": cfg.family,
            "category": cfg.category,
            "param_names": list(names),
            "pose": {n: float(v) for n, v in zip(names, params, strict=True)},
        },
        inputs={"keyboard": ref(keyboard_art)},
    )


def pose(scene_art: Artifact) -> tuple[str, np.ndarray]:
    """The true ``(family, params)`` of a scene artifact: for the world and evaluation only."""
    return scene_art.config["family"], np.asarray(scene_art.config["params"], float)
