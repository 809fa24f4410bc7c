"""``kbcli adapt``, ``kbcli plot adapt``, ``kbcli bench adapt``, the stage API and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import one_line_error as _one_line_error

from kbcli.cli import app
from kbcli.core.adaptation.config import SLOTS
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.core.options import flat_view
from kbcli.errors import ArtifactError, ConfigError, KbcliError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import adapt as stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact
from kbcli.stages.perturb import PerturbConfig
from kbcli.stages.perturb import run as perturb_run


@pytest.fixture
def files(tmp_path):
    kb_art = keyboard_stage.run(KeyboardConfig())
    write_artifact(kb_art, tmp_path / "kb.h5")
    model = exact_artifact(kb_art)
    write_artifact(model, tmp_path / "model.h5")
    rng = np.random.default_rng(0)
    write_artifact(perturb_run(PerturbConfig(params=(8.3, -5.6)), kb_art, rng=rng),
                   tmp_path / "scene.h5")
    write_artifact(perturb_run(PerturbConfig(family="rigid", params=(1.2, 4.0, 6.5)), kb_art,
                               rng=rng), tmp_path / "rigid.h5")
    other = keyboard_stage.run(KeyboardConfig(cols=6))
    write_artifact(perturb_run(PerturbConfig(params=(3.0, 3.0)), other, rng=rng),
                   tmp_path / "other_scene.h5")
    return tmp_path


def _adapt(runner, files, *extra, out="run.h5", scene="scene.h5", model="model.h5"):
    return runner.invoke(app, ["adapt", "--model", str(files / model), "--scene",
                               str(files / scene), "-o", str(files / out), "--prior-halfwidth",
                               "20", *extra])


def test_adapt_writes_a_run_and_plots_it(runner, files):
    r = _adapt(runner, files, "--max-steps", "12", "--seed", "3")
    assert r.exit_code == 0, r.output
    assert "final error" in r.output and "below 1 px" in r.output
    art = read_artifact(files / "run.h5", "run")
    d = art.data
    assert d["actions"].shape == (12, 2) and d["errors"].shape == (12,)
    assert d["estimates"].shape == (12, 2) and d["entropy"].shape == (12,)
    assert d["timing"]["step_ms"].shape == (12,) and d["classes"].dtype.kind == "i"
    assert list(d["snapshot_steps"]) == [0, 1, 2, 3, 5, 10]
    assert d["snapshots"].shape == (6, 81, 81)
    assert d["errors"][-1] < 1.0 and art.attrs["steps_to_1px"] <= 12
    assert art.inputs["model"]["kind"] == "model" and art.inputs["scene"]["kind"] == "scene"
    assert art.config["adapt"]["max_steps"] == 12 and art.seed == 3
    r = runner.invoke(app, ["plot", "adapt", str(files / "run.h5"), "-o", str(files / "a.png")])
    assert r.exit_code == 0, r.output
    assert (files / "a.png").read_bytes()[:4] == b"\x89PNG"


def test_adapt_is_deterministic_except_timing(runner, files):
    # a 2 px hypothesis grid, not the default 0.5 px: the same code, tables 16 times smaller
    for name in ("a.h5", "b.h5"):
        r = _adapt(runner, files, "--max-steps", "6", "--strategy", "active", "--resolution", "2",
                   out=name)
        assert r.exit_code == 0, r.output
    a = read_artifact(files / "a.h5").data
    b = read_artifact(files / "b.h5").data
    for k in a:
        if k != "timing":
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_adapt_rigid_scene_and_kde_posterior(runner, files):
    r = _adapt(runner, files, "--max-steps", "5", "--posterior", "kde", "--snapshots", "0,5",
               scene="rigid.h5")
    assert r.exit_code == 0, r.output
    art = read_artifact(files / "run.h5", "run")
    assert art.config["adapt"]["robot"]["family"] == "rigid"  # the scene's family by default
    assert r.stderr.count("family: rigid, the scene's") == 1  # said once, on stderr
    r = _adapt(runner, files, "--max-steps", "2", "--family", "translation", "--resolution", "2",
               scene="rigid.h5")
    assert r.exit_code == 0, r.output
    assert "family:" not in r.stderr  # chosen, not defaulted
    assert art.data["estimates"].shape == (5, 3) and "angle error" in r.output
    assert art.data["snapshot_angles"].shape[0] == 2


def test_stage_experiment_api():
    kb = Keyboard(KeyboardConfig())
    cfg = stage.AdaptConfig.flat(max_steps=8, prior_halfwidth=20.0, strategy="random")
    res = stage.experiment(cfg, ExactModel(kb), kb, np.array([3.0, 4.0]),
                           rng=np.random.default_rng(0), snapshot_steps=(0, 8))
    for key in ("actions", "landed", "classes", "estimates", "means", "errors", "angle_errors",
                "entropy", "step_ms"):
        assert len(res[key]) == 8, key
    assert res["snapshots"].shape == (2, 81, 81)
    assert np.all(res["angle_errors"] == 0)
    cfg2 = stage.AdaptConfig.from_dict(cfg.to_dict())
    assert cfg2 == cfg
    # the robot's config is held by composition; its options read through
    assert cfg.robot.prior_halfwidth == cfg.prior_halfwidth == 20.0
    assert set(cfg.to_dict()) == {"robot", *stage.LOOP_FIELDS}
    # the flat layout of schema-1 run artifacts and older TOML files is still read
    flat = {**cfg.to_dict()["robot"], **{k: v for k, v in cfg.to_dict().items() if k != "robot"}}
    assert stage.AdaptConfig.from_dict(flat) == cfg
    # a robot option at the top level overrides the robot table (as a flag overrides a TOML file)
    both = stage.AdaptConfig.from_dict({"robot": {"strategy": "active"}, "strategy": "infogain"})
    assert both.robot.strategy.name == "infogain"
    aim = stage.AdaptConfig.flat(feedback="aim", reach_noise=2.0)
    assert aim.adapter_config().blur == 2.0 and aim.robot.blur == 0.0
    with pytest.raises(ConfigError, match="unknown adapt option"):
        stage.AdaptConfig.from_dict({"strategy": "random", "speed": 3})
    with pytest.raises(ConfigError, match="feedback"):
        stage.AdaptConfig(feedback="telepathy")


def test_stage_refuses_mismatched_inputs(files):
    model = read_artifact(files / "model.h5")
    scene = read_artifact(files / "scene.h5")
    with pytest.raises(ArtifactError):
        stage.run(stage.AdaptConfig(), scene, scene, rng=np.random.default_rng(0))
    with pytest.raises(KbcliError, match="keyboard"):
        stage.run(stage.AdaptConfig(), model, read_artifact(files / "other_scene.h5"),
                  rng=np.random.default_rng(0))


@pytest.mark.parametrize(
    "args, kwargs, fragments",
    [
        ((), {"model": "scene.h5"}, ["scene artifact, expected model"]),
        ((), {"scene": "model.h5"}, ["model artifact, expected scene"]),
        ((), {"scene": "other_scene.h5"}, ["keyboard does not match"]),
        (("--max-steps", "0"), {}, ["adapt.max_steps", "a whole number in [1, 10000]"]),
        (("--strategy", "greedy"), {}, ["unknown strategy", "infogain"]),
        (("--posterior", "particles"), {}, ["unknown posterior", "kde"]),
        (("--resolution", "0.005"), {}, ["would need", "GB"]),
        (("--snapshots", "a,b"), {}, ["--snapshots"]),
        (("--model-blur", "-1"), {}, ["model_blur"]),
        (("--model-blur", "1000"), {}, ["model_blur", "<= 50"]),  # not a 35 GiB kernel
        (("--feedback", "vision"), {}, ["unknown feedback"]),
        ((), {"model": "missing.h5"}, ["no such file"]),
    ],
)
def test_adapt_bad_input(runner, files, args, kwargs, fragments):
    r = _adapt(runner, files, *args, out="bad.h5", **kwargs)
    _one_line_error(r, *fragments)
    assert not (files / "bad.h5").exists()
    assert not list(files.glob(".bad.h5*"))


def test_plot_adapt_refuses_other_kinds(runner, files):
    r = runner.invoke(app, ["plot", "adapt", str(files / "model.h5"), "-o", str(files / "x.png")])
    _one_line_error(r, "expected run")
    assert not (files / "x.png").exists()


def test_bench_adapt_small(runner):
    r = runner.invoke(app, ["bench", "adapt", "--experiments", "2", "-T", "4", "--section",
                            "exact", "--strategy", "random", "--strategy", "infogain",
                            "--category", "small"])
    assert r.exit_code == 0, r.output
    assert "infogain" in r.output and "rmse@3" in r.output and "p vs random" in r.output
    r = runner.invoke(app, ["bench", "adapt", "--section", "learned", "--experiments", "2"])
    _one_line_error(r, "learned model")


def test_bench_adapt_kde_prints_the_step_speed(runner, files):
    """The kde section times a KDE step on a model (here the exact one, few touches)."""
    r = runner.invoke(app, ["bench", "adapt", "--section", "kde", "--experiments", "2", "-T", "3",
                            "--strategy", "random", "--category", "small", "--kde-steps", "5",
                            "--model", str(files / "model.h5")])
    assert r.exit_code == 0, r.output
    assert "median ms/step" in r.output and "kde (Algorithm 2" in r.output
    assert "random/kde" in r.output and "paired" in r.output


def test_experiment_in_dynamics_mode():
    kb = Keyboard(KeyboardConfig())
    cfg = stage.AdaptConfig.flat(max_steps=3, prior_halfwidth=10.0, mode="dynamics", reach_noise=0.5)
    res = stage.experiment(cfg, ExactModel(kb), kb, np.array([2.0, -1.0]),
                           rng=np.random.default_rng(1))
    assert res["landed"].shape == (3, 2)
    # the arm does not land exactly where it aimed, and the robot observes where it landed
    assert not np.allclose(res["landed"], res["actions"])
    assert np.isfinite(res["errors"]).all()


def test_a_config_files_arm_table_is_read_beside_its_adapt_table(runner, files):
    """One file with [adapt] and [arm]: the arm is the run's (it was silently ignored); both [arm]
    and [adapt.arm], or an unknown preset there, are refused in one line."""
    conf = files / "a.toml"
    conf.write_text('[adapt]\nmax_steps = 2\n[arm]\npreset = "servo"\nfriction = 123.0\n')
    r = _adapt(runner, files, "--config", str(conf))
    assert r.exit_code == 0, r.output
    arm = read_artifact(files / "run.h5", "run").config["adapt"]["arm"]
    from kbcli.sim.arms import arm_config

    servo = arm_config("servo").to_dict()
    assert arm["friction"] == 123.0 and arm["kp"] == servo["kp"] != arm_config("ideal").kp
    conf.write_text('[adapt]\n[adapt.arm]\npreset = "servo"\n[arm]\npreset = "realistic"\n')
    _one_line_error(_adapt(runner, files, "--config", str(conf), out="bad.h5"), "both [arm]")
    conf.write_text('[adapt]\n[arm]\npreset = "wobbly"\n')
    _one_line_error(_adapt(runner, files, "--config", str(conf), out="bad.h5"), "wobbly")
    assert not (files / "bad.h5").exists()


# -- the paper method's options as flags (issue 26) -----------------------------------------------
def test_paper_method_flags_reach_the_run(runner, files):
    """Options once reachable only through TOML are flags; their values are the run's (recorded in
    its config); kbcli inspect shows only the options the run's method reads, --json every one."""
    r = _adapt(runner, files, "--posterior", "kde", "--strategy", "paper-active", "--estimator",
               "ml", "--kde-floor", "0", "--kde-draw", "fresh", "--kde-sampler", "raster",
               "--kde-samples", "500", "--ml-ties", "random", "--stop-ml", "0.02", "--stop-mass",
               "0", "--candidates", "16", "--active-keep", "3", "--max-steps", "3")
    assert r.exit_code == 0, r.output
    robot = flat_view(read_artifact(files / "run.h5", "run").config["adapt"]["robot"], SLOTS)
    assert {k: robot[k] for k in ("posterior", "strategy", "kde_floor", "kde_draw", "kde_sampler",
                                  "kde_samples", "ml_ties", "stop_ml", "stop_mass", "candidates",
                                  "active_keep")} == {
        "posterior": "kde", "strategy": "paper-active", "kde_floor": 0.0, "kde_draw": "fresh",
        "kde_sampler": "raster", "kde_samples": 500, "ml_ties": "random", "stop_ml": 0.02,
        "stop_mass": 0.0, "candidates": 16, "active_keep": 3}
    r = _adapt(runner, files, "--strategy", "random", "--random-actions", "model", "--max-steps",
               "2", out="random.h5")
    assert r.exit_code == 0, r.output
    assert read_artifact(files / "random.h5", "run").config["adapt"]["robot"]["strategy"][
        "random_actions"] == "model"
    table = runner.invoke(app, ["inspect", str(files / "run.h5")]).output
    assert "adapt.robot.kde_floor" in table and "adapt.robot.active_keep" in table
    assert "robust_eta" not in table and "hypotheses" not in table and "not shown" in table
    assert "max_angle" not in table  # recorded, not read (the family does not rotate)
    full = runner.invoke(app, ["inspect", "--json", str(files / "run.h5")]).output
    assert '"max_angle"' in full and '"robust_eta": 1.0' in full  # every option, every summary


