"""The simulated arm's config: its reach mode, geometry, landing scatter and how it errs."""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, BeforeValidator, InstanceOf

from kbcli.core.config import Config, Name, Number, between
from kbcli.core.instrument.geometry import MAX_COORD, Coordinate
from kbcli.sim.arms import PRESETS, ArmConfig, arm_config
from kbcli.sim.modes import MODES

#: Largest landing scatter (px) of ``reach_noise``: twice a default key's side.
MAX_REACH_NOISE = 100.0
_Link = between(Number, 0, MAX_COORD, low_open=True)
#: A landing scatter (px): a number in [0, MAX_REACH_NOISE], wherever a config takes one.
ReachNoise = between(Number, 0, MAX_REACH_NOISE)

#: A field naming a sim mode, checked against :data:`MODES` ("unknown sim mode 'x'; valid: ...").
ModeName = Annotated[Name, AfterValidator(MODES.check)]
#: A field holding an arm: a preset name, a table (``preset = NAME`` plus fields) or an ArmConfig,
#: resolved by :func:`kbcli.sim.arms.arm_config`.
Arm = Annotated[InstanceOf[ArmConfig], BeforeValidator(arm_config)]


class SimConfig(Config):
    """The arm and how it reaches (the ``sim`` table of an artifact's config).

    Parameters
    ----------
    mode : str
        A reach mode of :data:`kbcli.sim.modes.MODES`: ``ideal`` (the finger lands on the
        target) or ``dynamics`` (a pymunk two-link arm, Sect. IV-C).
    base : tuple of float
        Pad coordinates of the shoulder joint.
    link_lengths : tuple of float
        Upper arm and forearm lengths, px.
    reach_noise : float
        Std (px) of the landing scatter, at most :data:`MAX_REACH_NOISE`.
    arm : ArmConfig
        How the arm errs beyond ``reach_noise`` (:mod:`kbcli.sim.arms`; a preset name or a table).
    """

    what = "sim"

    mode: ModeName = "ideal"
    base: tuple[Coordinate, Coordinate] = (400.0, 0.0)
    link_lengths: tuple[_Link, _Link] = (320.0, 280.0)
    reach_noise: ReachNoise = 0.0
    arm: Arm = PRESETS.get("ideal")
