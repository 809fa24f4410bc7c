"""Model classes as a registry (issue 11): every class behind one interface, svc on any layout,
storage without pickle, learning and adapting on every layout."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from scipy.spatial import cKDTree
from sklearn.exceptions import NotFittedError

from kbcli.cli import app
from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.loop import adapt
from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.layouts import example_config_fields
from kbcli.core.model import accuracy as scoring
from kbcli.core.model.classes import (
    MODEL_CLASSES,
    fit_model,
    learned_classes,
    make_model,
    model_from_arrays,
)
from kbcli.core.model.explore import Exploration, ExploreConfig
from kbcli.core.model.svc import SVCModel
from kbcli.core.options import for_part
from kbcli.errors import ArtifactError, ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.sim import SimConfig, World, make_reacher
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage
from kbcli.stages.artifact import Artifact
from kbcli.stages.models import load_model

PADS = Keyboard(KeyboardConfig(layout="pads", rows=2, cols=3))


def _explore(kb: Keyboard, model_class: str, budget: int, strategy: str = "active",
             seed: int = 0) -> Exploration:
    ex = Exploration(ExploreConfig(strategy=strategy, budget=budget, model_class=model_class),
                     World(kb, make_reacher(SimConfig())).touch, kb.area,
                     kb.config.match_threshold, np.random.default_rng(seed))
    for _ in ex:
        pass
    return ex


@pytest.fixture(scope="module")
def pads_svc():
    """An svc model of 2 x 3 round pads learned with 300 active reaches."""
    return _explore(PADS, "svc", 300)


# -- the registry -----------------------------------------------------------------------------------
def test_registry_lists_the_classes_and_refuses_unknown_names():
    assert list(MODEL_CLASSES) == ["lines", "svc", "forest", "forest-xy", "knn", "exact"]
    assert learned_classes() == ("lines", "svc", "forest", "forest-xy", "knn")
    with pytest.raises(ConfigError, match="unknown model class 'gp'; valid: lines, svc, forest, forest-xy, knn, exact"):
        MODEL_CLASSES.get("gp")
    with pytest.raises(ConfigError, match="takes no parameter 'gamma'"):
        make_model("svc", match_threshold=1.5, area=PADS.area, gamma=3.0)
    with pytest.raises(ConfigError, match="unknown model class .tree."):
        ExploreConfig(model_class="tree")
    with pytest.raises(ConfigError, match="unknown model class"):
        learn_stage.LearnConfig(model_class="tree")


@pytest.mark.parametrize("name", learned_classes())
def test_every_class_follows_the_one_interface(name):
    """fit(actions, perceived) -> self; predicting before fitting raises; the same methods answer
    the same kinds of questions; to_arrays / from_arrays round-trip exactly."""
    ex = _explore(PADS, "lines", 120, seed=2)  # any samples will do
    model = make_model(name, match_threshold=1.5, area=PADS.area)
    with pytest.raises(NotFittedError):
        model.predict_proba(np.zeros((1, 2)))
    assert model.fit(ex.landed, ex.perceived) is model
    q = np.random.default_rng(1).uniform(PADS.area[:2], PADS.area[2:], size=(500, 2))
    p = model.predict_proba(q)
    assert p.shape == (500, model.n_classes) and np.allclose(p.sum(axis=1), 1.0)
    sure = p.max(axis=1) > 0.5 + 1e-6
    np.testing.assert_array_equal(model.predict_class(q)[sure], np.argmax(p[sure], axis=1))
    assert model.classify(model.class_features_[1:2] + 0.1).tolist() == [1]
    a = model.sample_actions(1, 20, np.random.default_rng(0))
    assert a.shape == (20, 2)
    r = model.raster(10.0)
    assert r.probs.shape[-1] == model.n_classes
    sites = model.boundary_sites(step=1.0, phase=0.3)
    assert sites["points"].shape[1] == 2 and len(sites["width"]) == len(sites["points"])
    assert (sites["width"] >= 0).all()
    back = model_from_arrays(model.to_arrays(), name)
    np.testing.assert_array_equal(back.predict_proba(q), p)
    fitted = fit_model(name, ex.landed, ex.perceived, match_threshold=1.5, area=PADS.area)
    np.testing.assert_array_equal(fitted.predict_proba(q), p)


# -- the svc class ----------------------------------------------------------------------------------
def test_svc_learns_round_pads(pads_svc):
    model = pads_svc.model
    assert isinstance(model, SVCModel) and model.n_classes == PADS.n_keys + 1
    keys = scoring.class_keys(model.class_features_, PADS)
    assert sorted(keys[1:]) == list(range(PADS.n_keys))
    pred, true = scoring.key_maps(model, PADS, 1.0)
    assert scoring.accuracy_from_maps(pred, true) > 0.97
    assert scoring.boundary_error(pred, true) < 2.0
    # the active rule spent its reaches near the pads' circles, not in silence
    d = PADS.shapes._tree.query(pads_svc.landed)[0] - PADS.config.layout.pad_radius
    assert np.mean(np.abs(d) < 3) > 0.4


def test_svc_probabilities_come_from_the_margin(pads_svc):
    """Across a pad's edge p goes through 1/2; deep inside a pad or far in silence it is sure."""
    model = pads_svc.model
    cx, cy = PADS.key_centres()[0]
    r = PADS.config.layout.pad_radius
    # on the edge: the point of the pad's circle furthest from every sample (a sample landed
    # right on the edge tells its sound there)
    th = np.linspace(0.0, 2 * np.pi, 360, endpoint=False)
    circle = np.column_stack([cx + r * np.cos(th), cy + r * np.sin(th)])
    edge = circle[np.argmax(cKDTree(model.actions_).query(circle)[0])]
    pts = np.array([[cx, cy], edge, [cx + 25.0, cy + 25.0]])  # the last between 4 pads
    p = model.predict_proba(pts)
    cls = scoring.class_keys(model.class_features_, PADS)
    k = int(np.flatnonzero(cls == 0)[0])
    assert p[0, k] > 0.99 and p[2, 0] > 0.99
    assert (model.confusion(pts)[[0, 2]] < 0.05).all()
    # across the edge (the pad's circle machine is sharp: a band of about a pixel), p falls from
    # sure to sure through uncertain values, within 2 px of the true edge
    u = (edge - (cx, cy)) / r
    ray = np.array([cx, cy]) + np.arange(r - 2.0, r + 2.0, 0.05)[:, None] * u
    pk = model.predict_proba(ray)[:, k]
    assert pk[0] > 0.99 and pk[-1] < 0.01 and ((pk > 0.05) & (pk < 0.95)).any()
    assert model.confusion(ray).max() > 0.1


