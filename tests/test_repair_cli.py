"""``kbcli adapt/run --repair --model-out`` (issue 42): the repaired model artifact, its lineage,
and the inputs it must never overwrite."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import one_line_error
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.cli import app
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.io.artifact import read_artifact, sha256_file, write_artifact
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage
from kbcli.stages.models import load_model
from kbcli.stages.perturb import PerturbConfig
from kbcli.stages.perturb import run as perturb_run


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A weak learned model (120 random reaches, k-nearest neighbours: cheap to refit) and a scene
    moved by (6, -4)."""
    d = tmp_path_factory.mktemp("repair")
    kb_art = keyboard_stage.run(KeyboardConfig())
    cfg = learn_stage.LearnConfig(strategy="random", budget=120, model_class="knn")
    write_artifact(learn_stage.run(cfg, kb_art, rng=np.random.default_rng(1), seed=1),
                   d / "model.h5")
    write_artifact(perturb_run(PerturbConfig(params=(6.0, -4.0)), kb_art,
                               rng=np.random.default_rng(0)), d / "scene.h5")
    write_artifact(perturb_run(PerturbConfig(params=(22.0, 17.0)), kb_art,
                               rng=np.random.default_rng(0)), d / "far.h5")
    return d


def _adapt(runner, d, *extra, model="model.h5", out="run.h5"):
    """adapt on a 1 px grid (the default 0.5 px took 4 times as long to set up, for nothing the
    tests below check)."""
    return runner.invoke(app, ["adapt", "--model", str(d / model), "--scene", str(d / "scene.h5"),
                               "-o", str(d / out), "--max-steps", "8", "--prior-halfwidth", "15",
                               "--resolution", "1", "--snapshots", "0", *extra])


def test_model_out_writes_a_repaired_model_with_its_lineage(runner, files):
    d = files
    before = sha256_file(d / "model.h5")
    r = _adapt(runner, d, "--repair", "--model-out", str(d / "gen1.h5"))
    assert r.exit_code == 0, r.output
    assert "generation 1" in r.output and "touches absorbed" in r.output
    assert sha256_file(d / "model.h5") == before  # the input is left as it was
    art = read_artifact(d / "gen1.h5", "model")  # validated against the model schema
    (gen,) = art.attrs["lineage"]
    assert gen["parent_sha256"] == before and gen["source"] == "adapt"
    assert art.inputs["parent"]["sha256"] == before
    assert art.attrs["absorbed_touches"] == gen["absorbed"] <= 8
    parent = read_artifact(d / "model.h5", "model")
    n0 = len(parent.data["samples"]["landed"])
    assert len(art.data["samples"]["landed"]) == n0 + gen["absorbed"]
    assert len(load_model(art).actions_) == len(load_model(parent).actions_) + gen["absorbed"]
    # the repaired model loads where a model does, and carries on: generation 2
    r = _adapt(runner, d, "--repair", "--model-out", str(d / "gen2.h5"), model="gen1.h5",
               out="run2.h5")
    assert r.exit_code == 0, r.output
    art2 = read_artifact(d / "gen2.h5", "model")
    assert [g["parent_sha256"] for g in art2.attrs["lineage"]] == [before,
                                                                    sha256_file(d / "gen1.h5")]
    r = runner.invoke(app, ["inspect", str(d / "gen2.h5")])
    assert r.exit_code == 0 and "lineage" in r.output and "gen1.h5" in r.output


def test_an_old_model_has_no_lineage_and_adapts_as_before(runner, files):
    r = runner.invoke(app, ["inspect", str(files / "model.h5")])
    assert r.exit_code == 0 and "lineage (" not in r.output
    r = _adapt(runner, files, out="plain.h5")
    assert r.exit_code == 0, r.output
    assert "repair" not in read_artifact(files / "plain.h5", "run").config["adapt"]["robot"]