@pytest.mark.parametrize(
    "args, fragments",
    [
        (("--kde-floor", "0"), ["adapt: --kde-floor does not apply",
                                "posterior likelihood takes no option 'kde_floor'",
                                "posterior kde does"]),
        (("--posterior", "kde", "--kde-sampler", "raster"),
         ["--kde-sampler does not apply", 'kde_draw = "fresh"']),
        (("--ml-ties", "random"), ["--ml-ties does not apply", "the estimator is mean",
                                   "strategy infogain"]),
        (("--strategy", "random", "--candidates", "8"),
         ["--candidates does not apply", "strategy random takes no option 'candidates'"]),
        (("--strategy", "infogain", "--active-keep", "2"),
         ["--active-keep does not apply", "strategy infogain takes no option"]),
        (("--random-actions", "model"), ["--random-actions does not apply",
                                         "strategy random does"]),
        (("--kde-draw", "sometimes", "--posterior", "kde"), ["kde_draw", "shared, fresh"]),
        (("--candidates", "0"), ["candidates"]),
    ],
)
def test_adapt_refuses_flags_the_method_does_not_read(runner, files, args, fragments):
    r = _adapt(runner, files, *args, out="bad.h5")
    _one_line_error(r, *fragments)
    assert not (files / "bad.h5").exists()