def test_svc_storage_has_no_pickle_and_refits_exactly(pads_svc, tmp_path):
    model = pads_svc.model
    d = model.to_arrays()
    for v in d.values():
        assert np.asarray(v).dtype != object
    write_artifact(Artifact(kind="model", config={}, data={"model": d}), tmp_path / "m.h5")
    kinds = []
    with h5py.File(tmp_path / "m.h5") as f:
        f.visititems(lambda _, node: kinds.append(node.dtype.kind)
                     if isinstance(node, h5py.Dataset) else None)
    assert kinds and set(kinds) <= {"f", "i"}  # numbers only: no opaque (pickled) bytes
    back = SVCModel.from_arrays(read_artifact(tmp_path / "m.h5", validate=False).data["model"])
    q = np.random.default_rng(5).uniform(PADS.area[:2], PADS.area[2:], size=(2000, 2))
    np.testing.assert_array_equal(back.predict_proba(q), model.predict_proba(q))
    np.testing.assert_array_equal(back.raster(4.0).probs, model.raster(4.0).probs)
    with pytest.raises(ArtifactError, match="not a stored svc model"):
        SVCModel.from_arrays({"actions": np.zeros((2, 2))})
    with pytest.raises(ConfigError, match="length_scale"):
        SVCModel(length_scale=0.0).fit(np.zeros((2, 2)), np.full((2, 2), np.nan))
    with pytest.raises(ConfigError, match="linear_pairs must be True or False"):
        make_model("svc", match_threshold=1.5, area=PADS.area, linear_pairs="no").fit(
            np.zeros((2, 2)), np.full((2, 2), np.nan))


def _two_sounds(inside) -> tuple[np.ndarray, np.ndarray]:
    """Samples on a 10 px lattice, heard as sound A where ``inside(points)`` else as sound B."""
    g = np.stack(np.meshgrid(np.arange(305.0, 500.0, 10.0), np.arange(255.0, 450.0, 10.0)), -1)
    x = g.reshape(-1, 2)
    heard = np.where(inside(x)[:, None], [[1.0, 1.0]], [[5.0, 5.0]])
    return x, heard


