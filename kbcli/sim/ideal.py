"""The ``ideal`` reach mode: the finger lands on the target (the paper's Sect. IV), no physics."""

from __future__ import annotations

import numpy as np

from kbcli.sim.kinematics import SimSpec, inverse_kinematics, sensed_positions
from kbcli.sim.reach import check_reachable


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

    def __init__(self, cfg: SimSpec) -> None:
        self.cfg = cfg
        self.last_felt = np.empty((0, 2))
        self.last_angles = np.empty((0, 2))

    def reach(self, targets: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) targets -> (n, 2) landed finger positions. Raises OutOfReachError."""
        t = check_reachable(self.cfg, targets)
        if self.cfg.reach_noise > 0:
            t = t + rng.normal(0.0, self.cfg.reach_noise, size=t.shape)
        self.last_angles = inverse_kinematics(self.cfg, t)
        self.last_felt = sensed_positions(self.cfg, self.last_angles, t, rng)
        return t
