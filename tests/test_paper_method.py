"""The paper's method as the paper writes it (issue 26): the model's confusion factor, ML ties
without positional bias, Algorithm 2's fresh samples, the paper's active strategy and random
baseline, and experiments that depend on their own seed only."""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.kde.samples import FreshSamples
from kbcli.core.adaptation.posteriors.posterior import Posterior, fair_argmax
from kbcli.core.adaptation.strategies import STRATEGIES, Context
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.core.model.sampling import RasterSampler
from kbcli.core.model.table import LikelihoodTable
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.runner import Job, execute
from kbcli.stages import evaluate as stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact

KB = Keyboard(KeyboardConfig())
MODEL = ExactModel(KB)
#: the paper's options (pipelines/paper.toml, method ``paper``) on a small grid
PAPER = dict(posterior="kde", estimator="ml", model_blur=0.0, kde_draw="fresh",
             kde_sampler="raster", kde_floor=0.0, ml_ties="random", random_actions="model",
             prior_halfwidth=15.0, kde_samples=2000, candidates=64)


def two_key_table() -> LikelihoodTable:
    """A 1 x 5 raster: silence | key 1 | a 50/50 boundary | 70/30 | key 2."""
    probs = np.array([[[1, 0, 0], [0, 1, 0], [0, 0.5, 0.5], [0, 0.7, 0.3], [0, 0, 1]]],
                     np.float32)
    return LikelihoodTable(np.zeros(2), 1.0, 3, 1e-3, probs=probs)


def test_confusion_factor_on_a_two_key_model():
    t = two_key_table()
    c = t.confusion_at(np.arange(5.0), np.zeros(5))
    np.testing.assert_allclose(c, [0.0, 0.0, 1.0, 0.6, 0.0], atol=1e-6)
    assert t.confusion_at(np.array([-10.0]), np.array([0.0]))[0] == 0  # outside: sure silence
    hard = LikelihoodTable(np.zeros(2), 1.0, 3, 1e-3, classes=np.array([[0, 1, 2]], np.int16))
    assert (hard.confusion_at(np.arange(3.0), np.zeros(3)) == 0).all()  # an exact map is sure


def test_raster_sampler_draws_p_action_given_sound():
    t = two_key_table()
    x = RasterSampler(t).sample_actions(1, 20000, np.random.default_rng(0))
    cell = np.rint(x[:, 0]).astype(int)
    assert (np.abs(x[:, 1]) <= 0.5).all() and set(cell) == {1, 2, 3}
    share = np.bincount(cell, minlength=5)[1:4] / len(cell)  # weights 1, 0.5, 0.7
    np.testing.assert_allclose(share, np.array([1, 0.5, 0.7]) / 2.2, atol=0.015)
    with pytest.raises(ValueError, match="out of range"):
        RasterSampler(t).sample_actions(3, 1, np.random.default_rng(0))


def test_ml_ties_have_no_positional_bias():
    grid = HypothesisGrid.build("translation", prior_halfwidth=5.0, resolution=1.0,
                                centre=np.zeros(2))
    flat = Posterior.uniform(grid)
    assert flat.ml_index() == 0  # the historical rule: the corner of the prior box
    picks = np.array([Posterior.uniform(grid, tie_seed=s).ml_index() for s in range(4000)])
    counts = np.bincount(picks, minlength=grid.size)
    # uniform over the 121 cells: chi-square with 120 dof stays far below 200
    expected = len(picks) / grid.size
    assert ((counts - expected) ** 2 / expected).sum() < 200
    ml = grid.params(picks)
    assert abs(ml[:, 0].mean()) < 0.3 and abs(ml[:, 1].mean()) < 0.3  # centred, not the corner
    # a strict maximum wins whatever the seed; ties only among the tied cells
    p = np.array([0.1, 0.3, 0.2, 0.3, 0.1])
    assert {fair_argmax(p, s) for s in range(50)} == {1, 3}
    assert fair_argmax(np.array([0.1, 0.5, 0.4]), 3) == 1


def adapter(seed, **kw):
    cfg = AdapterConfig.shared({**PAPER, **kw})  # the method's options its strategy takes
    return Adapter(MODEL, cfg, rng=np.random.default_rng(seed))