def test_svc_pairs_that_a_line_separates_get_a_straight_boundary():
    """Two sounds either side of x = 400: the pair's machine is linear (hard margin), so its
    boundary is the straight line midway between the nearest samples, +-1 on them."""
    x, heard = _two_sounds(lambda p: p[:, 0] < 400.0)
    model = SVCModel(area=PADS.area).fit(x, heard)
    ((code, svm),) = model._pairs.items()
    assert svm.kernel == "linear"
    y = np.linspace(270.0, 430.0, 9)
    side = 1.0 if model.predict_class(np.array([[450.0, 350.0]]))[0] > 1 else -1.0
    for bx, f in ((400.0, 0.0), (395.0, -side), (405.0, side)):
        np.testing.assert_allclose(model._decision(code, np.column_stack([np.full(9, bx), y])),
                                   f, atol=1e-3)
    # a shape no line nor circle separates (two discs of one sound): the RBF machine bends
    two = SVCModel(area=PADS.area).fit(*_two_sounds(
        lambda p: (np.hypot(p[:, 0] - 360.0, p[:, 1] - 350.0) < 30.0)
        | (np.hypot(p[:, 0] - 440.0, p[:, 1] - 350.0) < 30.0)))
    (svm,) = two._pairs.values()
    assert svm.kernel == "rbf"
    inner, outer = two.predict_class(np.array([[360.0, 350.0], [400.0, 420.0]]))
    assert inner != outer
    # the RBF-only machine of models stored before linear pairs: what such a stored model loads as
    rbf = SVCModel(area=PADS.area, linear_pairs=False, circle_pairs=False).fit(x, heard)
    assert next(iter(rbf._pairs.values())).kernel == "rbf"
    old = {k: v for k, v in model.to_arrays().items() if k not in ("linear_pairs", "circle_pairs")}
    back = SVCModel.from_arrays(old)
    assert back.linear_pairs is False
    q = np.random.default_rng(3).uniform(PADS.area[:2], PADS.area[2:], size=(500, 2))
    np.testing.assert_array_equal(back.predict_proba(q), rbf.predict_proba(q))
    np.testing.assert_array_equal(SVCModel.from_arrays(model.to_arrays()).predict_proba(q),
                                  model.predict_proba(q))


def test_svc_pairs_that_a_circle_separates_get_a_round_boundary():
    """A disc of radius 40 px of one sound inside the other, sampled on a 10 px lattice: no line
    separates the pair, a circle does; its machine's boundary is a circle between 36 and 44 px
    about the disc's centre (between the samples inside and out), +-1 on the nearest samples.
    Models stored before circle pairs load without them (the RBF machine)."""
    x, heard = _two_sounds(lambda p: np.hypot(p[:, 0] - 400.0, p[:, 1] - 350.0) < 40.0)
    model = SVCModel(area=PADS.area).fit(x, heard)
    ((code, svm),) = model._pairs.items()
    assert not hasattr(svm, "kernel")  # the circle machine
    t = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    ring = np.column_stack([np.cos(t), np.sin(t)])
    centre = np.array([400.0, 350.0])
    inside = model.predict_class(centre + 36.0 * ring)
    outside = model.predict_class(centre + 44.0 * ring)
    assert len(set(inside.tolist())) == 1 and len(set(outside.tolist())) == 1
    assert inside[0] != outside[0]
    f = model._decision(code, x)
    assert np.abs(f).min() == pytest.approx(1.0, abs=1e-3)
    old = {k: v for k, v in model.to_arrays().items() if k != "circle_pairs"}
    back = SVCModel.from_arrays(old)
    assert back.circle_pairs is False and next(iter(back._pairs.values())).kernel == "rbf"
    q = np.random.default_rng(4).uniform(PADS.area[:2], PADS.area[2:], size=(500, 2))
    np.testing.assert_array_equal(SVCModel.from_arrays(model.to_arrays()).predict_proba(q),
                                  model.predict_proba(q))


def test_svc_exploration_beats_random_on_pads():
    active = _explore(PADS, "svc", 240, seed=1)
    random = _explore(PADS, "svc", 240, strategy="random", seed=1)
    # both near the ceiling with circle pairs: active errs half as much
    active_error = 1 - scoring.accuracy(active.model, PADS, 2.0)
    random_error = 1 - scoring.accuracy(random.model, PADS, 2.0)
    assert active_error < 0.5 * random_error


