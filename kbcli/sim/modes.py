"""Reach modes: how the simulated arm gets its finger to a target.

:data:`MODES` holds one :class:`SimMode` per mode, which code asks for its reacher and whether it
simulates physics, never branching on its name: ``ideal``, the target plus Gaussian scatter of
``reach_noise`` px (:class:`kbcli.sim.ideal.IdealReacher`), and ``dynamics``, a pymunk two-link
arm (Sect. IV-C; :class:`kbcli.sim.arm.DynamicsReacher`, pymunk imported only then).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from kbcli.core.registry import Registry
from kbcli.sim.arms import ArmConfig
from kbcli.sim.ideal import IdealReacher
from kbcli.sim.kinematics import SimSpec


@dataclass(frozen=True)
class SimMode:
    """One reach mode.

    Attributes
    ----------
    name : str
        Its name in configs and on the command line.
    physics : bool
        Whether it simulates the arm's dynamics (an arm's servo and friction act only then).
    make : callable
        ``make(cfg) -> reacher``: an object with ``reach(targets, rng) -> landed``.
    """

    name: str
    physics: bool
    make: Callable[[SimSpec], Any]

    def reacher(self, cfg: SimSpec) -> Any:
        """The reacher of this mode for the arm of ``cfg``."""
        return self.make(cfg)


def _dynamics(cfg: SimSpec) -> Any:
    from kbcli.sim.arm import DynamicsReacher  # pymunk only loads when asked for

    return DynamicsReacher(cfg)


#: Name -> :class:`SimMode`.
MODES: Registry[SimMode] = Registry("sim mode")
MODES.register("ideal", SimMode("ideal", physics=False, make=IdealReacher),
               summary="the finger lands on the target")
MODES.register("dynamics", SimMode("dynamics", physics=True, make=_dynamics),
               summary="a pymunk two-link arm driven by motors")


def make_reacher(cfg: SimSpec) -> Any:
    """The reacher of ``cfg.mode``."""
    return MODES.get(cfg.mode).reacher(cfg)


def ideal_mode_note(arm: ArmConfig, mode: str) -> str | None:
    """A line for the user when ``mode`` ignores part of ``arm``: a mode without physics (``ideal``)
    has no servo, so a torque servo and its friction do nothing there (the ``servo`` preset is then
    the ideal arm). None when nothing is ignored."""
    if MODES.get(mode).physics or arm.exact_servo:
        return None
    tail = ("it is the ideal arm here" if arm.senses_exactly else
            "only its finger and proprioception act here")
    physical = " or ".join(n for n, m in MODES.items() if m.physics)
    return (f"note: {mode} mode has no physics, so the {arm.preset} arm's servo and friction are "
            f"ignored and {tail}; --mode {physical} simulates them")
