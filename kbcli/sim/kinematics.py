"""The planar two-link arm's geometry: joint angles <-> fingertip, its Jacobian, where the robot
feels its fingertip and where the pad hears the finger.

The functions read a :class:`SimSpec` (what they need of :class:`kbcli.sim.config.SimConfig`):
the shoulder ``base``, the ``link_lengths`` and the ``arm`` (:mod:`kbcli.sim.arms`). Pure numpy.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from kbcli.sim.arms import ArmConfig


class SimSpec(Protocol):
    """What the kinematics and the reachers read of a :class:`~kbcli.sim.config.SimConfig`."""

    mode: str
    base: tuple[float, float]
    link_lengths: tuple[float, float]
    reach_noise: float
    arm: ArmConfig


def inverse_kinematics(cfg: SimSpec, targets: np.ndarray) -> np.ndarray:
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


def forward_kinematics(cfg: SimSpec, angles: np.ndarray) -> np.ndarray:
    """(n, 2) joint angles -> (n, 2) fingertip positions on the pad."""
    q = np.asarray(angles, float).reshape(-1, 2)
    l1, l2 = cfg.link_lengths
    a = q[:, 0] + q[:, 1]
    return np.asarray(cfg.base) + np.column_stack(
        [l1 * np.cos(q[:, 0]) + l2 * np.cos(a), l1 * np.sin(q[:, 0]) + l2 * np.sin(a)]
    )


def jacobian(cfg: SimSpec, angles: np.ndarray) -> np.ndarray:
    """(n, 2, 2) d fingertip / d (q1, q2) at each pose."""
    q = np.asarray(angles, float).reshape(-1, 2)
    l1, l2 = cfg.link_lengths
    a = q[:, 0] + q[:, 1]
    j = np.empty((len(q), 2, 2))
    j[:, 0, 0] = -l1 * np.sin(q[:, 0]) - l2 * np.sin(a)
    j[:, 0, 1] = -l2 * np.sin(a)
    j[:, 1, 0] = l1 * np.cos(q[:, 0]) + l2 * np.cos(a)
    j[:, 1, 1] = l2 * np.cos(a)
    return j


def felt_positions(cfg: SimSpec, angles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Where the robot feels its fingertip: the forward kinematics of its encoder readings.

    The encoders read the true joint ``angles`` (n, 2) plus the arm's ``proprio_bias`` and
    Gaussian noise of ``proprio_noise`` rad (no draw when it is 0). Returns (n, 2) px.
    """
    arm = cfg.arm
    q = np.asarray(angles, float).reshape(-1, 2) + np.asarray(arm.proprio_bias)
    if arm.proprio_noise > 0:
        q = q + rng.normal(0.0, arm.proprio_noise, size=q.shape)
    return forward_kinematics(cfg, q)


def sensed_positions(cfg: SimSpec, angles: np.ndarray, landed: np.ndarray,
                     rng: np.random.Generator) -> np.ndarray:
    """Where the robot feels the fingertips it ``landed`` at joint ``angles``: the landings
    themselves (no draw) for exact proprioception, else :func:`felt_positions`."""
    arm = cfg.arm
    if arm.proprio_noise > 0 or arm.proprio_bias != (0.0, 0.0):
        return felt_positions(cfg, angles, rng)
    return np.asarray(landed, float).copy()


def contact_points(cfg: SimSpec, landed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Where the pad registers each touch: uniform in the finger's contact disc around ``landed``
    (the landed points themselves, and no draw, for a point finger)."""
    p = np.asarray(landed, float).reshape(-1, 2)
    r = cfg.arm.finger_radius
    if r <= 0 or len(p) == 0:
        return p
    u = rng.random((len(p), 2))
    rho, phi = r * np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    return p + np.column_stack([rho * np.cos(phi), rho * np.sin(phi)])