# -- learning and adapting on every layout ----------------------------------------------------------
SMALL = {"hex": {"rows": 2, "cols": 3}, "piano": {"cols": 5}, "pads": {"rows": 2, "cols": 3},
         "polygons": example_config_fields("polygons")}


@pytest.mark.parametrize("layout", list(SMALL))
def test_learn_stage_and_adaptation_on_every_layout(layout):
    """Learn an svc model of a (small) keyboard of each layout with the stage, reload it, and let
    infogain find a rigid move. (Batches of 25 reaches, not the default 10: active exploration
    refits the svc after each batch, and its refits were most of this test's time.)"""
    kb = Keyboard(KeyboardConfig(layout=layout, **SMALL[layout]))
    art = learn_stage.run(learn_stage.LearnConfig(budget=500, batch=25, model_class="svc",
                                                  curve_every=250),
                          keyboard_stage.run(kb.config), rng=np.random.default_rng(0), seed=0)
    assert art.config["model_class"] == "svc" and art.attrs["model_class"] == "svc"
    assert art.attrs["layout"] == layout and art.attrs["reaches_to_97"] in (None, 250, 500)
    assert art.attrs["accuracy"] > 0.9
    model = load_model(art)
    assert isinstance(model, SVCModel)
    truth = np.array([2.0, 9.0, -6.0])
    cfg = AdapterConfig(strategy="infogain", family="rigid", resolution=1.0, prior_halfwidth=15.0,
                        max_angle=4.0, angle_resolution=1.0, candidates=96, hypotheses=128)
    adapter = Adapter(model, cfg, rng=np.random.default_rng(1))
    world = World(kb, make_reacher(SimConfig()), truth, "rigid")
    rng = np.random.default_rng(2)

    def touch(a):
        landed, heard = world.touch(a[None], rng)
        return landed[0], heard[0]

    steps = list(adapt(adapter, touch, 30))
    est = steps[-1].estimate
    assert np.hypot(*(est[1:] - truth[1:])) < 3.0 and abs(est[0] - truth[0]) <= 1.5


