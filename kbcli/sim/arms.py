"""Arm presets: how a simulated arm errs (its servo, its joints, its finger, its proprioception).

:data:`PRESETS` names three arms (``--arm NAME``, or an ``[arm]`` TOML table with ``preset =
NAME`` and any field to override): ``ideal``, no error (the paper's idealised problem);
``servo``, a torque PD servo ``tau = kp * e - kd * w`` against Coulomb joint friction, so a joint
stops short of its target by up to ``friction / kp`` rad (``dynamics`` mode); ``realistic``,
``servo`` plus a finger of contact radius ``finger_radius`` px and encoders reading ``q +
proprio_bias + N(0, proprio_noise^2)`` rad. In ``ideal`` mode the servo fields are ignored.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pydantic import field_validator

from kbcli.core.config import Config, Name, NonNegative, Number, Positive, between
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

#: Longest reach (simulated seconds) an arm may take before it gives up: ``settle_time`` above it
#: is refused (each second is 240 physics steps).
MAX_SETTLE_TIME = 60.0
#: Largest encoder error (rad) of ``proprio_noise`` and of each ``proprio_bias`` component.
MAX_PROPRIO = 0.1

#: Largest servo gain, damping, torque bound and joint friction (pymunk's torque units): 300 times
#: the ``servo`` preset's gain, 30 times the default torque bound.
MAX_TORQUE = 1e10
#: Largest radius (px) of the finger's contact disc: a default key's side.
MAX_FINGER_RADIUS = 50.0

_Bias = between(Number, -MAX_PROPRIO, MAX_PROPRIO)
_Torque = between(Number, 0, MAX_TORQUE)


class ArmConfig(Config):
    """How a simulated arm errs (see the module docstring).

    Parameters
    ----------
    preset : str
        The preset these values started from (``ideal``, ``servo``, ``realistic``) or ``custom``.
    kp : float or None
        Stiffness of the torque servo (torque per rad); None: the ideal velocity servo. It,
        ``kd``, ``max_torque`` and ``friction`` are at most :data:`MAX_TORQUE`.
    kd : float
        Damping of the torque servo (torque per rad/s).
    max_torque : float
        Bound of each joint's servo torque.
    friction : float
        Coulomb friction torque of each joint.
    settle_time : float
        A reach gives up after this many simulated seconds, at most :data:`MAX_SETTLE_TIME`.
    finger_radius : float
        Radius (px) of the finger's contact disc on the pad, at most :data:`MAX_FINGER_RADIUS`.
    proprio_noise : float
        Std (rad) of each joint encoder's reading at a touch, at most :data:`MAX_PROPRIO`.
    proprio_bias : tuple of float
        Constant offset (rad) of the shoulder and elbow encoders, each within
        +-:data:`MAX_PROPRIO`.
    """

    what = "arm"

    preset: Name = "ideal"
    kp: between(Number, 0, MAX_TORQUE, low_open=True) | None = None
    kd: _Torque = 0.0
    max_torque: between(Number, 0, MAX_TORQUE, low_open=True) = 5e8
    friction: _Torque = 0.0
    settle_time: between(Positive, high=MAX_SETTLE_TIME) = 8.0
    finger_radius: between(Number, 0, MAX_FINGER_RADIUS) = 0.0
    proprio_noise: between(NonNegative, high=MAX_PROPRIO) = 0.0
    proprio_bias: tuple[_Bias, _Bias] = (0.0, 0.0)

    @field_validator("preset")
    @classmethod
    def _named(cls, v: str) -> str:
        if not v:
            raise ValueError("must be a name, got ''")
        return v

    @property
    def exact_servo(self) -> bool:
        """Whether the pymunk arm uses the ideal velocity servo (no tracking error)."""
        return self.kp is None

    @property
    def senses_exactly(self) -> bool:
        """Whether the robot feels exactly where its finger is and the pad hears exactly there."""
        return (self.finger_radius == 0 and self.proprio_noise == 0
                and self.proprio_bias == (0.0, 0.0))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ArmConfig:
        """Build from a table: ``preset`` (default ``ideal``) plus fields overriding it; the
        result is named ``custom`` unless the overrides repeat the preset's own values."""
        if not isinstance(d, Mapping):
            raise ConfigError(f"arm must be a table, got {d!r}")
        d = dict(d)
        name = d.pop("preset", "ideal")
        base = cls(preset="custom") if name == "custom" else PRESETS.get(name)
        if not d:
            return base
        same = cls(**{**base.to_dict(), **d})
        return base if same == base else same.replace(preset="custom")


#: Name -> the arm it stands for (see the module docstring).
PRESETS: Registry[ArmConfig] = Registry("arm preset")
PRESETS.register("ideal", ArmConfig(preset="ideal"), summary="lands on target, feels exactly")
PRESETS.register("servo", ArmConfig(preset="servo", kp=2.0e7, kd=2.4e6, max_torque=3.0e7,
                                    friction=8.0e4, settle_time=2.0),
                 summary="finite servo gains and joint friction")
PRESETS.register("realistic", ArmConfig(preset="realistic", kp=2.0e7, kd=2.4e6, max_torque=3.0e7,
                                        friction=8.0e4, settle_time=2.0, finger_radius=2.5,
                                        proprio_noise=3.5e-3, proprio_bias=(1.5e-3, -1.0e-3)),
                 summary="servo plus a finger of finite radius and noisy, biased proprioception")


def arm_config(value: str | Mapping | ArmConfig | None) -> ArmConfig:
    """An :class:`ArmConfig` from a preset name, a table or an ArmConfig (None: ``ideal``)."""
    if value is None:
        return PRESETS.get("ideal")
    if isinstance(value, ArmConfig):
        return value
    if isinstance(value, str):
        return PRESETS.get(value)
    if isinstance(value, Mapping):
        return ArmConfig.from_dict(value)
    raise ConfigError(f"arm must be a preset name or a table, got {value!r}")