def test_algorithm_2_samples_fresh_per_observation_and_per_seed():
    a, b, c = adapter(1), adapter(1), adapter(2)
    assert isinstance(a.samples, FreshSamples)
    point = np.array([400.0, 300.0])
    t1, t2 = a.simulate(point, 5), a.simulate(point, 5)
    assert not np.array_equal(t1, t2)  # a new draw for every observation
    np.testing.assert_array_equal(t1, b.simulate(point, 5))  # same seed, same samples
    assert not np.array_equal(t1, c.simulate(point, 5))  # another experiment, other samples
    shared = adapter(1, kde_draw="shared")
    np.testing.assert_array_equal(shared.simulate(point, 5), shared.simulate(point, 5))


def test_simulate_draw_shared_reuses_one_draw_per_sound_in_the_simulations_only():
    point = np.array([400.0, 300.0])
    a, b = adapter(1, simulate_draw="shared"), adapter(1, simulate_draw="shared")
    t1 = a.simulate(point, 5)
    np.testing.assert_array_equal(t1, a.simulate(point, 5))  # one draw per sound, reused
    np.testing.assert_array_equal(t1, b.simulate(point, 5))  # same seed, same samples
    assert not np.array_equal(t1, adapter(2, simulate_draw="shared").simulate(point, 5))
    assert isinstance(a.samples, FreshSamples) and a.samples.draws == 0  # simulations drew none
    a.observe_class(point, 5)
    assert a.samples.draws == 1  # a real touch still draws fresh (kde_draw)
    # unset, or the same as kde_draw: the simulations draw as the real touches (the paper's text)
    for ad in (adapter(1), adapter(1, simulate_draw="fresh")):
        assert ad.simulation_samples is ad.samples
    paper = [adapter(4, strategy="paper-active", **kw) for kw in ({}, {"simulate_draw": "fresh"})]
    np.testing.assert_array_equal(paper[0].suggest(), paper[1].suggest())
    cfg = AdapterConfig.shared({**PAPER, "strategy": "paper-active", "simulate_draw": "shared"})
    assert "simulate_draw" not in cfg.inactive()  # read: paper-active simulates, the KDE draws
    assert "simulate_draw" not in cfg.replace(posterior="likelihood").flat()  # the KDE's option
    assert "simulate_draw" in cfg.replace(strategy="infogain").inactive()
    with pytest.raises(ConfigError, match="shared, fresh"):
        AdapterConfig(posterior="kde", simulate_draw="sometimes")
    with pytest.raises(ConfigError, match="posterior likelihood takes no option 'simulate_draw'"):
        AdapterConfig(simulate_draw="shared")


def test_no_floor_rules_out_and_floor_keeps():
    a0, a1 = adapter(0), adapter(0, kde_floor=1e-3)
    t0, t1 = a0.simulate(np.array([400.0, 300.0]), 5), a1.simulate(np.array([400.0, 300.0]), 5)
    assert t0.min() < -600 and t1.min() > -20  # ruled out (log 1e-300) vs the floor
    with pytest.raises(ConfigError):
        AdapterConfig(posterior="kde", kde_floor=1.0)
    with pytest.raises(ConfigError, match="fresh"):
        AdapterConfig(posterior="kde", kde_draw="new")


@pytest.mark.parametrize("strategy", ["paper-active", "random"])
def test_paper_strategies_touch_inside_and_repeat(strategy):
    runs = []
    for _ in range(2):
        ad = adapter(3, strategy=strategy)
        acts = []
        for _ in range(3):
            a = ad.suggest()
            acts.append(a)
            ad.observe_class(a, int(MODEL.predict_class((a - [4.0, -3.0])[None])[0]))
        runs.append(np.array(acts))
    np.testing.assert_array_equal(runs[0], runs[1])
    x0, y0, x1, y1 = KB.area
    assert ((runs[0] >= [x0, y0]) & (runs[0] <= [x1, y1])).all()
    if strategy == "random":  # sampled from the model: every touch lands on a key
        assert (MODEL.predict_class(runs[0]) > 0).all()