def test_learn_cli_model_class_and_bad_names(runner, tmp_path):
    kb = tmp_path / "pads.h5"
    assert runner.invoke(app, ["keyboard", "--layout", "pads", "--rows", "2", "--cols", "3",
                               "-o", str(kb)]).exit_code == 0
    out = tmp_path / "m.h5"
    r = runner.invoke(app, ["learn", "--keyboard", str(kb), "--model-class", "svc", "--budget",
                            "120", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "svc model" in " ".join(r.output.split())
    art = read_artifact(out, "model")
    assert art.schema_version == 3 and art.config["model_class"] == "svc"
    rel = art.attrs["reliability"]  # every class estimates its own quality; svc has no calibration
    assert 0 <= rel["cv_error"] <= 1 and rel["boundary_error"] >= 0 and rel["calibration"] == {}
    assert isinstance(load_model(art), SVCModel)
    r = runner.invoke(app, ["plot", "model", str(out), "-o", str(tmp_path / "m.png")])
    assert r.exit_code == 0, r.output
    bad = tmp_path / "bad.h5"
    r = runner.invoke(app, ["learn", "--keyboard", str(kb), "--model-class", "tree", "-o",
                            str(bad)])
    assert r.exit_code == 1
    assert "unknown model class 'tree'; valid: auto, lines, svc, forest, forest-xy, knn" in r.output
    assert not bad.exists()


@pytest.mark.parametrize("version", [1, 2])
def test_models_of_schema_1_and_2_still_load_as_lines(version):
    art = read_artifact(f"data/schema/v{version}/model.h5", "model")
    assert art.schema_version == version and "model_class" not in art.config
    model = load_model(art)
    assert type(model).__name__ == "LearnedModel" and model.n_classes == 33


def test_bench_learn_per_layout_and_class(runner):
    r = runner.invoke(app, ["bench", "learn", "--seeds", "1", "--budgets", "20,40",
                            "--boundary-budget", "40", "--layout", "pads", "--layout", "hex",
                            "--model-class", "svc", "--strategy", "active", "--strategy",
                            "random", "--eval-step", "4"])
    assert r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    for frag in ("pads", "hex", "svc", "reaches to 97 %", "reaches to 99 %", "fit @40 (s)",
                 "active / random reaches to 97 %", "reaches/s"):
        assert frag in text, frag
    r = runner.invoke(app, ["bench", "learn", "--layout", "staggered"])
    assert r.exit_code == 1 and "unknown layout" in r.output
    r = runner.invoke(app, ["bench", "learn", "--model-class", "gp"])
    assert r.exit_code == 1 and "unknown model class" in r.output


def test_bench_layouts_pipeline_small(runner, tmp_path):
    """The layouts pipeline end to end on a small pads keyboard: report, figure, results, resume."""
    kbs = tmp_path / "kbs"
    kbs.mkdir()
    (kbs / "pads.toml").write_text('[keyboard]\nlayout = "pads"\nrows = 2\ncols = 3\n')
    cfg = tmp_path / "layouts.toml"
    cfg.write_text(f'[layouts]\nlayouts = ["pads"]\nkeyboards = "{kbs}"\n'
                   '[layouts.learn]\nmodel_classes = ["svc"]\nstrategies = ["active", "random"]\n'
                   'seeds = 1\nbudgets = [40, 80]\nboundary_budget = 80\n'
                   '[layouts.adapt]\nbudget = 80\nexperiments = 2\nstrategies = ["infogain"]\n'
                   'rigid_experiments = 2\nrigid_strategies = ["infogain"]\nmax_steps = 3\n')
    out = tmp_path / "out"
    r = runner.invoke(app, ["bench", "layouts", "--config", str(cfg), "-o", str(out)])
    assert r.exit_code == 0, r.output
    rep = out / "report"
    text = (rep / "README.md").read_text()
    for frag in ("## Targets", "## Learning the model", "## Adapting with a learned model",
                 "| pads | svc | active |", "rigid", "infogain", "pads.png"):
        assert frag in text, frag
    assert (rep / "pads.png").read_bytes()[:4] == b"\x89PNG"
    import json

    data = json.loads((rep / "results.json").read_text())
    assert data["layouts"]["pads"]["adapt_model"]["class"] == "svc"
    assert len(list((out / "cache").glob("learn-pads-svc-*.json"))) == 2
    assert len(list((out / "cache").glob("adapt-pads-*.json"))) == 1
    assert read_artifact(out / "models" / "pads.h5", "model").attrs["n_reaches"] == 80
    # a second run reads the learning runs back and gives the same tables
    r = runner.invoke(app, ["bench", "layouts", "--config", str(cfg), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert (rep / "README.md").read_text().split("## Adapting")[0] == text.split("## Adapting")[0]
    bad = tmp_path / "bad.toml"
    bad.write_text('[layouts]\nlayouts = ["pads"]\n[layouts.learn]\nseedz = 3\n')
    r = runner.invoke(app, ["bench", "layouts", "--config", str(bad), "-o", str(tmp_path / "o2")])
    assert r.exit_code == 1 and "unknown [layouts.learn] option(s) seedz" in r.output
    bad.write_text('[layouts]\nlayouts = ["staggered"]\n')
    r = runner.invoke(app, ["bench", "layouts", "--config", str(bad), "-o", str(tmp_path / "o2")])
    assert r.exit_code == 1 and "unknown layout 'staggered'" in r.output
    assert not (tmp_path / "o2").exists()


@pytest.mark.parametrize("family", ["translation", "rigid"])
@pytest.mark.parametrize("strategy", ["random", "active", "infogain"])
def test_every_strategy_adapts_with_an_svc_model(pads_svc, strategy, family):
    """Every adaptation strategy takes an svc model (any class behind the one interface) in both
    families: the posterior concentrates and the estimate moves towards the truth."""
    truth = np.array([6.0, -4.0]) if family == "translation" else np.array([1.0, 6.0, -4.0])
    own = for_part(STRATEGIES, strategy,
                   {"candidates": 64, "hypotheses": 64, "active_hypotheses": 256})
    cfg = AdapterConfig(strategy=strategy, family=family, resolution=1.0, prior_halfwidth=10.0,
                        max_angle=2.0, angle_resolution=1.0, **own)
    adapter = Adapter(pads_svc.model, cfg, rng=np.random.default_rng(3))
    world = World(PADS, make_reacher(SimConfig()), truth, family)
    rng = np.random.default_rng(4)

    def touch(a):
        landed, heard = world.touch(a[None], rng)
        return landed[0], heard[0]

    steps = list(adapt(adapter, touch, 15))
    prior_entropy = np.log(adapter.grid.size)
    assert steps[-1].entropy < prior_entropy - 1.0
    assert np.hypot(*(steps[-1].estimate[-2:] - truth[-2:])) < np.hypot(*truth[-2:])
