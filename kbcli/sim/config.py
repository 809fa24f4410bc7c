"""The simulated arm's config: its reach mode, geometry, landing scatter and how it errs."""

from __future__ import annotations

from typing import Any

from pydantic import field_validator

from kbcli.core.config import Config, Name, NonNegative, Number, Positive
from kbcli.sim.arms import PRESETS, ArmConfig, arm_config
from kbcli.sim.modes import MODES


class SimConfig(Config):
    """The arm and how it reaches (the ``sim`` table of an artifact's config).

    Parameters
    ----------
    mode : str
        A reach mode of :data:`kbcli.sim.modes.MODES`: ``ideal``, the finger lands exactly on the
        target (the paper's Sect. IV); ``dynamics``, a pymunk two-link arm driven by motors
        (Sect. IV-C).
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

    what = "sim"

    mode: Name = "ideal"
    base: tuple[Number, Number] = (400.0, 0.0)
    link_lengths: tuple[Positive, Positive] = (320.0, 280.0)
    reach_noise: NonNegative = 0.0
    arm: ArmConfig = PRESETS.get("ideal")

    @field_validator("mode")
    @classmethod
    def _mode(cls, v: str) -> str:
        return MODES.check(v)

    @field_validator("arm", mode="before")
    @classmethod
    def _arm(cls, v: Any) -> ArmConfig:
        return arm_config(v)