def test_adapt_refuses_a_config_files_option_the_method_does_not_read(runner, files):
    conf = files / "a.toml"
    conf.write_text('[adapt]\nmax_steps = 2\nrobust_eta = 0.5\n')
    r = _adapt(runner, files, "--config", str(conf), "--posterior", "kde", out="bad.h5")
    _one_line_error(r, "adapt: robust_eta (in", "a.toml) does not apply",
                    "posterior kde takes no option 'robust_eta'", "posterior likelihood does")
    conf.write_text('[adapt]\nmax_steps = 2\n[adapt.robot]\nrobust = false\nrobust_blurs = [1.0]\n')
    _one_line_error(_adapt(runner, files, "--config", str(conf), out="bad.h5"),
                    "robust_blurs (in", "robust = false")
    assert not (files / "bad.h5").exists()


def test_run_refuses_flags_the_method_does_not_read_and_records_those_it_reads(runner, files):
    base = ["run", "--model", str(files / "model.h5"), "--scene", str(files / "scene.h5"),
            "--steps", "30", "--perturb-at", "16", "--n-lt", "10", "--n-st", "5"]
    r = runner.invoke(app, [*base, "-o", str(files / "bad.h5"), "--posterior", "likelihood",
                            "--kde-floor", "0"])
    _one_line_error(r, "run: --kde-floor does not apply", "posterior kde")
    assert not (files / "bad.h5").exists()
    r = runner.invoke(app, [*base, "-o", str(files / "loop.h5"), "--posterior", "kde",
                            "--kde-floor", "0.01", "--stop-ml", "0.1", "--stop-mass", "0",
                            "--candidates", "32"])
    assert r.exit_code == 0, r.output
    robot = flat_view(read_artifact(files / "loop.h5").config["loop"]["adapt"]["robot"], SLOTS)
    assert (robot["kde_floor"], robot["stop_ml"], robot["stop_mass"], robot["candidates"]) == (
        0.01, 0.1, 0.0, 32)