def test_paper_active_keeps_the_most_confusing_candidates():
    """With a model unsure only on one boundary, every kept candidate lies on it."""
    t = two_key_table()
    grid = HypothesisGrid.build("translation", prior_halfwidth=1.0, resolution=1.0,
                                centre=np.zeros(2))
    cfg = AdapterConfig(strategy="paper-active", candidates=64, active_keep=4)
    seen = []

    def simulate(a, c):
        seen.append(np.asarray(a).copy())
        return np.zeros(grid.shape)

    ctx = Context(Posterior.uniform(grid), t, (-0.5, -0.5, 4.5, 0.5), np.empty((0, 2)),
                  np.empty((0, 2)), cfg, sampler=RasterSampler(t), simulate=simulate)
    a = STRATEGIES.get("paper-active")(ctx, np.random.default_rng(0))
    assert len(seen) == 4 and all(round(s[0]) == 2 for s in seen)  # the 50/50 cell
    assert round(a[0]) == 2


@pytest.fixture
def model_path(tmp_path):
    kb = keyboard_stage.run(KeyboardConfig())
    path = tmp_path / "model.h5"
    write_artifact(exact_artifact(kb), path)
    return path


def test_common_experiments_identical_whatever_methods_are_selected(model_path):
    base = {"strategies": ["random"], "posterior": "likelihood"}
    paper = {"strategies": ["random", "paper-active"], "posterior": "kde", "estimator": "ml",
             "model_blur": 0.0, "kde_draw": "fresh", "kde_sampler": "raster", "kde_floor": 0.0,
             "ml_ties": "random", "random_actions": "model", "kde_samples": 500,
             "candidates": 32, "stop_ml": 0.2, "stop_mass": 0.0}
    common = dict(seed=5, experiments=1, modes=["ideal"], max_steps=3, play_notes=10,
                  thresholds=[10.0], snapshot_steps=[1], example="small",
                  categories={"small": {"limit": 10.0, "displacements": [[3.0, -4.0]]}})
    both = stage.EvaluateConfig.from_dict({**common, "judged": "paper",
                                           "methods": {"paper": paper, "kbcli": base}})
    alone = stage.EvaluateConfig.from_dict({**common, "judged": "kbcli",
                                            "methods": {"kbcli": base}})
    art = read_artifact(model_path)
    res = {}
    for name, cfg in (("both", both), ("alone", alone)):
        tasks = stage.plan(cfg)
        ctx = stage.context(cfg, art)
        job = Job(setup="kbcli.stages.evaluate:setup", run="kbcli.stages.evaluate:run_experiment",
                  context=ctx, context_key=stage.context_key(ctx), tasks=tuple(tasks))
        out = dict(execute(job, range(len(tasks))))
        res[name] = {(t.method, t.strategy, t.rep): out[t.row] for t in tasks}
        # the reference replays: measured once, by whichever task is planned first
        ref = [out[t.row] for t in tasks if t.play_reference]
        res[name]["reference"] = ref[0]
    key = ("kbcli", "random", 0)
    a, b = res["both"][key], res["alone"][key]
    for k in ("errors", "estimates", "actions", "classes", "entropy", "play_adapted",
              "stop_step"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    ra, rb = res["both"]["reference"], res["alone"]["reference"]
    assert ra is not a and rb is b  # run by another method in one selection, by kbcli alone
    for k in ("play_before", "play_unadapted"):
        assert np.isfinite(ra[k]) and ra[k] == rb[k], k
    p = res["both"][("paper", "paper-active", 0)]
    assert p["stop_step"] >= 0 and np.isfinite(p["errors"]).all()


def test_reference_seed_has_no_method_or_strategy():
    cfg = stage.EvaluateConfig.from_dict({
        "seed": 5, "experiments": 2, "modes": ["ideal"], "max_steps": 3, "thresholds": [10.0],
        "judged": "a", "methods": {"a": {"strategies": ["random"]},
                                   "b": {"strategies": ["random", "active"]}},
        "categories": {"small": {"limit": 10.0, "displacements": [[3.0, -4.0]]}}})
    tasks = stage.plan(cfg)
    for rep in range(2):
        seeds = {tuple(t.reference_seed.generate_state(4)) for t in tasks if t.rep == rep}
        assert len(seeds) == 1
    assert tasks[0].seed.generate_state(4).tolist() != \
        tasks[0].reference_seed.generate_state(4).tolist()
