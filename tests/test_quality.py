"""The model-quality sweep (issue 9): config, a tiny end-to-end run, the report's verdicts."""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.cli import app
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import quality as stage
from kbcli.stages.artifact import Artifact

TINY = """
[quality]
seed = 3
budgets = [40, 120]
explorations = ["random"]
mode = "ideal"
arm = "ideal"
experiments = 2
max_steps = 6
[quality.rows]
random = { strategy = "random" }
infogain = { strategy = "infogain" }
[quality.categories.small]
limit = 10.0
displacements = [[3.0, -2.0]]
[quality.adapt]
resolution = 2.0  # each model's likelihood table in 1 s, not 10
"""


@pytest.fixture(scope="module")
def small_kb(tmp_path_factory):
    path = tmp_path_factory.mktemp("kb") / "kb.h5"
    write_artifact(keyboard_stage.run(KeyboardConfig(rows=2, cols=3)), path)
    return path


@pytest.fixture(scope="module")
def tiny_sweep(small_kb, tmp_path_factory):
    """The TINY sweep run once through the CLI: (its command line without the output, the output,
    the CLI result). Shared by the tests that check its artifact, its report, that a second run
    gives the same numbers and that an interrupted run resumes to them."""
    from typer.testing import CliRunner

    tmp = tmp_path_factory.mktemp("tiny")
    conf = tmp / "q.toml"
    conf.write_text(TINY)
    base = ["quality", "--config", str(conf), "--keyboard", str(small_kb)]
    out = tmp / "q.h5"
    return base, out, CliRunner().invoke(app, [*base, "-o", str(out)])


def test_the_default_pipeline_config_is_valid():
    from kbcli.io.config import load_toml

    cfg = stage.QualityConfig.from_dict(load_toml("pipelines/model-quality.toml", "quality"))
    assert cfg.arm["preset"] == "realistic" and cfg.mode == "dynamics"
    assert min(cfg.budgets) <= 150 and max(cfg.budgets) >= 1600
    assert cfg.experiments * 4 >= 30  # 30 runs or more per (model, category, row) cell
    assert cfg.ideal  # and the exact model's reference runs once, on the same displacements
    assert len(stage.plan(cfg)) == (len(cfg.budgets) * len(cfg.explorations) * 12
                                    * len(cfg.rows) * cfg.experiments + 12 * cfg.experiments)


def test_the_variants_pipeline_reuses_the_sweeps_weak_active_models():
    """pipelines/infogain-variants.toml learns the same models as the sweep (same seeds, mode and
    arm), so its numbers compare with the sweep's."""
    from kbcli.io.config import load_toml

    main = stage.QualityConfig.from_dict(load_toml("pipelines/model-quality.toml", "quality"))
    var = stage.QualityConfig.from_dict(load_toml("pipelines/infogain-variants.toml", "quality"))
    assert (var.seed, var.mode, var.arm, var.reach_noise) == (main.seed, main.mode, main.arm,
                                                              main.reach_noise)
    learned = stage.learn_tasks(var)  # the same models: same names, budgets and seeds
    assert learned == stage.learn_tasks(main)[:len(learned)]
    assert var.baseline == main.baseline and "infogain" in var.rows and len(var.rows) >= 3
    assert len(stage.plan(var)) == len(var.budgets) * 12 * len(var.rows) * var.experiments


@pytest.mark.parametrize("table", [
    {"explorations": ["psychic"]}, {"budgets": [5]}, {"rows": {}},
    {"rows": {"a": {"strategy": "random", "mode": "ideal"}}}, {"baseline": "nobody"},
    {"adapt": {"strategy": "random"}}, {"arm": "clumsy"}, {"mode": "teleport"}, {"budget": [10]},
    {"ideal": "yes"}, {"rows": {"random": {"strategy": "random"},
                                stage.IDEAL_ROW: {"strategy": "infogain"}}},
])
def test_bad_quality_configs_are_refused(table):
    with pytest.raises(ConfigError):
        stage.QualityConfig.from_dict(table)