def test_adapt_says_nothing_of_options_the_user_never_gave(runner, files):
    """Issue 40: `adapt -T 3` warned about --snapshots steps nobody asked for, and every run said
    "family: translation, the scene's"."""
    r = _adapt(runner, files, "-T", "3")
    assert r.exit_code == 0, r.output
    assert r.stderr == "", r.stderr
    assert read_artifact(files / "run.h5", "run").data["snapshot_steps"].tolist() == [0, 1, 2, 3]
    r = _adapt(runner, files, "-T", "3", "--snapshots", "0,5", out="r5.h5")
    assert r.exit_code == 0 and "--snapshots 5 beyond --max-steps 3" in r.stderr
    r = _adapt(runner, files, "-T", "2", scene="rigid.h5", out="rigid_run.h5")
    assert r.exit_code == 0 and "family: rigid, the scene's" in r.stderr  # not the usual one


def test_adapt_reads_snapshot_steps_from_its_config(runner, files):
    """`kbcli inspect` shows snapshot_steps as a run's key; [adapt] snapshot_steps is accepted."""
    # resolution = 2 (not the default 0.5 px): the snapshot steps do not depend on the grid
    (files / "a.toml").write_text("[adapt]\nmax_steps = 4\nsnapshot_steps = [0, 2, 4]\n"
                                  "resolution = 2.0\n")
    r = _adapt(runner, files, "--config", str(files / "a.toml"))
    assert r.exit_code == 0, r.output
    art = read_artifact(files / "run.h5", "run")
    assert art.data["snapshot_steps"].tolist() == [0, 2, 4]
    assert art.config["snapshot_steps"] == [0, 2, 4]
    r = _adapt(runner, files, "--config", str(files / "a.toml"), "--snapshots", "1", out="r1.h5")
    assert read_artifact(files / "r1.h5", "run").data["snapshot_steps"].tolist() == [1]
