"""The simulated world: the keyboard at its (hidden) true pose, an arm and a perception channel.

The world holds the ground truth; robot-side code only gets :meth:`World.touch`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kbcli.core.instrument.keyboard import Keyboard
from kbcli.sim.kinematics import SimSpec, contact_points, forward_kinematics, inverse_kinematics


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


def keys_heard_when_felt(cfg: SimSpec, keyboard: Keyboard, felt: np.ndarray, samples: int,
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
