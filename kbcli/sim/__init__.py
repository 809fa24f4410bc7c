"""The simulated world: an arm reaching on a pad, and the keyboard at its (hidden) true pose.

Only this package imports pymunk (in :mod:`kbcli.sim.arm`, loaded when a ``dynamics`` reacher is
built). The rest of kbcli sees a reacher, ``reach(targets, rng) -> landed finger positions``
(:func:`make_reacher` of a :class:`SimConfig`), and :class:`World`, which turns an action into
what the robot hears. The world holds the ground truth; robot-side code only gets ``World.touch``.
"""

from kbcli.sim.arms import PRESETS, ArmConfig, arm_config
from kbcli.sim.config import SimConfig
from kbcli.sim.ideal import IdealReacher
from kbcli.sim.kinematics import (
    contact_points,
    felt_positions,
    forward_kinematics,
    inverse_kinematics,
)
from kbcli.sim.modes import MODES, SimMode, ideal_mode_note, make_reacher
from kbcli.sim.reach import (
    check_keyboard_reachable,
    check_reachable,
    polygons_reachable,
    rect_reachable,
    workspace_check,
)
from kbcli.sim.world import World, keys_heard_when_felt

__all__ = [
    "PRESETS", "ArmConfig", "arm_config", "SimConfig", "IdealReacher", "contact_points",
    "felt_positions", "forward_kinematics", "inverse_kinematics", "MODES", "SimMode",
    "ideal_mode_note", "make_reacher", "check_keyboard_reachable", "check_reachable",
    "polygons_reachable", "rect_reachable", "workspace_check", "World", "keys_heard_when_felt",
]
