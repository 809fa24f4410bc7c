"""Arm presets (issue 9): how each preset errs, and bad arm parameters refused cleanly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kbcli.bench import arm as bench
from kbcli.cli import app
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.errors import ConfigError
from kbcli.sim import SimConfig, World, contact_points, make_reacher
from kbcli.sim.arms import PRESETS, ArmConfig, arm_config

KB = Keyboard(KeyboardConfig())


def _targets(n: int, seed: int = 3) -> np.ndarray:
    x0, y0, x1, y1 = KB.area
    return np.random.default_rng(seed).uniform((x0, y0), (x1, y1), size=(n, 2))


def test_ideal_preset_lands_on_target_and_feels_it_exactly():
    t = _targets(60)
    for mode in ("ideal", "dynamics"):
        s = bench.landing_statistics(SimConfig(mode=mode, arm="ideal"), t, np.random.default_rng(0))
        assert np.max(s["landing"]) < 0.05
        assert np.max(s["felt"]) == 0 and np.max(s["contact"]) == 0


def test_servo_preset_misses_by_about_a_pixel_and_the_miss_depends_on_the_reach():
    t = _targets(120)
    s = bench.landing_statistics(SimConfig(mode="dynamics", arm="servo"), t,
                                 np.random.default_rng(0))
    assert 0.4 < np.median(s["landing"]) < 3.0
    assert np.max(s["felt"]) == 0  # it feels where it is
    # the same target reached from two different starting poses lands in two different places
    target = t[:1]
    a = make_reacher(SimConfig(mode="dynamics", arm="servo"))
    a.reach(np.array([[250.0, 250.0]]), np.random.default_rng(0))
    la = a.reach(target, np.random.default_rng(0))
    b = make_reacher(SimConfig(mode="dynamics", arm="servo"))
    b.reach(np.array([[600.0, 480.0]]), np.random.default_rng(0))
    lb = b.reach(target, np.random.default_rng(0))
    assert np.hypot(*(la - lb)[0]) > 0.05


def test_realistic_preset_feels_one_to_three_px_off():
    t = _targets(200)
    for mode in ("ideal", "dynamics"):
        s = bench.landing_statistics(SimConfig(mode=mode, arm="realistic"), t,
                                     np.random.default_rng(1))
        assert np.median(s["felt"]) >= 1.0 and np.median(s["felt"]) <= 3.0
        r = PRESETS.get("realistic").finger_radius
        assert np.max(s["contact"]) <= r + 1e-9
        # uniform in the disc: the median distance is r / sqrt(2)
        assert abs(np.median(s["contact"]) - r / math.sqrt(2)) < 0.15 * r


def test_world_hears_at_the_contact_point_and_reports_the_felt_position():
    sim = SimConfig(mode="ideal", arm="realistic")
    world = World(KB, make_reacher(sim))
    felt, heard = world.touch(_targets(50), np.random.default_rng(2))
    assert felt.shape == world.last_landed.shape == (50, 2)
    assert not np.allclose(felt, world.last_landed)
    # with a point finger and exact proprioception, felt == landed and nothing extra is drawn
    w0 = World(KB, make_reacher(SimConfig(mode="ideal")))
    r1, r2 = np.random.default_rng(5), np.random.default_rng(5)
    f0, _ = w0.touch(_targets(10), r1)
    np.testing.assert_array_equal(f0, w0.last_landed)
    np.testing.assert_array_equal(contact_points(SimConfig(), f0, r2), f0)
    assert r1.random() == r2.random()


def test_arm_config_round_trips_and_overrides_mark_it_custom():
    for _, p in PRESETS.items():
        assert ArmConfig.from_dict(p.to_dict()) == p
    a = arm_config({"preset": "realistic", "finger_radius": 1.0})
    assert a.preset == "custom" and a.finger_radius == 1.0 and a.kp == PRESETS.get("realistic").kp
    assert arm_config({"preset": "servo", "kp": PRESETS.get("servo").kp}).preset == "servo"


@pytest.mark.parametrize("table", [
    {"preset": "clumsy"}, {"kp": -1.0}, {"kp": 0.0}, {"friction": float("nan")},
    {"finger_radius": -2.0}, {"proprio_noise": float("inf")}, {"proprio_bias": [0.1]},
    {"proprio_bias": [0.5, 0.0]}, {"settle_time": 0}, {"elbow": 1},
])
def test_bad_arm_tables_are_refused(table):
    with pytest.raises(ConfigError):
        arm_config(table)


@pytest.mark.parametrize("args", [
    ["--arm", "clumsy"], ["--arm", "missing.toml"],
])
def test_bad_arm_options_fail_cleanly(runner, kb_path, tmp_path, args):
    out = tmp_path / "m.h5"
    r = runner.invoke(app, ["learn", "--keyboard", str(kb_path), "--budget", "20", "-o", str(out),
                            *args])
    assert r.exit_code == 1
    assert "error" in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()


def test_arm_from_a_toml_table_is_recorded_in_the_model(runner, kb_path, tmp_path):
    toml = tmp_path / "arm.toml"
    toml.write_text('[arm]\npreset = "realistic"\nfinger_radius = 1.5\n')
    bad = tmp_path / "bad.toml"
    bad.write_text('[arm]\npreset = "realistic"\nfinger_radius = -1\n')
    out = tmp_path / "m.h5"
    r = runner.invoke(app, ["learn", "--keyboard", str(kb_path), "--budget", "20", "-o", str(out),
                            "--arm", str(bad)])
    assert r.exit_code == 1 and not out.exists()
    # a named class (knn, the cheapest): the arm is recorded whichever class is learned
    r = runner.invoke(app, ["learn", "--keyboard", str(kb_path), "--budget", "20", "-o", str(out),
                            "--arm", str(toml), "--model-class", "knn"])
    assert r.exit_code == 0, r.output
    from kbcli.io.artifact import read_artifact

    arm = read_artifact(out).config["sim"]["arm"]
    assert arm["preset"] == "custom" and arm["finger_radius"] == 1.5


@pytest.mark.parametrize("arm", ["ideal", "realistic"])
def test_servo_on_chipmunk_takes_the_same_steps_as_through_pymunk(arm):
    """The fast path of each servo (chipmunk called directly: the velocity servo of the ideal arm,
    the torque servo of the realistic one) is its public-API loop, to the bit: same landings, same
    step counts, same felt positions."""
    from kbcli.sim.arm import DynamicsReacher, _chipmunk

    cfg = SimConfig(mode="dynamics", arm=arm, reach_noise=1.0)
    rng = np.random.default_rng(3)
    targets = np.column_stack([rng.uniform(200, 600, 25), rng.uniform(250, 450, 25)])
    fast, public = DynamicsReacher(cfg), DynamicsReacher(cfg)
    assert _chipmunk(fast) is not None  # the pymunk we pin exposes chipmunk
    public._drive = public._drive_public
    public._drive_torque = public._drive_torque_public
    a = fast.reach(targets, np.random.default_rng(4))
    b = public.reach(targets, np.random.default_rng(4))
    assert np.array_equal(a, b)
    assert np.array_equal(fast.last_steps, public.last_steps)
    assert np.array_equal(fast.last_felt, public.last_felt)
    assert fast.last_steps.min() > 12  # every reach moved and settled


def test_ideal_mode_says_which_part_of_the_arm_it_ignores():
    from kbcli.sim import ideal_mode_note

    assert ideal_mode_note(PRESETS.get("ideal"), "ideal") is None
    assert ideal_mode_note(PRESETS.get("servo"), "dynamics") is None
    assert "it is the ideal arm here" in ideal_mode_note(PRESETS.get("servo"), "ideal")
    assert "finger and proprioception act" in ideal_mode_note(PRESETS.get("realistic"), "ideal")


def test_play_notes_an_ignored_servo_on_stderr(runner, tmp_path):
    from pathlib import Path

    golden = Path(__file__).resolve().parent.parent / "data" / "golden"
    r = runner.invoke(app, ["play", "--model", str(golden / "model.h5"), "--scene",
                            str(golden / "scene.h5"), "--steps", "2", "--arm", "servo", "-o",
                            str(tmp_path / "h.h5")])
    assert r.exit_code == 0, r.output
    assert "servo and friction are ignored" in r.stderr and "no physics" not in r.stdout