@pytest.mark.parametrize("table,fragments", [
    ({"budgets": [100, 5]}, ["quality.budgets", "a whole number in [10, 20000]", "got 5"]),
    ({"budgets": []}, ["quality.budgets", "at least one budget"]),
    ({"budgets": [True]}, ["quality.budgets", "whole number"]),
    ({"budgets": [100, 150, 100]}, ["quality.budgets", "each budget once", "got 100"]),
    ({"seed": -1}, ["quality.seed", "greater than or equal to 0", "got -1"]),
    ({"experiments": 2.0}, ["quality.experiments", "whole number", "got 2.0"]),
    ({"reach_noise": -0.5}, ["quality.reach_noise", "in [0, 100]", "got -0.5"]),
    ({"ideal": "yes"}, ["quality.ideal", "true or false"]),
    ({"mode": "teleport"}, ["quality.mode", "'teleport'", "ideal, dynamics"]),
    ({"explorations": ["psychic"]}, ["quality.explorations", "'psychic'", "active, random"]),
    ({"arm": "clumsy"}, ["quality.arm", "'clumsy'", "realistic"]),
    ({"rows": {"a": {"strategy": "random", "mode": "ideal"}}}, ["quality.rows", "a.mode",
                                                                 "set by the sweep"]),
    ({"baseline": "nobody"}, ["quality.baseline", "'nobody'", "random, active"]),
    ({"adapt": {"max_steps": 3}}, ["quality.adapt", "max_steps"]),
    ({"rows": {"random": {"strategy": "psychic"}}}, ["quality", "row 'random'", "'psychic'"]),
    ({"categories": {"a": {"limit": 3}}}, ["quality.categories", "displacements"]),
    ({"budget": [10]}, ["unknown quality option 'budget'", "budgets"]),
    ({"rows": {"random": {"strategy": "random", "candidates": 9}}},
     ["rows.random: candidates does not apply", "strategy active, paper-active and infogain do"]),
    ({"adapt": {"kde_floor": 0.01}}, ["quality: adapt.kde_floor does not apply to any row",
                                      "posterior kde"]),
])
def test_bad_quality_config_messages_name_key_and_range(table, fragments):
    """One line naming the table, the key and what is allowed (issue 25: pydantic configs)."""
    with pytest.raises(ConfigError) as exc:
        stage.QualityConfig.from_dict(table)
    msg = str(exc.value)
    assert "\n" not in msg
    for f in fragments:
        assert f in msg, (f, msg)


def test_a_shared_option_read_by_some_row_is_accepted():
    """[quality.adapt] options go to every row: one row reading it is enough (issue 26)."""
    cfg = stage.QualityConfig.from_dict({
        "rows": {"random": {"strategy": "random"}, "infogain": {"strategy": "infogain"}},
        "baseline": "random", "adapt": {"candidates": 9}})
    assert cfg.adapt["candidates"] == 9


def test_quality_config_normalises_round_trips_and_copies():
    import copy
    import pickle

    cfg = stage.QualityConfig.from_dict({"budgets": [400, 100], "arm": "ideal",
                                         "reach_noise": 1, "adapt": {"robust": False}})
    assert cfg.budgets == (100, 400) and cfg.arm["preset"] == "ideal"
    assert cfg.reach_noise == 1.0 and isinstance(cfg.reach_noise, float)
    assert [c.name for c in cfg.categories] == ["small", "medium", "large"]
    back = stage.QualityConfig.from_dict(cfg.to_dict())
    assert back == cfg and back.to_dict() == cfg.to_dict()
    assert pickle.loads(pickle.dumps(cfg)) == cfg and copy.deepcopy(cfg) == cfg
    with pytest.raises(TypeError):
        cfg.rows["extra"] = {"strategy": "random"}  # read-only
    assert cfg.with_overrides(experiments=3).experiments == 3
    assert cfg.with_overrides(budgets=(50, 20)).budgets == (20, 50)
    assert cfg.with_overrides() is cfg


