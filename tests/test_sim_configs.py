"""Configs of the simulator, the detector and the play / run / serve / perturb stages on the
pydantic ``Config`` base: bad values refused with one line naming the key and the accepted range,
round trips through ``to_dict`` / ``from_dict``, and the registries (sim modes, arm presets,
detectors) answering an unknown name with the valid ones."""

from __future__ import annotations

import pytest

from kbcli.core.config import Config, Count, Number, Whole, between
from kbcli.errors import ConfigError


# -- the Config base: nested errors and intervals ---------------------------------------------
class _Inner(Config):
    what = "detector"
    n_st: Count = 10


class _Outer(Config):
    what = "loop"
    detector: _Inner = _Inner()


def test_a_nested_config_error_names_the_key_once():
    with pytest.raises(ConfigError) as e:
        _Outer(detector={"n_st": 0})
    assert str(e.value) == "loop.detector.n_st must be greater than or equal to 1, got 0"
    with pytest.raises(ConfigError) as e:
        _Outer.from_dict({"detector": {"n_sd": 3}})
    assert str(e.value).startswith("unknown loop.detector option 'n_sd'; valid: n_st")
    with pytest.raises(ConfigError) as e:  # the inner config alone keeps its own name
        _Inner(n_st=0)
    assert str(e.value) == "detector.n_st must be greater than or equal to 1, got 0"


class _Bounded(Config):
    what = "play"
    steps: between(Whole, 1, 1000) = 3
    rate: between(Number, 0, 1, low_open=True, high_open=True) = 0.5


@pytest.mark.parametrize(("kw", "line"), [
    ({"steps": 10**9}, "play.steps must be a whole number in [1, 1000], got 1000000000"),
    ({"steps": 0}, "play.steps must be a whole number in [1, 1000], got 0"),
    ({"steps": 3.0}, "play.steps must be a whole number, got 3.0"),
    ({"rate": 1.0}, "play.rate must be a number in (0, 1), got 1.0"),
    ({"rate": 0}, "play.rate must be a number in (0, 1), got 0.0"),
])
def test_between_names_the_whole_interval(kw, line):
    with pytest.raises(ConfigError) as e:
        _Bounded(**kw)
    assert str(e.value) == line


# -- the configs of sim, detect and the stages --------------------------------------------------
from kbcli.core.detection.detectors import DETECTORS, MAX_N_LT, MAX_N_ST, DetectorConfig  # noqa: E402
from kbcli.sim import MODES, PRESETS, ArmConfig, SimConfig, arm_config, make_reacher  # noqa: E402
from kbcli.sim.arms import MAX_SETTLE_TIME  # noqa: E402
from kbcli.stages.perturb import PerturbConfig  # noqa: E402
from kbcli.stages.play import MAX_PLAY_STEPS, PlayConfig  # noqa: E402
from kbcli.stages.run import MAX_ADAPT_STEPS, MAX_LOOP_STEPS, LoopConfig  # noqa: E402
from kbcli.stages.serve import MAX_SERVE_STEPS, ServeConfig  # noqa: E402


def _line(make, *args, **kw) -> str:
    with pytest.raises(ConfigError) as e:
        make(*args, **kw)
    text = str(e.value)
    assert "\n" not in text
    return text


