"""The simulated world: an arm reaching on a pad, and the keyboard at its (hidden) true pose.

Only this package imports pymunk (in :mod:`kbcli.sim.arm`). The rest of kbcli sees a reacher,
``reach(targets, rng) -> landed finger positions``, and :class:`World`, which turns an action into
what the robot hears. The world holds the ground truth; robot-side code only gets ``World.touch``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kbcli.core.config import check_known
from kbcli.core.keyboard import Keyboard
from kbcli.errors import ConfigError
from kbcli.sim.arms import PRESETS, ArmConfig, arm_config

MODES = ("ideal", "dynamics")


@dataclass(frozen=True, kw_only=True)
class SimConfig:
    """The arm and how it reaches.

    Parameters
    ----------
    mode : str
        ``ideal``: the finger lands exactly on the target (the paper's Sect. IV); ``dynamics``: a
        pymunk two-link arm driven by motors (Sect. IV-C).
    base : tuple of float
        Pad coordinates of the shoulder joint.
    link_lengths : tuple of float
        Upper arm and forearm lengths, px.
    reach_noise : float
        Std (px) of the landing scatter: motor noise in ``dynamics`` mode, Gaussian scatter of the
        landing point in ``ideal`` mode.
    arm : ArmConfig
        How the arm errs beyond ``reach_noise``: servo, friction, finger, proprioception
        (:mod:`kbcli.sim.arms`; default the ``ideal`` preset). A preset name or a table is accepted.
    """

    mode: str = "ideal"
    base: tuple[float, float] = (400.0, 0.0)
    link_lengths: tuple[float, float] = (320.0, 280.0)
    reach_noise: float = 0.0
    arm: ArmConfig = PRESETS["ideal"]

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"unknown mode {self.mode!r}; valid: {', '.join(MODES)}")
        l1, l2 = self.link_lengths
        if not (l1 > 0 and l2 > 0 and np.isfinite(l1) and np.isfinite(l2)):
            raise ConfigError(f"link_lengths must be positive, got {self.link_lengths!r}")
        if not (np.isfinite(self.reach_noise) and self.reach_noise >= 0):
            raise ConfigError(f"reach_noise must be >= 0 px, got {self.reach_noise!r}")
        object.__setattr__(self, "base", (float(self.base[0]), float(self.base[1])))
        object.__setattr__(self, "link_lengths", (float(l1), float(l2)))
        object.__setattr__(self, "arm", arm_config(self.arm))

    def to_dict(self) -> dict:
        return {"mode": self.mode, "base": list(self.base), "link_lengths": list(self.link_lengths),
                "reach_noise": self.reach_noise, "arm": self.arm.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> SimConfig:
        check_known(cls, d, "sim")
        d = dict(d)
        for k in ("base", "link_lengths"):
            if k in d:
                d[k] = tuple(d[k])
        if "arm" in d:
            d["arm"] = arm_config(d["arm"])
        return cls(**d)


def workspace_check(cfg: SimConfig, points: np.ndarray) -> np.ndarray:
    """(n,) bool: whether each point is inside the arm's annular workspace."""
    p = np.asarray(points, float).reshape(-1, 2) - np.asarray(cfg.base)
    r = np.hypot(p[:, 0], p[:, 1])
    l1, l2 = cfg.link_lengths
    return (r >= abs(l1 - l2)) & (r <= l1 + l2) & np.isfinite(r)


def rect_reachable(cfg: SimConfig, rects: np.ndarray) -> np.ndarray:
    """(n,) bool: whether each axis-aligned rectangle lies wholly inside the arm's workspace.

    Parameters
    ----------
    rects : (n, 4) ndarray
        (xmin, ymin, xmax, ymax) rows. The workspace is an annulus: a rectangle is inside when its
        farthest corner is within ``l1 + l2`` of the shoulder and its nearest point is at least
        ``|l1 - l2|`` away.
    """
    r = np.asarray(rects, float).reshape(-1, 4)
    b = np.asarray(cfg.base)
    l1, l2 = cfg.link_lengths
    far = np.hypot(np.maximum(np.abs(r[:, 0] - b[0]), np.abs(r[:, 2] - b[0])),
                   np.maximum(np.abs(r[:, 1] - b[1]), np.abs(r[:, 3] - b[1])))
    nearest = np.column_stack([np.clip(b[0], r[:, 0], r[:, 2]), np.clip(b[1], r[:, 1], r[:, 3])])
    near = np.hypot(*(nearest - b).T)
    return (far <= l1 + l2) & (near >= abs(l1 - l2))


def polygons_reachable(cfg: SimConfig, polygons: list[np.ndarray]) -> np.ndarray:
    """(K,) bool: whether each polygon lies wholly inside the arm's annular workspace.

    The outer limit is a disc (convex): a polygon is within it when all its vertices are. The inner
    limit is a hole: a polygon clears it when the shoulder is outside the polygon and every edge
    stays at least ``|l1 - l2|`` from it.
    """
    from kbcli.core.geometry import points_in_polygon, segment_distance

    b = np.asarray(cfg.base, float)
    l1, l2 = cfg.link_lengths
    out = np.empty(len(polygons), dtype=bool)
    for k, poly in enumerate(polygons):  # one per key
        far = np.hypot(*(np.asarray(poly, float) - b).T).max() <= l1 + l2
        near = (segment_distance(b[None], poly)[0] >= abs(l1 - l2)
                and not points_in_polygon(b[None], poly)[0])
        out[k] = far and near
    return out


def check_keyboard_reachable(cfg: SimConfig, keyboard: Keyboard) -> None:
    """Raise OutOfReachError unless the keyboard's whole working area is within the arm's reach.

    The message names the keys out of reach (or says that only the margin is).
    """
    from kbcli.errors import OutOfReachError

    if rect_reachable(cfg, np.asarray(keyboard.area))[0]:
        return
    bad = ~polygons_reachable(cfg, keyboard.key_outlines())
    l1, l2 = cfg.link_lengths
    x0, y0, x1, y1 = keyboard.area
    where = (f"the working area ({x0:g}, {y0:g})-({x1:g}, {y1:g}) is not all within the arm's "
             f"reach ({abs(l1 - l2):g} to {l1 + l2:g} px from the shoulder at "
             f"({cfg.base[0]:g}, {cfg.base[1]:g}))")
    if bad.any():
        names = [keyboard.key_label(k) for k in np.flatnonzero(bad)]
        shown = ", ".join(names[:12]) + (f" and {len(names) - 12} more" if len(names) > 12 else "")
        raise OutOfReachError(f"{where}: {len(names)} key(s) out of reach: {shown}")
    raise OutOfReachError(f"{where}: every key is reachable but part of the margin is not")


def inverse_kinematics(cfg: SimConfig, targets: np.ndarray) -> np.ndarray:
    """Joint angles (shoulder q1, elbow q2 > 0) that put the fingertip on each target.

    Parameters
    ----------
    targets : (n, 2) ndarray
        Pad points inside the workspace.

    Returns
    -------
    (n, 2) ndarray
        q1 is the upper arm's angle from the pad's x axis, q2 the forearm's angle relative to it.
    """
    p = np.asarray(targets, float).reshape(-1, 2) - np.asarray(cfg.base)
    l1, l2 = cfg.link_lengths
    c2 = (np.sum(p * p, axis=1) - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    q2 = np.arccos(np.clip(c2, -1.0, 1.0))
    q1 = np.arctan2(p[:, 1], p[:, 0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
    return np.column_stack([q1, q2])


def forward_kinematics(cfg: SimConfig, angles: np.ndarray) -> np.ndarray:
    """(n, 2) joint angles -> (n, 2) fingertip positions on the pad."""
    q = np.asarray(angles, float).reshape(-1, 2)
    l1, l2 = cfg.link_lengths
    a = q[:, 0] + q[:, 1]
    return np.asarray(cfg.base) + np.column_stack(
        [l1 * np.cos(q[:, 0]) + l2 * np.cos(a), l1 * np.sin(q[:, 0]) + l2 * np.sin(a)]
    )


def felt_positions(cfg: SimConfig, angles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Where the robot feels its fingertip: the forward kinematics of its encoder readings.

    The encoders read the true joint ``angles`` (n, 2) plus the arm's ``proprio_bias`` and
    Gaussian noise of ``proprio_noise`` rad (no draw when it is 0). Returns (n, 2) px.
    """
    arm = cfg.arm
    q = np.asarray(angles, float).reshape(-1, 2) + np.asarray(arm.proprio_bias)
    if arm.proprio_noise > 0:
        q = q + rng.normal(0.0, arm.proprio_noise, size=q.shape)
    return forward_kinematics(cfg, q)


def contact_points(cfg: SimConfig, landed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Where the pad registers each touch: uniform in the finger's contact disc around ``landed``
    (the landed points themselves, and no draw, for a point finger)."""
    p = np.asarray(landed, float).reshape(-1, 2)
    r = cfg.arm.finger_radius
    if r <= 0 or len(p) == 0:
        return p
    u = rng.random((len(p), 2))
    rho, phi = r * np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    return p + np.column_stack([rho * np.cos(phi), rho * np.sin(phi)])


class IdealReacher:
    """The finger lands on the target (plus optional Gaussian scatter of ``reach_noise`` px).

    Attributes
    ----------
    last_felt : (n, 2) ndarray
        Where the robot felt each landing of the last :meth:`reach` call (the landings themselves
        unless the arm's proprioception is imperfect).
    last_angles : (n, 2) ndarray
        True joint angles at each landing of the last call.
    """

    def __init__(self, cfg: SimConfig) -> None:
        self.cfg = cfg
        self.last_felt = np.empty((0, 2))
        self.last_angles = np.empty((0, 2))

    def reach(self, targets: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) targets -> (n, 2) landed finger positions. Raises OutOfReachError."""
        from kbcli.errors import OutOfReachError

        t = np.asarray(targets, float).reshape(-1, 2)
        ok = workspace_check(self.cfg, t)
        if not ok.all():
            bad = t[~ok][0]
            raise OutOfReachError(f"target ({bad[0]:.1f}, {bad[1]:.1f}) is outside the arm's workspace")
        if self.cfg.reach_noise > 0:
            t = t + rng.normal(0.0, self.cfg.reach_noise, size=t.shape)
        self.last_angles = inverse_kinematics(self.cfg, t)
        arm = self.cfg.arm
        if arm.proprio_noise > 0 or arm.proprio_bias != (0.0, 0.0):
            self.last_felt = felt_positions(self.cfg, self.last_angles, rng)
        else:
            self.last_felt = t.copy()
        return t


def keys_heard_when_felt(cfg: SimConfig, keyboard: Keyboard, felt: np.ndarray, samples: int,
                         rng: np.random.Generator) -> np.ndarray:
    """Ground truth of p(key | where the robot *feels* it touched), by Monte Carlo.

    For a robot that feels its fingertip at ``felt`` (n, 2), the finger truly is at the forward
    kinematics of the encoder readings minus their bias and noise, and the pad hears it anywhere in
    the finger's contact disc: draw ``samples`` such touches per point (the keyboard at its
    reference pose). What a model of p(sound | action) should predict, where the action is the felt
    position (the robot never knows better). For an arm that senses exactly, every draw is the key
    under ``felt`` and no random number is used.

    Returns
    -------
    (n, samples) int ndarray
        Key index of each draw, -1 for silence.
    """
    f = np.asarray(felt, float).reshape(-1, 2)
    n = len(f)
    if cfg.arm.senses_exactly:
        return np.repeat(keyboard.key_at(f)[:, None], samples, axis=1)
    arm = cfg.arm
    q = inverse_kinematics(cfg, f)[:, None, :] - np.asarray(arm.proprio_bias)
    if arm.proprio_noise > 0:
        q = q + rng.normal(0.0, arm.proprio_noise, size=(n, samples, 2))
    else:
        q = np.broadcast_to(q, (n, samples, 2))
    landed = forward_kinematics(cfg, q.reshape(-1, 2))
    contact = contact_points(cfg, landed, rng)
    return keyboard.key_at(contact).reshape(n, samples)


def make_reacher(cfg: SimConfig):
    """The reacher for ``cfg.mode``."""
    if cfg.mode == "ideal":
        return IdealReacher(cfg)
    from kbcli.sim.arm import DynamicsReacher  # pymunk only loads when asked for

    return DynamicsReacher(cfg)


@dataclass
class World:
    """The keyboard at its true pose, an arm and a perception channel.

    ``touch`` is all the robot side may call: it reaches for the actions and returns where the
    robot *feels* its finger landed (proprioception) and the perceived sound features (NaN rows
    for silence). The pad hears at the finger's contact point (:func:`contact_points`). Where the
    finger truly landed stays on the world's side (``last_landed``), for evaluation only.
    """

    keyboard: Keyboard
    reacher: object
    pose: np.ndarray | None = None
    family: str = "translation"
    touches: int = field(default=0, init=False)
    last_landed: np.ndarray = field(default_factory=lambda: np.empty((0, 2)), init=False)

    def touch(self, actions: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(n, 2) actions -> felt landing positions (n, 2), perceived features (n, D)."""
        landed = self.reacher.reach(np.asarray(actions, float).reshape(-1, 2), rng)
        self.touches += len(landed)
        self.last_landed = landed
        cfg = getattr(self.reacher, "cfg", None)
        contact = landed if cfg is None else contact_points(cfg, landed, rng)
        heard = self.keyboard.perceive(contact, self.pose, self.family, rng=rng)
        felt = getattr(self.reacher, "last_felt", None)
        return (landed if felt is None or len(felt) != len(landed) else felt), heard