def test_seeds_are_paired_across_rows_and_models():
    cfg = stage.QualityConfig.from_dict({"budgets": [100, 200], "experiments": 2})
    tasks = stage.plan(cfg)
    by = {}
    for t in tasks:
        by.setdefault((t.category, t.param_index, t.rep), set()).add(t.spawn_key)
    assert all(len(v) == 1 for v in by.values())  # one seed per displacement and repetition
    assert len(by) == 12 * 2
    exact = [t for t in tasks if t.model == stage.EXACT]
    assert len(exact) == 12 * 2 and {t.method for t in exact} == {stage.IDEAL_ROW}
    off = stage.plan(stage.QualityConfig.from_dict({"budgets": [100, 200], "experiments": 2,
                                                    "ideal": False}))
    assert len(off) == len(tasks) - len(exact) and stage.EXACT not in {t.model for t in off}


def test_touches_to_threshold_and_paired_test_known_answers():
    e = np.array([[5.0, 3.0, 0.9], [5.0, 5.0, 5.0]])
    np.testing.assert_array_equal(stage.touches_to(e, 1.0), [3, 4])
    assert stage.threshold(0.1) == 1.0 and stage.threshold(3.0) == 6.0
    assert stage.paired_test(np.array([5, 5, 5]), np.array([5, 5, 5])) == (0.0, 1.0)
    adv, p = stage.paired_test(np.full(20, 9), np.arange(20) % 3 + 1)
    assert adv == 7 and p < 1e-3


def _synthetic(berr, adv, p):
    models = {f"m{i}": {"exploration": "active", "budget": 100 * (i + 1), "accuracy": 0.9,
                        "boundary_error": b, "threshold": stage.threshold(b)}
              for i, b in enumerate(berr)}
    summary = {f"m{i}": {"all": {"random": {}, "active": {"advantage": a, "pvalue": q}}}
               for i, (a, q) in enumerate(zip(adv, p, strict=True))}
    return Artifact(kind="model_quality", config={}, attrs={"models": models, "summary": summary,
                                                            "baseline": "random"})


def test_the_verdict_follows_the_data():
    berr = [0.2, 0.5, 1.0, 2.0, 4.0, 8.0]
    holds = stage.hypothesis(_synthetic(berr, [9, 8, 6, 4, 1, 0], [1e-6] * 4 + [0.5] * 2), "active")
    assert holds["rho"] < -0.9 and stage.verdict(holds).startswith("holds")
    assert holds["significant_good"] == 3 and holds["significant_bad"] == 1
    flat = stage.hypothesis(_synthetic(berr, [3, 1, 4, 1, 5, 2], [0.5] * 6), "active")
    assert stage.verdict(flat).startswith("not supported")
    grows = stage.hypothesis(_synthetic(berr, [0, 1, 2, 4, 6, 9], [0.5] * 6), "active")
    assert stage.verdict(grows).startswith("contradicted")