@pytest.mark.parametrize(("make", "kw", "line"), [
    (SimConfig, {"reach_noise": -1.0}, "sim.reach_noise must be a number in [0, 100], got -1.0"),
    (SimConfig, {"link_lengths": (320.0, 0.0)}, "sim.link_lengths[1] must be a number in (0, 10000]"),
    (SimConfig, {"mode": "teleport"}, "valid: ideal, dynamics"),
    (SimConfig, {"arm": {"kp": -1.0}}, "sim.arm.kp must be a number in (0, 10000000000], got -1.0"),
    (SimConfig, {"reach_noise": 1e308}, "sim.reach_noise must be a number in [0, 100], got 1e+308"),
    (SimConfig, {"base": (400.0,)}, "sim.base has too few values (no value [1]), got [400.0]"),
    (ArmConfig, {"finger_radius": 1e300}, "arm.finger_radius must be a number in [0, 50]"),
    (ArmConfig, {"max_torque": 1e300}, "arm.max_torque must be a number in (0, 10000000000]"),
    (SimConfig, {"speed": 3}, "unknown sim option 'speed'"),
    (ArmConfig, {"settle_time": 1e9}, f"arm.settle_time must be a number <= {MAX_SETTLE_TIME:g}"),
    (ArmConfig, {"proprio_bias": (0.5, 0.0)}, "arm.proprio_bias[0] must be a number in [-0.1, 0.1]"),
    (DetectorConfig, {"n_lt": 10**9}, f"detector.n_lt must be a whole number in [1, {MAX_N_LT}]"),
    (DetectorConfig, {"n_st": 10**9}, f"detector.n_st must be a whole number in [1, {MAX_N_ST}]"),
    (DetectorConfig, {"detector": "bocpd", "hazard": 1.0},
     "detector.detector.hazard must be a number in (0, 1), got 1.0"),
    (DetectorConfig, {"n_lt": 10.0}, "detector.n_lt must be a whole number, got 10.0"),
    (PerturbConfig, {"category": "small", "max_angle": 1e9},
     "perturb.max_angle must be a number in [0, 180]"),
    (PlayConfig, {"steps": 10**9}, f"play.steps must be a whole number in [1, {MAX_PLAY_STEPS}]"),
    (PlayConfig, {"melody": "A:1 " * 10**5}, "play.melody must be at most"),
    (PlayConfig, {"reach_noise": float("inf")}, "play.reach_noise must be a finite number"),
    (LoopConfig, {"steps": 10**9}, f"loop.steps must be a whole number in [1, {MAX_LOOP_STEPS}]"),
    (LoopConfig, {"max_adapt_steps": 10**9},
     f"loop.max_adapt_steps must be a whole number in [1, {MAX_ADAPT_STEPS}]"),
    (LoopConfig, {"detector": {"threshold": 2.0}},
     "loop.detector.threshold must be a number in (0, 1), got 2.0"),
    (ServeConfig, {"max_steps": 10**9},
     f"serve.max_steps must be a whole number in [1, {MAX_SERVE_STEPS}]"),
    (ServeConfig, {"stop": "yes"}, "serve.stop must be true or false"),
])
def test_bad_values_are_refused_with_one_line_naming_key_and_range(make, kw, line):
    assert line in _line(make, **kw)


@pytest.mark.parametrize("cfg", [
    SimConfig(mode="dynamics", base=(410.0, 5.0), reach_noise=1.5, arm="realistic"),
    ArmConfig(preset="custom", kp=3.0, finger_radius=1.0, proprio_bias=(0.01, -0.02)),
    DetectorConfig(detector="bocpd", n_lt=50, n_st=5, prior=(0.5, 2.0)),
    PerturbConfig(family="rigid", params=(1.0, 2.0, 3.0)),
    PerturbConfig(category="large", max_angle=2.0),
    PlayConfig(steps=20, perturb_at=3, mode="dynamics", arm="servo"),
    LoopConfig(steps=400, perturb_at=150, detector=DetectorConfig(detector="cusum", n_lt=60,
                                                                  n_st=6)),
    ServeConfig(max_steps=12, stop=False),
])
def test_configs_round_trip(cfg):
    d = cfg.to_dict()
    assert type(cfg).from_dict(d) == cfg
    assert type(cfg).from_dict(d).to_dict() == d


def test_the_stored_sim_table_reads_back():
    """The ``sim`` table as artifacts store it (learn, play, perturb write ``to_dict``)."""
    stored = {"mode": "dynamics", "base": [400.0, 0.0], "link_lengths": [320, 280],
              "reach_noise": 1, "arm": {"preset": "ideal", "kp": None, "kd": 0.0,
                                        "max_torque": 5e8, "friction": 0.0, "settle_time": 8.0,
                                        "finger_radius": 0.0, "proprio_noise": 0.0,
                                        "proprio_bias": [0.0, 0.0]}}
    cfg = SimConfig.from_dict(stored)
    assert cfg == SimConfig(mode="dynamics", reach_noise=1.0)
    assert cfg.arm is PRESETS.get("ideal") or cfg.arm == PRESETS.get("ideal")


@pytest.mark.parametrize(("registry", "valid"), [
    (MODES, "valid: ideal, dynamics"),
    (PRESETS, "valid: ideal, servo, realistic"),
    (DETECTORS, "valid: binomial, cusum, bocpd"),
])
def test_unknown_names_list_the_valid_ones(registry, valid):
    assert _line(registry.get, "nonesuch") == f"unknown {registry.kind} 'nonesuch'; {valid}"


def test_names_reach_the_registries_through_the_configs():
    assert "valid: ideal, servo, realistic" in _line(arm_config, "clumsy")
    assert "valid: binomial, cusum, bocpd" in _line(DetectorConfig, detector="page")
    assert "valid: ideal, dynamics" in _line(PlayConfig, mode="warp")
    ideal = make_reacher(SimConfig())
    assert type(ideal) is type(MODES.get("ideal").reacher(SimConfig()))
    assert not MODES.get("ideal").physics and MODES.get("dynamics").physics