def test_a_generation_that_absorbs_nothing_keeps_its_parents_model(files):
    """An adaptation whose credible disc is wider than the absorb radius gives nothing: the new
    generation records it, and its model is the parent's, byte for byte, so it adapts exactly as
    its parent (a refit or a new calibration would change it)."""
    from kbcli.stages import repair as repair_stage

    parent = read_artifact(files / "model.h5", "model")
    model = load_model(parent)
    pts = np.array([[300.0, 300.0], [420.0, 380.0]])
    wide = repair_stage.Adaptation(pts, pts, np.full((2, 1), np.nan), np.array([0, 1]),
                                   np.zeros(2), repair_stage.ABSORB_RADIUS + 1.0)
    art, summary = repair_stage.repaired_model(parent, model, [wide], source="adapt")
    assert (summary["absorbed"], summary["skipped"], summary["generation"]) == (0, 1, 1)
    assert art.attrs["lineage"][-1]["absorbed"] == 0
    for key, arr in parent.data["model"].items():
        np.testing.assert_array_equal(art.data["model"][key], arr)
    grid = np.random.default_rng(0).uniform((200, 250), (600, 450), (500, 2))
    np.testing.assert_array_equal(load_model(art).predict_proba(grid), model.predict_proba(grid))
    assert art.attrs["boundary_error_px"] == pytest.approx(parent.attrs["boundary_error_px"])
    assert art.attrs["reliability"] == parent.attrs["reliability"]  # not assessed anew


def test_model_out_never_overwrites_its_input(runner, files):
    before = sha256_file(files / "model.h5")
    r = _adapt(runner, files, "--repair", "--model-out", str(files / "model.h5"), out="x.h5")
    one_line_error(r, "refusing to overwrite an input")
    assert sha256_file(files / "model.h5") == before and not (files / "x.h5").exists()


def test_model_out_needs_repair(runner, files):
    r = _adapt(runner, files, "--model-out", str(files / "m.h5"), out="y.h5")
    one_line_error(r, "--model-out", "--repair")
    assert not (files / "m.h5").exists() and not (files / "y.h5").exists()


def test_repair_is_refused_for_the_rigid_family(runner, files):
    r = _adapt(runner, files, "--repair", "--family", "rigid", out="z.h5")
    one_line_error(r, "repair", "translation")


def test_run_repair_writes_the_repaired_model(runner, files):
    r = runner.invoke(app, ["run", "--model", str(files / "model.h5"), "--scene",
                            str(files / "far.h5"), "-o", str(files / "loop.h5"), "--steps", "150",
                            "--perturb-at", "70", "--n-lt", "50", "--n-st", "10", "--max-adapt-steps", "8", "--repair",
                            "--model-out", str(files / "loop-model.h5")])
    assert r.exit_code == 0, r.output
    art = read_artifact(files / "loop-model.h5", "model")
    assert art.attrs["lineage"][-1]["source"] == "run"
    assert art.attrs["lineage"][-1]["adaptations"] >= 1


# -- kbcli bench repair ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tiny_weak():
    """One weak model as the protocol learns it, smaller and cheaper to rasterise: 40 random
    reaches, ideal arm, k-nearest neighbours (the benchmark's logic does not look at the class)."""
    from kbcli.bench import repair as bench

    kb_art = keyboard_stage.run(KeyboardConfig())
    cfg = learn_stage.LearnConfig(strategy="random", budget=40, model_class="knn")
    art = learn_stage.run(cfg, kb_art, rng=np.random.default_rng(1), seed=1)
    return [bench.WeakModel("ideal-1", art, load_model(art), "ideal", "ideal")]


def test_bench_repair_replicates_are_the_single_seed_runs_of_successive_seeds(tiny_weak):
    """Run r * moves + k of --replicates R is move k adapted at seed --seed + r: the first
    replicate is the single-seed benchmark, the second the single-seed benchmark at seed + 1."""
    from kbcli.bench import repair as bench

    plain = (bench.METHODS[0],)
    kw = {"n_moves": 2, "touches": 3, "methods": plain}
    both = bench.side_by_side(tiny_weak, seed=4, replicates=2, **kw)
    first = bench.side_by_side(tiny_weak, seed=4, **kw)
    second = bench.side_by_side(tiny_weak, seed=5, **kw)
    assert [r.move for r in both] == [0, 1, 2, 3]
    for got, want in zip(both, [*first, *second], strict=True):
        np.testing.assert_array_equal(got.errors, want.errors)
    assert bench.summarize(both, 3)[0]["runs"] == 4


