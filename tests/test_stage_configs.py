"""The adapt and evaluate stages' configs on the pydantic base (issue 25): known answers, one-line
errors naming the table and the key, round trips, and every stored config still read as it was."""

from __future__ import annotations

import pickle
from pathlib import Path

import pytest

from kbcli.core.adaptation.config import AdapterConfig
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact
from kbcli.stages.adapt import AdaptConfig, PlayCheck
from kbcli.stages.evaluate import Category, EvaluateConfig, Method

DATA = Path(__file__).resolve().parent.parent / "data"


def _error(fn, *fragments):
    with pytest.raises(ConfigError) as exc:
        fn()
    msg = str(exc.value)
    assert "\n" not in msg
    for f in fragments:
        assert f in msg, msg
    return msg


# -- AdaptConfig ---------------------------------------------------------------------------------
def test_adapt_config_nests_flat_robot_options():
    cfg = AdaptConfig(strategy="random", resolution=1.0, mode="dynamics", max_steps=5)
    assert cfg.robot == AdapterConfig(strategy="random", resolution=1.0)
    assert (cfg.strategy.name, cfg.resolution, cfg.mode, cfg.max_steps) == ("random", 1.0, "dynamics",
                                                                          5)
    # a flat option overrides the robot table's, in the constructor as in from_dict
    both = AdaptConfig(robot=AdapterConfig(strategy="active"), strategy="infogain")
    assert both.robot.strategy.name == "infogain"
    assert AdaptConfig.from_dict(cfg.to_dict()) == cfg
    assert pickle.loads(pickle.dumps(cfg)) == cfg
    assert hash(cfg) == hash(AdaptConfig.from_dict(cfg.to_dict()))


def test_adapt_config_replace_and_with_robot():
    cfg = AdaptConfig(max_steps=7)
    aim = cfg.replace(reach_noise=2.0, feedback="aim")
    assert (aim.max_steps, aim.reach_noise, aim.feedback) == (7, 2.0, "aim")
    assert aim.adapter_config().blur == 2.0 and aim.robot.blur == 0.0
    assert cfg.replace(strategy="random").robot.strategy.name == "random"  # flat robot option
    assert cfg.with_robot(family="rigid").robot.family == "rigid"
    assert cfg.max_steps == 7 and cfg.feedback == "landed"  # frozen: copies, never edits
    with pytest.raises(Exception):  # noqa: B017 (pydantic's frozen-instance error)
        cfg.max_steps = 3


def test_adapt_config_errors_are_one_line():
    _error(lambda: AdaptConfig(max_steps=0), "adapt.max_steps", "a whole number in [1, 10000]")
    _error(lambda: AdaptConfig(stop="yes"), "adapt.stop")
    _error(lambda: AdaptConfig(feedback="telepathy"), "adapt.feedback", "unknown feedback",
           "landed, aim")
    _error(lambda: AdaptConfig(mode="flying"), "unknown sim mode 'flying'", "ideal, dynamics")
    # an unknown key lists the robot's options too (they are accepted at the top level)
    _error(lambda: AdaptConfig.from_dict({"speed": 3}), "unknown adapt option 'speed'",
           "strategy", "mode")
    _error(lambda: AdaptConfig.from_dict({"robot": 3}), "adapt.robot must be a table")
    _error(lambda: AdaptConfig(strategy="psychic"), "unknown strategy 'psychic'")
    _error(lambda: PlayCheck(notes=0), "play.notes", "a whole number in [1, 100000]")


# -- EvaluateConfig ------------------------------------------------------------------------------
def test_evaluate_config_known_answers():
    cfg = EvaluateConfig(thresholds=(1, 10.0, 4.0, 10.0), snapshot_steps=(5, 1, 5),
                         reach_noise={"dynamics": 3})
    assert cfg.thresholds == (10.0, 4.0, 1.0)  # distinct, largest first, floats
    assert cfg.snapshot_steps == (1, 5)
    assert dict(cfg.reach_noise) == {"ideal": 0.0, "dynamics": 3.0}  # every mode
    assert set(cfg.arm) == {"ideal", "dynamics"}
    assert [m.name for m in cfg.methods] == ["paper", "kbcli"] and cfg.judged == "paper"
    assert [c.name for c in cfg.categories] == ["small", "medium", "large"]
    assert cfg.strategies == ("random", "paper-active", "active", "infogain") and cfg.n_params == 2
    assert EvaluateConfig.from_dict(cfg.to_dict()) == cfg
    assert pickle.loads(pickle.dumps(cfg)) == cfg
    fewer = cfg.replace(experiments=2)
    assert fewer.experiments == 2 and fewer.methods == cfg.methods and cfg.experiments == 50
    one = cfg.with_overrides(mode="ideal", methods=("kbcli",))
    assert one.modes == ("ideal",) and [m.name for m in one.methods] == ["kbcli"]
    assert one.judged == "kbcli"


