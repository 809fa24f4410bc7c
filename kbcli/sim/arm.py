"""A planar two-link arm simulated with pymunk: the ``dynamics`` reach mode (paper Sect. IV-C).

The arm lies on the pad, seen from above: a shoulder pivot at ``SimConfig.base``, links of
``SimConfig.link_lengths``. A reach checks the target is in the annular workspace (else
:class:`~kbcli.errors.OutOfReachError`; never clipped), solves the inverse kinematics (elbow
branch q2 > 0), offsets the joint targets by ``J^-1 e``, ``e ~ N(0, reach_noise^2 I)``, and drives
both joints with ``SimpleMotor`` servos (``rate = KP * error``) until the fingertip settles. With
finite servo gains (``ArmConfig.kp``) the drive is a torque PD servo against joint friction on the
*measured* angles instead. Each reach starts from the pose the previous one ended in
(:meth:`DynamicsReacher.reset` sets it).
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from kbcli.sim.kinematics import SimSpec, inverse_kinematics, jacobian, sensed_positions
from kbcli.sim.reach import check_reachable

__all__ = ["DynamicsReacher"]

DT = 1.0 / 240.0  # physics time step, s
KP = 40.0  # proportional gain of the servo, 1/s
MAX_RATE = 8.0  # joint speed limit, rad/s
MAX_TORQUE = 5e8  # motor torque bound (px^2 * mass / s^2)
ANGLE_TOL = 2e-5  # joint-angle error at which a joint counts as settled, rad
SPEED_TOL = 2e-3  # joint speed below which a joint counts as still, rad/s
MAX_STEPS = 2000  # give up settling after this many steps (8.3 s of simulated time)
SETTLE_STEPS = 12  # torque servo: a reach ends after this many steps with both joints still
LINK_MASS = (2.0, 1.5)  # upper arm, forearm
# pivots: share of a joint's drift left after 1 s (pymunk's default is 0.9**60)
JOINT_ERROR_BIAS = 0.5**240


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _chipmunk(reacher: DynamicsReacher):
    """(lib, upper, forearm, space) as chipmunk handles, or None when pymunk does not expose them
    (private API: the fast path of the servo loops; ``cpSpaceStep`` does exactly what
    ``Space.step`` would, as the arm adds and removes nothing while it reaches)."""
    try:
        from pymunk._chipmunk_cffi import lib

        handles = (lib, reacher.upper._body, reacher.fore._body, reacher.space._space)
        for name in ("cpBodyGetAngle", "cpBodyGetAngularVelocity", "cpBodySetTorque",
                     "cpSpaceStep"):
            getattr(lib, name)
    except (ImportError, AttributeError):
        return None
    if reacher.space._add_later or reacher.space._remove_later or \
            reacher.space._post_step_callbacks or reacher.space.threaded:
        return None
    return handles


class DynamicsReacher:
    """A pymunk two-link arm driven by servo motors.

    Parameters
    ----------
    cfg : SimConfig (or any :class:`~kbcli.sim.kinematics.SimSpec`)
        Geometry (``base``, ``link_lengths``) and ``reach_noise`` (px) of the arm.

    Attributes
    ----------
    last_start_angles, last_end_angles : (n, 2) ndarray
        Joint angles each reach of the last :meth:`reach` call started from and ended in
        (``last_angles`` the same as the latter).
    last_steps : (n,) int ndarray
        Physics steps each reach of the last call took to settle.
    last_felt : (n, 2) ndarray
        Where the robot felt its fingertip at the end of each reach.
    """

    def __init__(self, cfg: SimSpec) -> None:
        self.cfg = cfg
        l1, l2 = cfg.link_lengths
        self._l1, self._l2 = l1, l2
        self._base = pymunk.Vec2d(*cfg.base)
        self.space = space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.iterations = 10
        group = pymunk.ShapeFilter(group=1)  # the links never collide with each other
        self.upper = self._link(l1, LINK_MASS[0], group)
        self.fore = self._link(l2, LINK_MASS[1], group)
        shoulder = pymunk.PivotJoint(space.static_body, self.upper, self._base, (-l1 / 2, 0))
        self._elbow_joint = pymunk.PivotJoint(self.upper, self.fore, (l1 / 2, 0), (-l2 / 2, 0))
        self.m1 = pymunk.SimpleMotor(space.static_body, self.upper, 0.0)
        self.m2 = pymunk.SimpleMotor(self.upper, self.fore, 0.0)
        arm = cfg.arm
        self._torque = not arm.exact_servo
        for m in (self.m1, self.m2):
            # exact servo: velocity motors; torque servo: rate-0 motors as joint friction
            m.max_force = arm.friction if self._torque else MAX_TORQUE
        for j in (shoulder, self._elbow_joint):
            j.error_bias = JOINT_ERROR_BIAS
        space.add(shoulder, self._elbow_joint, self.m1, self.m2)
        self.home = inverse_kinematics(cfg, np.array(cfg.base) + (0.0, 0.7 * (l1 + l2)))[0]
        self.last_start_angles = np.empty((0, 2))
        self.last_steps = np.empty(0, dtype=np.int64)
        self.last_angles = np.empty((0, 2))
        self.last_felt = np.empty((0, 2))
        self.last_end_angles = np.empty((0, 2))
        self.reset(self.home)

    def _link(self, length: float, mass: float, group: pymunk.ShapeFilter) -> pymunk.Body:
        a, b = (-length / 2, 0.0), (length / 2, 0.0)
        body = pymunk.Body(mass, pymunk.moment_for_segment(mass, a, b, 4.0))
        shape = pymunk.Segment(body, a, b, 4.0)
        shape.filter = group
        self.space.add(body, shape)
        return body

    # -- state ----------------------------------------------------------------------------------
    @property
    def angles(self) -> np.ndarray:
        """(2,) current joint angles (q1, q2)."""
        return np.array([self.upper.angle, self.fore.angle - self.upper.angle])

    def fingertip(self) -> np.ndarray:
        """(2,) fingertip position on the pad, read from the simulated forearm."""
        p = self.fore.local_to_world((self._l2 / 2, 0.0))
        return np.array([p.x, p.y])

    def reset(self, angles: np.ndarray) -> None:
        """Put the arm at rest in joint angles ``angles`` (q1, q2)."""
        q1, q2 = (float(v) for v in np.asarray(angles, float).reshape(2))
        elbow = self._base + pymunk.Vec2d(math.cos(q1), math.sin(q1)) * self._l1
        self.upper.angle = q1
        self.upper.position = self._base + pymunk.Vec2d(math.cos(q1), math.sin(q1)) * (self._l1 / 2)
        self.fore.angle = q1 + q2
        self.fore.position = elbow + pymunk.Vec2d(math.cos(q1 + q2), math.sin(q1 + q2)) * (
            self._l2 / 2
        )
        for b in (self.upper, self.fore):
            b.velocity = (0.0, 0.0)
            b.angular_velocity = 0.0
        self.m1.rate = self.m2.rate = 0.0
        self.space.reindex_shapes_for_body(self.upper)
        self.space.reindex_shapes_for_body(self.fore)

    # -- reaching -------------------------------------------------------------------------------
    def _drive(self, q1t: float, q2t: float) -> int:
        """Servo both joints to (q1t, q2t) until settled; return the number of steps (on
        chipmunk directly when it can, else :meth:`_drive_public`: the same steps, to the bit)."""
        cm = _chipmunk(self)
        if cm is None:
            return self._drive_public(q1t, q2t)
        lib, up, fo, space = cm
        get_a, get_w, set_rate, step = (lib.cpBodyGetAngle, lib.cpBodyGetAngularVelocity,
                                        lib.cpSimpleMotorSetRate, lib.cpSpaceStep)
        m1, m2 = self.m1._constraint, self.m2._constraint
        pi, tau = math.pi, 2.0 * math.pi
        for n in range(1, MAX_STEPS + 1):
            a1 = get_a(up)
            e1 = (q1t - a1 + pi) % tau - pi  # _wrap, inlined: this loop is the hot path
            e2 = (q2t - (get_a(fo) - a1) + pi) % tau - pi
            w1 = KP * e1
            w1 = MAX_RATE if w1 > MAX_RATE else (-MAX_RATE if w1 < -MAX_RATE else w1)
            w2 = KP * e2
            w2 = MAX_RATE if w2 > MAX_RATE else (-MAX_RATE if w2 < -MAX_RATE else w2)
            # SimpleMotor(a, b) keeps a.w - b.w == rate: static.w - upper.w = -w1, and so on.
            set_rate(m1, -w1)
            set_rate(m2, -w2)
            step(space, DT)
            if abs(e1) < ANGLE_TOL and abs(e2) < ANGLE_TOL:
                v1 = get_w(up)
                if abs(v1) < SPEED_TOL and abs(get_w(fo) - v1) < SPEED_TOL:
                    return n
        return MAX_STEPS

    def _drive_public(self, q1t: float, q2t: float) -> int:
        """:meth:`_drive` through pymunk's public API (the reference the fast path is tested
        against)."""
        up, fo, m1, m2, step = self.upper, self.fore, self.m1, self.m2, self.space.step
        for n in range(1, MAX_STEPS + 1):
            a1 = up.angle
            e1 = _wrap(q1t - a1)
            e2 = _wrap(q2t - (fo.angle - a1))
            w1 = min(MAX_RATE, max(-MAX_RATE, KP * e1))
            w2 = min(MAX_RATE, max(-MAX_RATE, KP * e2))
            # SimpleMotor(a, b) keeps a.w - b.w == rate: static.w - upper.w = -w1, and so on.
            m1.rate = -w1
            m2.rate = -w2
            step(DT)
            if (
                abs(e1) < ANGLE_TOL
                and abs(e2) < ANGLE_TOL
                and abs(up.angular_velocity) < SPEED_TOL
                and abs(fo.angular_velocity - up.angular_velocity) < SPEED_TOL
            ):
                return n
        return MAX_STEPS

    def _drive_torque(self, q1t: float, q2t: float) -> int:
        """Torque PD servo of both joints to the *measured* angles (q1t, q2t) against friction
        until still; return the steps (as :meth:`_drive`, :meth:`_drive_torque_public` the
        fallback)."""
        cm = _chipmunk(self)
        if cm is None:
            return self._drive_torque_public(q1t, q2t)
        lib, up, fo, space = cm
        get_a, get_w, set_t, step = (lib.cpBodyGetAngle, lib.cpBodyGetAngularVelocity,
                                     lib.cpBodySetTorque, lib.cpSpaceStep)
        arm = self.cfg.arm
        kp, kd, tmax = float(arm.kp), float(arm.kd), float(arm.max_torque)
        b1, b2 = arm.proprio_bias
        pi, tau = math.pi, 2.0 * math.pi
        max_steps = max(1, int(round(arm.settle_time / DT)))
        still = 0
        w1 = get_w(up)
        w2 = get_w(fo) - w1
        for n in range(1, max_steps + 1):
            a1 = get_a(up)
            e1 = (q1t - (a1 + b1) + pi) % tau - pi  # _wrap, inlined: this loop is the hot path
            e2 = (q2t - (get_a(fo) - a1 + b2) + pi) % tau - pi
            t1 = kp * e1 - kd * w1
            t1 = tmax if t1 > tmax else (-tmax if t1 < -tmax else t1)
            t2 = kp * e2 - kd * w2
            t2 = tmax if t2 > tmax else (-tmax if t2 < -tmax else t2)
            set_t(up, t1 - t2)  # chipmunk resets body torques after every step
            set_t(fo, t2)
            step(space, DT)
            w1 = get_w(up)
            w2 = get_w(fo) - w1
            if abs(w1) < SPEED_TOL and abs(w2) < SPEED_TOL:
                still += 1
                if still >= SETTLE_STEPS:
                    return n
            else:
                still = 0
        return max_steps

    def _drive_torque_public(self, q1t: float, q2t: float) -> int:
        """:meth:`_drive_torque` through pymunk's public API (the reference the fast path is
        tested against)."""
        arm = self.cfg.arm
        kp, kd, tmax = float(arm.kp), float(arm.kd), float(arm.max_torque)
        b1, b2 = arm.proprio_bias
        up, fo, step = self.upper, self.fore, self.space.step
        max_steps = max(1, int(round(arm.settle_time / DT)))
        still = 0
        for n in range(1, max_steps + 1):
            a1 = up.angle
            w1 = up.angular_velocity
            w2 = fo.angular_velocity - w1
            e1 = _wrap(q1t - (a1 + b1))
            e2 = _wrap(q2t - (fo.angle - a1 + b2))
            t1 = min(tmax, max(-tmax, kp * e1 - kd * w1))
            t2 = min(tmax, max(-tmax, kp * e2 - kd * w2))
            up.torque = t1 - t2  # pymunk resets body torques after every step
            fo.torque = t2
            step(DT)
            if abs(up.angular_velocity) < SPEED_TOL and abs(
                    fo.angular_velocity - up.angular_velocity) < SPEED_TOL:
                still += 1
                if still >= SETTLE_STEPS:
                    return n
            else:
                still = 0
        return max_steps

    def reach(self, targets: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) where the fingertip ended reaching for each of ``targets`` (n, 2) in turn
        (``rng``: the motor noise).

        Raises
        ------
        OutOfReachError
            If any target is outside the workspace (checked before the arm moves).
        """
        t = check_reachable(self.cfg, targets)
        q = inverse_kinematics(self.cfg, t)
        if self.cfg.reach_noise > 0 and len(t):
            e = rng.normal(0.0, self.cfg.reach_noise, size=t.shape)
            q = q + np.linalg.solve(jacobian(self.cfg, q), e[:, :, None])[:, :, 0]
        starts = np.empty((len(t), 2))
        steps = np.empty(len(t), dtype=np.int64)
        landed = np.empty((len(t), 2))
        ends = np.empty((len(t), 2))
        drive = self._drive_torque if self._torque else self._drive
        for i in range(len(t)):  # reaches are sequential in time: each starts where the last ended
            starts[i] = self.angles
            steps[i] = drive(float(q[i, 0]), float(q[i, 1]))
            landed[i] = self.fingertip()
            ends[i] = self.angles
        self.last_start_angles = starts
        self.last_steps = steps
        self.last_angles = ends
        self.last_felt = sensed_positions(self.cfg, ends, landed, rng)
        self.last_end_angles = ends
        return landed
