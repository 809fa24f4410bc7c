"""Arm presets: how a simulated arm errs (its servo, its joints, its finger, its proprioception).

A real arm does not land where it aims, and does not land where it *feels* it landed. An
:class:`ArmConfig` describes four sources of error, each optional, and :data:`PRESETS` names three
arms built from them (``kbcli ... --arm NAME`` or an ``[arm]`` TOML table with ``preset = NAME``
and any field to override):

``ideal``
    No error at all: in ``ideal`` mode the finger lands on the target, in ``dynamics`` mode the
    pymunk arm's velocity servo settles within about 0.01 px. The robot feels exactly where it
    landed. This is the paper's idealised problem and kbcli's historical arm.
``servo``
    Finite servo gains and joint friction (``dynamics`` mode): each joint is driven by a
    torque-level PD controller ``tau = kp * e - kd * w`` (bounded by ``max_torque``) against a
    Coulomb friction torque ``friction``; the joint sticks as soon as ``kp * |e|`` no longer
    beats the friction, so it stops short of its target by up to ``friction / kp`` rad, on the side
    it came from: the tracking error depends on the reach (where the arm came from, how far it
    went). A reach also gives up after ``settle_time`` seconds. Perception stays exact.
``realistic``
    ``servo`` plus a finger of finite contact radius and imperfect proprioception: the pad
    registers the touch at a point uniform in the finger's contact disc of ``finger_radius`` px
    (near a boundary a fat finger can sound either key), and the joint encoders read
    ``q + proprio_bias + N(0, proprio_noise^2)`` rad: the servo drives the *measured* angles to
    their targets, and the robot feels the fingertip at the forward kinematics of the measured
    angles. Where it feels it landed differs from where it landed by 1 to 3 px (median), so
    feeling the landing no longer removes the error (``kbcli bench arm`` prints the
    distributions).

In ``ideal`` mode (no physics) the servo fields are ignored; the finger and the proprioception
apply as in ``dynamics`` mode (the encoders then read the inverse kinematics of the landing point).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

from kbcli.core.config import check_known
from kbcli.errors import ConfigError


def _num(name: str, v: Any, *, positive: bool = False) -> float:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    if not ok or v < 0 or (positive and v == 0):
        rel = "> 0" if positive else ">= 0"
        raise ConfigError(f"arm.{name} must be a finite number {rel}, got {v!r}")
    return float(v)


@dataclass(frozen=True, kw_only=True)
class ArmConfig:
    """How a simulated arm errs (see the module docstring).

    Parameters
    ----------
    preset : str
        The preset these values started from (``ideal``, ``servo``, ``realistic``) or ``custom``.
    kp : float or None
        Stiffness of the torque servo (torque per rad); None: the ideal velocity servo.
    kd : float
        Damping of the torque servo (torque per rad/s).
    max_torque : float
        Bound of each joint's servo torque.
    friction : float
        Coulomb friction torque of each joint.
    settle_time : float
        A reach gives up after this many simulated seconds.
    finger_radius : float
        Radius (px) of the finger's contact disc on the pad.
    proprio_noise : float
        Std (rad) of each joint encoder's reading at a touch.
    proprio_bias : tuple of float
        Constant offset (rad) of the shoulder and elbow encoders.
    """

    preset: str = "ideal"
    kp: float | None = None
    kd: float = 0.0
    max_torque: float = 5e8
    friction: float = 0.0
    settle_time: float = 8.0
    finger_radius: float = 0.0
    proprio_noise: float = 0.0
    proprio_bias: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not isinstance(self.preset, str) or not self.preset:
            raise ConfigError(f"arm.preset must be a name, got {self.preset!r}")
        if self.kp is not None:
            _num("kp", self.kp, positive=True)
        _num("kd", self.kd)
        _num("max_torque", self.max_torque, positive=True)
        _num("friction", self.friction)
        _num("settle_time", self.settle_time, positive=True)
        _num("finger_radius", self.finger_radius)
        _num("proprio_noise", self.proprio_noise)
        b = self.proprio_bias
        if isinstance(b, (str, bytes)) or not hasattr(b, "__len__") or len(b) != 2:
            raise ConfigError(f"arm.proprio_bias must be two numbers (rad), got {b!r}")
        vals = []
        for v in b:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ConfigError(f"arm.proprio_bias must be two finite numbers (rad), got {b!r}")
            vals.append(float(v))
        if max(abs(v) for v in vals) > 0.1:
            raise ConfigError(f"arm.proprio_bias must be within +-0.1 rad, got {b!r}")
        if self.proprio_noise > 0.1:
            raise ConfigError(f"arm.proprio_noise must be at most 0.1 rad, got {self.proprio_noise!r}")
        object.__setattr__(self, "proprio_bias", tuple(vals))

    @property
    def exact_servo(self) -> bool:
        """Whether the pymunk arm uses the ideal velocity servo (no tracking error)."""
        return self.kp is None

    @property
    def senses_exactly(self) -> bool:
        """Whether the robot feels exactly where its finger is and the pad hears exactly there."""
        return (self.finger_radius == 0 and self.proprio_noise == 0
                and self.proprio_bias == (0.0, 0.0))

    def to_dict(self) -> dict:
        d = asdict(self)
        d["proprio_bias"] = list(self.proprio_bias)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ArmConfig:
        """Build from a table: ``preset`` (default ``ideal``) plus fields overriding it."""
        check_known(cls, d, "arm")
        d = dict(d)
        name = d.pop("preset", "ideal")
        base = ArmConfig(preset="custom") if name == "custom" else preset(name)
        if not d:
            return base
        if "proprio_bias" in d and isinstance(d["proprio_bias"], list):
            d["proprio_bias"] = tuple(d["proprio_bias"])
        return replace(base, preset=base.preset if _same(base, d) else "custom", **d)


def _same(base: ArmConfig, d: dict) -> bool:
    cur = base.to_dict()
    return all(cur.get(k) == (list(v) if isinstance(v, tuple) else v) for k, v in d.items())


#: Name -> the arm it stands for (see the module docstring).
PRESETS: dict[str, ArmConfig] = {
    "ideal": ArmConfig(preset="ideal"),
    "servo": ArmConfig(preset="servo", kp=2.0e7, kd=2.4e6, max_torque=3.0e7, friction=8.0e4,
                       settle_time=2.0),
    "realistic": ArmConfig(preset="realistic", kp=2.0e7, kd=2.4e6, max_torque=3.0e7,
                           friction=8.0e4, settle_time=2.0, finger_radius=2.5,
                           proprio_noise=3.5e-3, proprio_bias=(1.5e-3, -1.0e-3)),
}


def ideal_mode_note(arm: ArmConfig, mode: str) -> str | None:
    """A line for the user when ``mode`` ignores part of ``arm``: ``ideal`` mode has no physics,
    so a torque servo and its friction do nothing there (the ``servo`` preset is then the ideal
    arm). None when nothing is ignored."""
    if mode != "ideal" or arm.exact_servo:
        return None
    tail = ("it is the ideal arm here" if arm.senses_exactly else
            "only its finger and proprioception act here")
    return (f"note: ideal mode has no physics, so the {arm.preset} arm's servo and friction are "
            f"ignored and {tail}; --mode dynamics simulates them")


def preset(name: str) -> ArmConfig:
    """The arm preset called ``name``; ConfigError listing the valid ones otherwise."""
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown arm preset {name!r}; valid: {', '.join(PRESETS)}") from None


def arm_config(value: str | dict | ArmConfig | None) -> ArmConfig:
    """An :class:`ArmConfig` from a preset name, a table or an ArmConfig (None: ``ideal``)."""
    if value is None:
        return PRESETS["ideal"]
    if isinstance(value, ArmConfig):
        return value
    if isinstance(value, str):
        return preset(value)
    if isinstance(value, dict):
        return ArmConfig.from_dict(value)
    raise ConfigError(f"arm must be a preset name or a table, got {value!r}")