def test_a_tiny_sweep_runs_and_reports(runner, tiny_sweep, tmp_path):
    base, out, r = tiny_sweep
    assert r.exit_code == 0, r.output
    assert "advantage over random" in r.output
    art = read_artifact(out, "model_quality")
    # 2 models x 1 displacement x 2 rows x 2 repetitions, then the exact model's 2 runs
    assert art.data["experiments"]["errors"].shape == (2 * 1 * 2 * 2 + 2, 6)
    assert set(art.attrs["models"]) == {"random-40", "random-120"}
    info = sorted(art.attrs["models"].values(), key=lambda m: m["threshold"])
    ideal = [m["ideal_touches"]["small"] for m in info]  # a wider tau is never reached later
    assert all(1 <= v <= 7 for v in ideal) and ideal == sorted(ideal, reverse=True)
    assert art.attrs["rows_resolved"][stage.IDEAL_ROW]["robot"]["strategy"]["name"] == "infogain"
    assert art.attrs["rows_resolved"]["infogain"]["robot"]["posterior"]["robust"] is True
    assert not out.with_name("q.h5.ckpt").exists()
    # same inputs and seed: the same numbers
    r = runner.invoke(app, [*base, "-o", str(tmp_path / "again.h5")])
    assert r.exit_code == 0, r.output
    np.testing.assert_array_equal(read_artifact(tmp_path / "again.h5").data["experiments"]["errors"],
                                  art.data["experiments"]["errors"])
    rep = tmp_path / "rep"
    r = runner.invoke(app, ["report", str(out), "-o", str(rep)])
    assert r.exit_code == 0, r.output
    text = (rep / "README.md").read_text()
    assert "The paper's explanation, tested" in text and "random-120" in text
    assert "infogain with the exact model" in text and "exact model's touches" in text
    assert (rep / "advantage.png").stat().st_size > 10_000


def test_an_interrupted_sweep_keeps_its_models_and_resumes_to_the_same_numbers(
        runner, tiny_sweep, tmp_path, monkeypatch):
    """Ctrl-C during the adaptations: exit 130, no output, the learned models kept in the
    checkpoint and named in the message; --resume then gives the uninterrupted run's numbers."""
    from kbcli.cli import quality as cli_quality

    base, whole, r = tiny_sweep  # the uninterrupted run
    assert r.exit_code == 0, r.output
    real = cli_quality.execute

    def interrupting(job, todo, **kw):
        if job.run.endswith("adapt_one"):
            raise KeyboardInterrupt
        yield from real(job, todo, **kw)

    monkeypatch.setattr(cli_quality, "execute", interrupting)
    out = tmp_path / "q.h5"
    r = runner.invoke(app, [*base, "-o", str(out)])
    assert r.exit_code == 130
    assert "0 of 10 adaptations kept" in r.stderr and "--resume" in r.stderr, r.stderr
    assert not out.exists()
    assert len(list((tmp_path / "q.h5.ckpt" / "models").glob("*.h5"))) == 2
    monkeypatch.setattr(cli_quality, "execute", real)
    r = runner.invoke(app, [*base, "-o", str(out), "--resume", "--models", str(tmp_path / "m")])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in (tmp_path / "m").iterdir()) == ["random-120.h5", "random-40.h5"]
    np.testing.assert_array_equal(read_artifact(out).data["experiments"]["errors"],
                                  read_artifact(whole).data["experiments"]["errors"])
    assert not (tmp_path / "q.h5.ckpt").exists()


def test_each_models_likelihood_tables_are_built_once(runner, small_kb, tmp_path, monkeypatch):
    """Three rows (robust, robust without the redundancy discount, plain) over two displacements:
    each model's two tables (the robust rows share one) are built once (a cache that held two
    configs rebuilt them at every displacement)."""
    from kbcli.stages import adapt as adapt_stage

    conf = tmp_path / "q.toml"
    conf.write_text(TINY.replace(
        'infogain = { strategy = "infogain" }',
        'respot = { strategy = "infogain", redundancy_radius = 0.0 }\n'
        'plain = { strategy = "infogain", robust = false }').replace(
        "displacements = [[3.0, -2.0]]", "displacements = [[3.0, -2.0], [-2.0, 3.0]]").replace(
        "experiments = 2", "experiments = 1").replace("max_steps = 6", "max_steps = 2"))
    real, calls = adapt_stage.build_shared_table, []

    def counting(acfg, model):
        calls.append(acfg)
        return real(acfg, model)

    monkeypatch.setattr(adapt_stage, "build_shared_table", counting)
    r = runner.invoke(app, ["quality", "--config", str(conf), "--keyboard", str(small_kb), "-o",
                            str(tmp_path / "q.h5")])
    assert r.exit_code == 0, r.output
    assert len(calls) == 2 * 2 + 1  # two models' two tables, and the exact model's one


