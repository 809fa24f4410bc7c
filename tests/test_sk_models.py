"""The model classes on plain scikit-learn classifiers (issue 27): ``forest`` and ``knn``.

Known answers: each separates two half-planes and a disc, its probabilities are calibrated on a
noisy synthetic case (after the floor chosen by cross-validation), its stored arrays refit to the
same predictions (no pickle), and bad hyper-parameters are one line.
"""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.core.model_classes import MODEL_CLASSES, make_model, model_from_arrays
from kbcli.core.reliability import assess, expected_calibration_error
from kbcli.core.sk_models import ForestModel, KNNModel
from kbcli.errors import ArtifactError, ConfigError

AREA = (150.0, 200.0, 650.0, 500.0)
A, B = [10.0, 10.0], [20.0, 20.0]
NEW = ("forest", "knn")


def _lattice(step: float = 10.0) -> np.ndarray:
    g = np.stack(np.meshgrid(np.arange(160.0, 650.0, step), np.arange(210.0, 500.0, step)), -1)
    return g.reshape(-1, 2)


def _disc(x: np.ndarray) -> np.ndarray:
    """Heard B inside the disc of radius 60 px around (400, 350), silence (NaN) outside."""
    inside = np.hypot(x[:, 0] - 400.0, x[:, 1] - 350.0) < 60.0
    return np.where(inside[:, None], [B], np.nan)


@pytest.mark.parametrize("name", NEW)
def test_separates_two_half_planes(name):
    x = _lattice(20.0)
    heard = np.where((x[:, 0] < 390.0)[:, None], [A], [B])
    model = make_model(name, match_threshold=1.5, area=AREA).fit(x, heard)
    assert model.n_classes == 3
    q = np.random.default_rng(0).uniform((160.0, 210.0), (640.0, 490.0), size=(4000, 2))
    q = q[np.abs(q[:, 0] - 390.0) > 3.0]
    np.testing.assert_array_equal(model.predict_class(q), np.where(q[:, 0] < 390.0, 1, 2))
    np.testing.assert_array_equal(model.predict_class(x), np.where(x[:, 0] < 390.0, 1, 2))


@pytest.mark.parametrize("name", NEW)
def test_separates_a_disc(name):
    x = _lattice(10.0)
    model = make_model(name, match_threshold=1.5, area=AREA).fit(x, _disc(x))
    q = np.random.default_rng(1).uniform((160.0, 210.0), (640.0, 490.0), size=(6000, 2))
    r = np.hypot(q[:, 0] - 400.0, q[:, 1] - 350.0)
    far = np.abs(r - 60.0) > 6.0  # a sample spacing from the circle
    want = np.where(r < 60.0, 1, 0)
    np.testing.assert_array_equal(model.predict_class(q[far]), want[far])
    near = np.abs(r - 60.0) < 10.0
    assert np.mean(model.predict_class(q[near]) == want[near]) > 0.85
    p = model.predict_proba(q)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)


@pytest.mark.parametrize("name", NEW)
def test_probabilities_are_calibrated_on_a_noisy_case(name):
    """Sounds heard with a logistic ramp across x = 400 (10 px wide): after the calibration
    chosen by cross-validation, held-out-style predictions on fresh noisy draws have a small
    calibration error."""
    rng = np.random.default_rng(3)
    x = rng.uniform((160.0, 210.0), (640.0, 490.0), size=(800, 2))
    p_b = 1.0 / (1.0 + np.exp(-(x[:, 0] - 400.0) / 10.0))
    heard = np.where((rng.uniform(size=len(x)) < p_b)[:, None], [B], [A])
    model = make_model(name, match_threshold=1.5, area=AREA).fit(x, heard)
    model, _ = assess(model, x, heard, rng=np.random.default_rng(0))
    q = rng.uniform((160.0, 210.0), (640.0, 490.0), size=(4000, 2))
    truth = 1.0 / (1.0 + np.exp(-(q[:, 0] - 400.0) / 10.0))
    p = model.predict_proba(q)
    true_dist = np.column_stack([np.zeros(len(q)), 1 - truth, truth])
    assert expected_calibration_error(p, true_dist) < 0.1


@pytest.mark.parametrize("name", NEW)
def test_stored_model_refits_to_the_same_predictions(name):
    x = _lattice(10.0)
    model = make_model(name, match_threshold=1.5, area=AREA).fit(x, _disc(x))
    d = model.to_arrays()
    assert all(np.asarray(v).dtype != object for v in d.values())
    back = model_from_arrays(d, name)
    q = np.random.default_rng(2).uniform((160.0, 210.0), (640.0, 490.0), size=(3000, 2))
    np.testing.assert_array_equal(back.predict_proba(q), model.predict_proba(q))
    np.testing.assert_array_equal(back.raster(5.0).probs, model.raster(5.0).probs)
    sites = back.boundary_sites(phase=0.5)
    r = np.hypot(sites["points"][:, 0] - 400.0, sites["points"][:, 1] - 350.0)
    assert len(r) and np.all(np.abs(r - 60.0) < 8.0)
    assert set(map(tuple, sites["pair"].tolist())) == {(0, 1)}
    a = back.sample_actions(1, 50, np.random.default_rng(0))
    assert np.all(np.hypot(a[:, 0] - 400.0, a[:, 1] - 350.0) < 70.0)
    with pytest.raises(ArtifactError, match=f"not a stored {name} model"):
        model_from_arrays({k: v for k, v in d.items() if k != "actions"}, name)


def test_forest_seed_is_stored_and_changes_the_trees():
    x = _lattice(20.0)
    heard = _disc(x)
    a = ForestModel(area=AREA, random_state=1).fit(x, heard)
    assert int(a.to_arrays()["random_state"]) == 1
    b = ForestModel(area=AREA, random_state=2).fit(x, heard)
    q = np.random.default_rng(2).uniform((300.0, 250.0), (500.0, 450.0), size=(2000, 2))
    assert not np.array_equal(a.predict_proba(q), b.predict_proba(q))


@pytest.mark.parametrize(("name", "params", "msg"), [
    ("forest", {"n_estimators": 0}, "n_estimators must be a whole number >= 1, got 0"),
    ("forest", {"n_directions": 1}, "n_directions must be a whole number >= 2"),
    ("forest", {"random_state": -1}, "random_state must be a whole number >= 0"),
    ("knn", {"n_neighbors": 2.5}, "n_neighbors must be a whole number >= 1, got 2.5"),
    ("knn", {"floor": 1.0}, r"floor must be in \[0, 1\)"),
])
def test_bad_hyper_parameters_are_one_line(name, params, msg):
    x = _lattice(20.0)
    with pytest.raises(ConfigError, match=msg):
        make_model(name, match_threshold=1.5, area=AREA, **params).fit(x, _disc(x))


def test_registered_with_their_parameters():
    assert set(MODEL_CLASSES.get("forest").params) == {
        "n_estimators", "n_directions", "min_samples_leaf", "random_state", "floor"}
    assert set(MODEL_CLASSES.get("knn").params) == {"n_neighbors", "floor"}
    assert MODEL_CLASSES.get("knn").estimator() is KNNModel
