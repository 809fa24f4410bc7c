"""The simulated arm (issue 3): kinematics, the pymunk dynamics reacher, reachability checks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.errors import OutOfReachError
from kbcli.sim import (
    SimConfig,
    World,
    check_keyboard_reachable,
    make_reacher,
    rect_reachable,
    workspace_check,
)
from kbcli.sim.arm import DynamicsReacher
from kbcli.sim.kinematics import forward_kinematics, inverse_kinematics, jacobian

CFG = SimConfig(mode="dynamics")
AREA = Keyboard(KeyboardConfig()).area


@settings(max_examples=50, deadline=None)
@given(r=st.floats(45.0, 595.0), a=st.floats(0.05, np.pi - 0.05))
def test_inverse_then_forward_kinematics_is_identity(r, a):
    p = np.array([[400 + r * np.cos(a), r * np.sin(a)]])
    q = inverse_kinematics(CFG, p)
    assert q[0, 1] >= 0  # always the same elbow branch
    np.testing.assert_allclose(forward_kinematics(CFG, q), p, atol=1e-6)


def test_jacobian_matches_finite_differences():
    q = np.array([[0.9, 1.4], [1.7, 0.6]])
    j = jacobian(CFG, q)
    h = 1e-6
    for k in range(2):
        dq = np.zeros(2)
        dq[k] = h
        num = (forward_kinematics(CFG, q + dq) - forward_kinematics(CFG, q - dq)) / (2 * h)
        np.testing.assert_allclose(j[:, :, k], num, rtol=1e-5, atol=1e-4)


def test_dynamics_reacher_lands_on_the_target_and_records_start_poses():
    reacher = make_reacher(CFG)
    assert isinstance(reacher, DynamicsReacher)
    rng = np.random.default_rng(0)
    targets = rng.uniform(AREA[:2], AREA[2:], size=(25, 2))
    home = reacher.angles.copy()
    landed = reacher.reach(targets, rng)
    assert landed.shape == (25, 2)
    assert np.max(np.hypot(*(landed - targets).T)) < 0.05  # settles within 0.05 px
    starts = reacher.last_start_angles
    assert starts.shape == (25, 2)
    np.testing.assert_allclose(starts[0], home)
    # each reach starts where the previous one ended
    np.testing.assert_allclose(forward_kinematics(CFG, starts[1:]), landed[:-1], atol=0.05)
    assert (reacher.last_steps > 0).all() and (reacher.last_steps < 2000).all()


def test_dynamics_reacher_is_reproducible_and_scatters_by_reach_noise():
    cfg = SimConfig(mode="dynamics", reach_noise=2.0)
    targets = np.random.default_rng(1).uniform(AREA[:2], AREA[2:], size=(300, 2))
    a = DynamicsReacher(cfg).reach(targets, np.random.default_rng(7))
    b = DynamicsReacher(cfg).reach(targets, np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    d = a - targets
    assert abs(np.mean(d)) < 0.3
    sd = np.std(d, axis=0)  # both axes scatter by about the 2 px asked for
    assert np.all((sd > 1.6) & (sd < 2.4))


def test_ideal_reacher_scatters_from_the_given_generator():
    """Same generator state, same landings; another seed, other landings (reach noise on)."""
    cfg = SimConfig(mode="ideal", reach_noise=2.0)
    targets = np.random.default_rng(1).uniform(AREA[:2], AREA[2:], size=(200, 2))
    a = make_reacher(cfg).reach(targets, np.random.default_rng(7))
    b = make_reacher(cfg).reach(targets, np.random.default_rng(7))
    c = make_reacher(cfg).reach(targets, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    sd = np.std(a - targets, axis=0)
    assert np.all((sd > 1.6) & (sd < 2.4))


def test_reset_puts_the_arm_in_a_pose():
    r = DynamicsReacher(CFG)
    q = np.array([1.1, 0.9])
    r.reset(q)
    np.testing.assert_allclose(r.angles, q, atol=1e-12)
    np.testing.assert_allclose(r.fingertip(), forward_kinematics(CFG, q)[0], atol=1e-9)


@pytest.mark.parametrize("target", [(400.0, 620.0), (400.0, 20.0), (1200.0, 300.0)])
@pytest.mark.parametrize("mode", ["ideal", "dynamics"])
def test_targets_out_of_the_workspace_are_refused_not_clipped(target, mode):
    reacher = make_reacher(SimConfig(mode=mode))
    before = getattr(reacher, "angles", None)
    with pytest.raises(OutOfReachError, match="outside the arm's workspace"):
        reacher.reach(np.array([[300.0, 300.0], target]), np.random.default_rng(0))
    if before is not None:  # checked before the arm moves
        np.testing.assert_array_equal(reacher.angles, before)


def test_world_touch_through_the_dynamics_arm():
    kb = Keyboard(KeyboardConfig())
    world = World(kb, make_reacher(CFG))
    landed, heard = world.touch(kb.key_centres()[:3], np.random.default_rng(0))
    np.testing.assert_allclose(heard, kb.features[:3])
    assert world.touches == 3


def test_rect_reachable_known_answers():
    cfg = SimConfig()  # shoulder (400, 0), reach 40 to 600 px
    rects = np.array([
        [150, 200, 650, 500],  # the default working area: farthest corner 559 px
        [100, 200, 700, 550],  # corners 650 px away
        [380, -10, 420, 10],  # around the shoulder: inside the inner hole
        [395, 100, 405, 110],
    ], float)
    np.testing.assert_array_equal(rect_reachable(cfg, rects), [True, False, False, True])
    # consistent with the point check on the rectangles' corners
    corners = np.array([[150, 200], [650, 200], [150, 500], [650, 500]], float)
    assert workspace_check(cfg, corners).all()


def test_keyboard_reachability_names_the_keys_out_of_reach():
    check_keyboard_reachable(SimConfig(), Keyboard(KeyboardConfig()))
    far = Keyboard(KeyboardConfig(origin=(500.0, 250.0)))  # right half beyond 600 px
    with pytest.raises(OutOfReachError, match=r"key\(s\) out of reach: .*F7"):
        check_keyboard_reachable(SimConfig(), far)
    wide = Keyboard(KeyboardConfig(origin=(200.0, 300.0), margin=150.0))
    with pytest.raises(OutOfReachError, match="only the margin|margin is not"):
        check_keyboard_reachable(SimConfig(), wide)