def test_bench_repair_cli_pools_replicates_and_skips_the_lifelong_section(runner, tiny_weak,
                                                                           tmp_path, monkeypatch):
    from kbcli.bench import repair as bench

    monkeypatch.setattr(bench, "weak_models", lambda **_: tiny_weak)
    r = runner.invoke(app, ["bench", "repair", "--moves", "2", "-T", "3", "--replicates", "2",
                            "--episodes", "0", "--plot", str(tmp_path / "l.png")],
                      env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    assert "2 moves x 2 adaptation seeds" in r.output and "lifelong" not in r.output
    assert "samples floor" in r.output and "systematic part / spread" in r.output
    assert not (tmp_path / "l.png").exists()


@pytest.mark.parametrize("flag, value", [("--replicates", "0"), ("--replicates", "11"),
                                         ("--episodes", "-1"), ("--episodes", "21")])
def test_bench_repair_refuses_counts_out_of_range(runner, flag, value):
    r = runner.invoke(app, ["bench", "repair", flag, value])
    assert r.exit_code != 0
    one_line_error(r, flag)


def test_systematic_split_known_answer():
    """A model whose runs all end at the same offset is all systematic; one whose offsets
    cancel is all spread; the share weighs each model's mean by its runs."""
    from kbcli.bench.repair import systematic

    off = np.array([[3.0, 4.0], [3.0, 4.0], [1.0, 0.0], [-1.0, 0.0]])
    share, per = systematic(off, ["a", "a", "b", "b"])
    assert per["a"] == pytest.approx((5.0, 0.0))
    assert per["b"] == pytest.approx((0.0, 1.0))
    assert share == pytest.approx(50.0 / 52.0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.integers(0, 2)),
                min_size=1, max_size=30),
       st.tuples(st.floats(-5, 5), st.floats(-5, 5)))
def test_systematic_part_and_spread_add_up_and_the_spread_ignores_a_common_offset(data, shift):
    """Per model, systematic^2 + spread^2 is its mean squared offset; the share lies in
    [0, 1]; moving every run of a model by the same vector leaves its spread as it was."""
    from kbcli.bench.repair import systematic

    off = np.array([d[:2] for d in data], float)
    keys = [d[2] for d in data]
    share, per = systematic(off, keys)
    assert -1e-9 <= share <= 1 + 1e-9
    for k, (bias, spread) in per.items():
        e = off[np.asarray(keys) == k]
        assert bias**2 + spread**2 == pytest.approx((e**2).sum(axis=1).mean(), rel=1e-9, abs=1e-9)
    moved = off + np.where(np.asarray(keys)[:, None] == keys[0], np.array(shift), 0.0)
    _, per2 = systematic(moved, keys)
    assert per2[keys[0]][1] == pytest.approx(per[keys[0]][1], rel=1e-9, abs=1e-9)


def test_lifelong_summary_reads_the_targets():
    """Falls are counted move by move against the error before it (the learned model's first);
    the first and last moves' touches are the repaired belief's."""
    from kbcli.bench.repair import Episode, lifelong_summary

    def ep(i, berr, stay, final=0.5, learned=0.5):
        return Episode(i, np.zeros(2), stay, final, 31, 1.0, berr, 30, i, 31, learned)

    s = lifelong_summary(3.2, [ep(1, 3.0, 31, 2.0, 2.0), ep(2, 2.5, 20, 0.4, 0.9),
                               ep(3, 2.6, 12, 1.1, 0.3)])
    assert s["errors"] == [3.2, 3.0, 2.5, 2.6]
    assert s["falls"] == 2 and not s["falls_every"]
    assert (s["first_stay"], s["last_stay"]) == (31, 12)
    assert (s["carried_closer"], s["carried_further"], s["later"]) == (1, 1, 2)
    assert lifelong_summary(3.2, [ep(1, 3.1, 5), ep(2, 3.0, 5)])["falls_every"]
    assert not lifelong_summary(3.0, [ep(1, 3.0, 5)])["falls_every"]  # level is not a fall


def test_bench_repair_cli_carries_every_model_and_summarises_it(runner, tiny_weak, tmp_path,
                                                                 monkeypatch):
    from kbcli.bench import repair as bench

    monkeypatch.setattr(bench, "weak_models", lambda **_: tiny_weak)
    plot = tmp_path / "l.png"
    r = runner.invoke(app, ["bench", "repair", "--moves", "1", "-T", "3", "--replicates", "1",
                            "--episodes", "2", "--plot", str(plot)], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    assert "lifelong, every carried model: 2 moves" in r.output
    assert "fell after every move on" in r.output and "of 1 models" in r.output
    assert "model as learned" in r.output
    assert plot.exists() and plot.stat().st_size > 0


def test_bench_repair_cli_refuses_a_lifelong_model_count_out_of_range(runner):
    r = runner.invoke(app, ["bench", "repair", "--lifelong-models", "0"])
    one_line_error(r, "--lifelong-models", "[1, 6]")