def test_a_top_level_arm_table_is_refused_not_ignored(runner, small_kb, tmp_path):
    conf = tmp_path / "q.toml"
    conf.write_text(TINY + '\n[arm]\npreset = "servo"\n')
    r = runner.invoke(app, ["quality", "--config", str(conf), "--keyboard", str(small_kb), "-o",
                            str(tmp_path / "q.h5")])
    assert r.exit_code == 1 and "remove it" in r.stderr and r.stderr.count("\n") == 1, r.output
    assert not (tmp_path / "q.h5").exists() and not (tmp_path / "q.h5.ckpt").exists()


def test_an_unreachable_scheduler_leaves_nothing(runner, small_kb, tmp_path, monkeypatch):
    import kbcli.io.runner

    monkeypatch.setattr(kbcli.io.runner, "CONNECT_TIMEOUT_S", 1.0)
    conf = tmp_path / "q.toml"
    conf.write_text(TINY)
    before = sorted(p.name for p in tmp_path.iterdir())
    r = runner.invoke(app, ["quality", "--config", str(conf), "--keyboard", str(small_kb), "-o",
                            str(tmp_path / "q.h5"), "--scheduler", "tcp://127.0.0.1:9"])
    assert r.exit_code == 1 and "cannot reach the Dask scheduler" in r.stderr, r.output
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no q.h5, no q.h5.ckpt


def test_the_default_keyboard_is_found_from_any_folder(runner, tmp_path, monkeypatch):
    """Without --keyboard, quality learns on the checkout's data/keyboard.h5 even when run from
    another folder (it said 'data/keyboard.h5: no such file')."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "q.toml").write_text(
        '[quality]\nbudgets = [20]\nexplorations = ["random"]\nmode = "ideal"\narm = "ideal"\n'
        'experiments = 1\nmax_steps = 2\nideal = false\n[quality.rows]\nrandom = '
        '{ strategy = "random" }\n[quality.categories.small]\nlimit = 10.0\n'
        'displacements = [[3.0, -2.0]]\n[quality.adapt]\nresolution = 2.0\n')  # as TINY's
    r = runner.invoke(app, ["quality", "--config", "q.toml", "-o", "q.h5"])
    assert r.exit_code == 0, r.output
    kb = read_artifact(tmp_path / "q.h5").inputs["keyboard"]
    assert kb["sha256"] == read_artifact(stage.__file__.rsplit("/kbcli/", 1)[0]
                                         + "/data/keyboard.h5").sha256


def test_a_row_may_be_compared_with_its_own_baseline():
    """The paper's strategies on the paper's posterior: paper-active against paper-random (issue
    39), every other row against `baseline`; a baseline row is not compared itself."""
    rows = {"random": {"strategy": "random"}, "infogain": {"strategy": "infogain"},
            "paper-random": {"strategy": "random", "posterior": "kde"},
            "paper-active": {"strategy": "paper-active", "posterior": "kde"}}
    cfg = stage.QualityConfig.from_dict({"rows": rows, "baselines": {"paper-active":
                                                                      "paper-random"}})
    assert cfg.baseline_of("paper-active") == "paper-random"
    assert cfg.baseline_of("infogain") == "random"
    assert stage.compared_rows(cfg.to_dict()) == ["infogain", "paper-active"]
    assert stage.QualityConfig.from_dict(cfg.to_dict()) == cfg
    assert "baselines" not in stage.QualityConfig.from_dict({"rows": rows}).to_dict()
    for bad, says in (({"paper-active": "nope"}, "must name a row"),
                      ({"ghost": "random"}, "must name a row"),
                      ({"random": "random"}, "its own baseline")):
        with pytest.raises(ConfigError, match=says):
            stage.QualityConfig.from_dict({"rows": rows, "baselines": bad})
