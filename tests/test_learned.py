"""The learned model, the exploration strategies and the accuracy scores (issue 3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.exceptions import NotFittedError
from sklearn.svm import SVC

from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model import accuracy as scoring
from kbcli.core.model.base import ExactModel
from kbcli.core.model.explore import (
    STRATEGIES,
    Exploration,
    ExploreConfig,
    farthest_points,
    hex_lattice,
)
from kbcli.core.model.lines import LearnedModel
from kbcli.core.model.separation import convex_hull, separating_line
from kbcli.core.model.sounds import discover_classes
from kbcli.errors import ArtifactError, ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.sim import SimConfig, World, make_reacher
from kbcli.stages.artifact import Artifact

KB = Keyboard(KeyboardConfig())
SMALL = Keyboard(KeyboardConfig(rows=2, cols=3))


def _explore(kb: Keyboard, strategy: str, budget: int, seed: int = 0) -> Exploration:
    ex = Exploration(ExploreConfig(strategy=strategy, budget=budget),
                     World(kb, make_reacher(SimConfig())).touch, kb.area,
                     kb.config.match_threshold, np.random.default_rng(seed))
    for _ in ex:
        pass
    return ex


@pytest.fixture(scope="module")
def small_model() -> LearnedModel:
    """A model of a 2 x 3 keyboard learned with 300 active reaches."""
    return _explore(SMALL, "active", 300).model


# -- sound classes ------------------------------------------------------------------------------
def test_discover_classes_finds_the_sounds_whatever_the_order():
    rng = np.random.default_rng(0)
    true = np.array([[60.0, 60.0], [62.0, 64.0], [64.0, 68.0]])
    idx = rng.integers(0, 3, 200)
    s = true[idx] + rng.normal(0, 0.15, size=(200, 2))
    s[::7] = np.nan  # silence
    feats, labels = discover_classes(s, 1.5)
    assert feats.shape == (4, 2) and np.isnan(feats[0]).all()
    np.testing.assert_allclose(feats[1:], true, atol=0.1)
    silent = np.isnan(s).any(axis=1)
    assert (labels[silent] == 0).all()
    np.testing.assert_array_equal(labels[~silent], idx[~silent] + 1)
    perm = rng.permutation(200)
    feats2, labels2 = discover_classes(s[perm], 1.5)
    np.testing.assert_allclose(feats2, feats, atol=1e-9)
    np.testing.assert_array_equal(labels2, labels[perm])


def test_discover_classes_merges_classes_split_by_noise():
    s = np.array([[60.0, 60.0], [60.9, 60.0], [61.8, 60.0], [61.0, 60.0]])
    feats, labels = discover_classes(s, 1.5)
    assert len(feats) == 2 and (labels == 1).all()


# -- geometry -----------------------------------------------------------------------------------
def test_convex_hull_of_a_square_with_inner_points():
    p = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [0.2, 0.7]], float)
    h = convex_hull(p)
    assert {tuple(v) for v in h} == {(0, 0), (1, 0), (1, 1), (0, 1)}


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_separating_line_is_the_hard_margin_svm(seed):
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * np.pi)
    n = np.array([np.cos(ang), np.sin(ang)])
    p = rng.uniform(-30, 30, size=(40, 2))
    v = p @ n
    a, b = p[v > 0.5], p[v < -0.5]
    if len(a) == 0 or len(b) == 0:
        return
    line, separable = separating_line(a, b)
    assert separable
    assert (a @ line[:2] - line[2] > 0).all() and (b @ line[:2] - line[2] < 0).all()
    svm = SVC(kernel="linear", C=1e8).fit(np.vstack([a, b]) / 10,
                                          np.r_[np.ones(len(a)), np.zeros(len(b))])
    w = svm.coef_[0] / np.linalg.norm(svm.coef_[0])
    np.testing.assert_allclose(line[:2], w, atol=2e-3)
    np.testing.assert_allclose(line[2], -svm.intercept_[0] * 10 / np.linalg.norm(svm.coef_[0]),
                               atol=0.02)


# -- the estimator contract ---------------------------------------------------------------------
def test_predicting_before_fit_raises():
    m = LearnedModel()
    with pytest.raises(NotFittedError):
        m.predict_proba(np.zeros((1, 2)))
    with pytest.raises(NotFittedError):
        m.to_arrays()


@pytest.mark.parametrize("kwargs", [{"match_threshold": 0}, {"n_neighbors": 1},
                                    {"area": (0, 0, -1, 5)}, {"min_sd": 0}, {"max_sd": 0.01},
                                    {"merge_angle": 95}, {"extrapolation": -1.0}])
def test_bad_parameters_are_refused_at_fit(kwargs):
    with pytest.raises(ConfigError):
        LearnedModel(**kwargs).fit(np.zeros((2, 2)), np.full((2, 2), np.nan))


def test_fit_returns_self_and_sets_fitted_attributes():
    x = np.array([[300.0, 300.0], [330.0, 300.0], [315.0, 330.0]])
    s = np.array([[60.0, 60.0], [np.nan, np.nan], [62.0, 64.0]])
    m = LearnedModel()
    assert m.fit(x, s) is m
    assert m.n_classes == 3 and m.actions_.shape == (3, 2) and len(m.edges_) == 3
    assert m.reach_sd_ == 0.0
    m.fit(x, s, targets=x + 1.0)
    assert m.reach_sd_ == pytest.approx(1.0)


def test_probabilities_are_distributions_and_agree_with_predict_class(small_model):
    q = np.random.default_rng(3).uniform(SMALL.area[:2], SMALL.area[2:], size=(4000, 2))
    p = small_model.predict_proba(q)
    assert p.shape == (4000, small_model.n_classes)
    assert (p >= 0).all()
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-9)
    sure = np.sort(p, axis=1)[:, -1] > 0.5 + 1e-6
    np.testing.assert_array_equal(np.argmax(p[sure], axis=1), small_model.predict_class(q[sure]))
    c = small_model.confusion(q)
    assert (c >= 0).all() and (c <= 1 + 1e-12).all()


def test_a_learned_small_keyboard_is_accurate(small_model):
    assert small_model.n_classes == SMALL.n_keys + 1
    keys = scoring.class_keys(small_model.class_features_, SMALL)
    assert sorted(keys[1:]) == list(range(SMALL.n_keys))
    pred, true = scoring.key_maps(small_model, SMALL, 1.0)
    assert scoring.accuracy_from_maps(pred, true) > 0.99
    assert scoring.boundary_error(pred, true) < 2.0


def test_classify_matches_perceived_sounds(small_model):
    f = small_model.class_features_
    got = small_model.classify(np.vstack([f[3] + 0.2, [np.nan, np.nan], [300.0, 300.0]]))
    np.testing.assert_array_equal(got, [3, 0, -1])


def test_sample_actions_draws_from_the_sound_region(small_model):
    rng = np.random.default_rng(4)
    keys = scoring.class_keys(small_model.class_features_, SMALL)
    for cls in (1, small_model.n_classes - 1, 0):
        a = small_model.sample_actions(cls, 300, rng)
        assert a.shape == (300, 2)
        x0, y0, x1, y1 = SMALL.area
        assert ((a[:, 0] >= x0) & (a[:, 0] <= x1) & (a[:, 1] >= y0) & (a[:, 1] <= y1)).all()
        assert np.mean(SMALL.key_at(a) == keys[cls]) > 0.95  # soft near the edges
    with pytest.raises(ValueError):
        small_model.sample_actions(small_model.n_classes, 1, rng)


def test_raster_is_a_probability_grid(small_model):
    r = small_model.raster(5.0)
    x0, y0, x1, y1 = SMALL.area
    assert r.probs.shape == (int((y1 - y0) / 5), int((x1 - x0) / 5), small_model.n_classes)
    assert r.probs.dtype == np.float32
    np.testing.assert_allclose(r.probs.sum(axis=-1), 1.0, atol=1e-5)


def test_round_trip_is_exact_in_memory_and_through_hdf5(small_model, tmp_path):
    d = small_model.to_arrays()
    m2 = LearnedModel.from_arrays(d)
    for k, v in m2.to_arrays().items():
        np.testing.assert_array_equal(v, d[k])
    q = np.random.default_rng(5).uniform(SMALL.area[:2], SMALL.area[2:], size=(3000, 2))
    np.testing.assert_array_equal(m2.predict_proba(q), small_model.predict_proba(q))
    write_artifact(Artifact(kind="model", config={}, data={"model": d}), tmp_path / "m.h5")
    m3 = LearnedModel.from_arrays(read_artifact(tmp_path / "m.h5", validate=False).data["model"])
    np.testing.assert_array_equal(m3.predict_proba(q), small_model.predict_proba(q))
    np.testing.assert_array_equal(m3.raster(4.0).probs, small_model.raster(4.0).probs)


def test_from_arrays_refuses_other_data():
    with pytest.raises(ArtifactError, match="not a stored learned model"):
        LearnedModel.from_arrays({"actions": np.zeros((2, 2))})


# -- scores -------------------------------------------------------------------------------------
def test_exact_model_scores_perfectly():
    pred, true = scoring.key_maps(ExactModel(KB), KB, 1.0)
    assert scoring.accuracy_from_maps(pred, true) == 1.0
    assert scoring.boundary_error(pred, true) == 0.0


@settings(max_examples=10, deadline=None)
@given(k=st.integers(1, 6))
def test_boundary_error_of_a_shifted_map_is_the_shift(k):
    _, true = scoring.key_maps(ExactModel(KB), KB, 1.0)
    shifted = np.roll(true, k, axis=1)  # every vertical edge k px to the right
    shifted[:, :k] = -1
    err = scoring.boundary_error(shifted, true)
    # vertical edges are k px off; horizontal ones are mostly in place
    assert 0.3 * k < err <= k + 1e-9
    assert scoring.accuracy_from_maps(shifted, true) < 1.0


def test_boundary_error_edge_cases():
    a = np.zeros((5, 5), int)
    assert scoring.boundary_error(a, a) == 0.0
    b = a.copy()
    b[:, 3:] = 1
    assert scoring.boundary_error(a, b) == float("inf")
    assert scoring.boundary_error(b, b) == 0.0


# -- exploration --------------------------------------------------------------------------------
def test_unknown_strategy_lists_the_valid_ones():
    with pytest.raises(ConfigError, match="active, balanced, random"):
        STRATEGIES.get("greedy")
    with pytest.raises(ConfigError, match="budget"):
        ExploreConfig(budget=0)


def test_a_strategy_owns_its_options():
    """``explore_radius`` is the covering strategies' (active, balanced): given flat it goes to
    the chosen one, another refuses it; a model records the learn config flat, as before."""
    from kbcli.core.model.explore.base import Covering
    from kbcli.stages.learn import LearnConfig, model_config

    cfg = ExploreConfig(strategy="balanced", explore_radius=12.0)
    assert cfg.strategy == Covering(name="balanced", explore_radius=12.0)
    assert ExploreConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ConfigError, match="exploration strategy random takes no option "
                                          "'explore_radius' \\(exploration strategy active and "
                                          "balanced do\\)"):
        ExploreConfig(strategy="random", explore_radius=12.0)
    learn = LearnConfig(explore_radius=12.0)
    assert learn.explore_config().strategy == Covering(name="active", explore_radius=12.0)
    recorded = model_config(learn, {})
    assert recorded["strategy"] == "active" and recorded["explore_radius"] == 12.0
    assert "explore_radius" not in model_config(LearnConfig(strategy="random"), {})


def test_hex_lattice_covers_the_area_to_its_radius():
    rng = np.random.default_rng(0)
    r = 20.0
    lat = hex_lattice(KB.area, r * np.sqrt(3), rng)
    probe = rng.uniform((KB.area[0] + r, KB.area[1] + r), (KB.area[2] - r, KB.area[3] - r),
                        size=(5000, 2))
    d = np.min(np.hypot(probe[:, None, 0] - lat[:, 0], probe[:, None, 1] - lat[:, 1]), axis=1)
    assert d.max() <= r + 1e-9


def test_farthest_points_spreads_out():
    c = np.array([[0.0, 0.0], [1.0, 0.0], [10.0, 0.0], [5.0, 0.0]])
    np.testing.assert_array_equal(farthest_points(c, np.array([[0.0, 0.0]]), 2),
                                  [[10.0, 0.0], [5.0, 0.0]])


@pytest.mark.parametrize("strategy", sorted(STRATEGIES))
def test_every_strategy_explores_inside_the_area_reproducibly(strategy):
    a = _explore(SMALL, strategy, 60, seed=3)
    b = _explore(SMALL, strategy, 60, seed=3)
    np.testing.assert_array_equal(a.targets, b.targets)
    assert a.targets.shape == (60, 2) and a.perceived.shape == (60, 2)
    x0, y0, x1, y1 = SMALL.area
    t = a.targets
    assert ((t[:, 0] >= x0) & (t[:, 0] <= x1) & (t[:, 1] >= y0) & (t[:, 1] <= y1)).all()
    assert a.model.n_classes >= 2


def test_active_covers_then_beats_random():
    active = _explore(KB, "active", 300, seed=1)
    random = _explore(KB, "random", 300, seed=1)
    # every key was heard (the cover phase), and the model is better than random's
    assert active.model.n_classes == KB.n_keys + 1
    assert scoring.accuracy(active.model, KB, 2.0) > scoring.accuracy(random.model, KB, 2.0) + 0.03