def test_size_categories_take_their_bounds():
    small = Category(name="small", displacements=[[3, 4]])
    assert (small.limit, small.lower, small.displacements) == (10.0, 0.0, ((3.0, 4.0),))
    assert Category(name="medium", displacements=[[12.0, 0.0]]).lower == 10.0
    _error(lambda: Category(name="huge", displacements=[[1.0, 1.0]]), "categories.huge",
           "limit is needed")
    _error(lambda: Category(name="small", limit=-1.0, displacements=[[1.0, 1.0]]),
           "categories.small.limit", "greater than 0")
    _error(lambda: Category(name="small", displacements=[]), "categories.small.displacements")
    _error(lambda: Category(name="small", displacements=[[1.0, "a"]]),
           "categories.small.displacements")


def test_methods_check_their_own_table():
    m = Method.from_table("m", {"strategies": ["random"], "posterior": "kde",
                                "robot": {"estimator": "ml"}})
    assert m.options["posterior"] == "kde" and m.to_dict() == {
        "strategies": ["random"], "posterior": "kde", "robot": {"estimator": "ml"}}
    _error(lambda: Method.from_table("m", {"strategies": ["random", "random"]}),
           "methods.m.strategies", "twice")
    _error(lambda: Method.from_table("m", {"strategies": ["random"], "modes": ["x"]}),
           "methods.m.modes", "unknown mode 'x'")
    _error(lambda: Method.from_table("m", {"strategies": ["random"],
                                           "robot": {"max_steps": 3}}),
           "methods.m.max_steps is set per experiment")
    _error(lambda: Method.from_table("m", 3), "methods.m must be a table")


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ({"seed": -1}, "evaluate.seed must be greater than or equal to 0"),
        ({"seed": 1.5}, "evaluate.seed must be a whole number"),
        ({"thresholds": []}, "evaluate.thresholds"),
        ({"reach_noise": {"dynamics": -1.0}}, "evaluate.reach_noise.dynamics"),
        ({"reach_noise": {"flying": 1.0}}, "evaluate.reach_noise: unknown mode 'flying'"),
        ({"arm": {"flying": "ideal"}}, "evaluate.arm: unknown mode 'flying'"),
        ({"melody": " "}, ("evaluate.melody", "must be notes like 'A:1 D:1'")),
        ({"family": "shear"}, "unknown"),
        ({"methods": {}}, "evaluate.methods must hold at least one table"),
        ({"strategies": ["random"], "methods": {"m": {"strategies": ["random"]}}},
         "not both"),
    ],
)
def test_evaluate_config_errors_are_one_line(change, fragment):
    fragments = fragment if isinstance(fragment, tuple) else (fragment,)
    _error(lambda: EvaluateConfig.from_dict(change), *fragments)


# -- stored configs --------------------------------------------------------------------------------
@pytest.mark.parametrize("path", sorted(DATA.rglob("evaluation.h5")), ids=str)
def test_every_stored_evaluation_config_is_read(path):
    art = read_artifact(path)
    cfg = EvaluateConfig.from_dict(art.config)
    assert EvaluateConfig.from_dict(cfg.to_dict()) == cfg
    if "golden" in path.parts:  # written by today's code: it reads back to the same dict
        assert cfg.to_dict() == art.config


@pytest.mark.parametrize("path", sorted(DATA.rglob("run.h5")), ids=str)
def test_every_stored_adapt_config_is_read(path):
    art = read_artifact(path)
    cfg = AdaptConfig.from_dict(art.config["adapt"])
    if "golden" in path.parts:
        assert cfg.to_dict() == art.config["adapt"]


def test_learn_config_replace_keeps_its_arm():
    """``replace`` round-trips the ``sim`` table through its dict form (it was refused: a SimConfig
    instance only), and a bad table is refused naming the field."""
    from kbcli.sim import SimConfig
    from kbcli.stages.learn import LearnConfig

    cfg = LearnConfig(sim=SimConfig(mode="dynamics", arm="realistic"), budget=300)
    copy = cfg.replace(budget=100)
    assert copy.budget == 100 and copy.sim == cfg.sim and copy.sim.mode == "dynamics"
    with pytest.raises(ConfigError, match="learn.sim.mode"):
        LearnConfig(sim={"mode": "warp"})
