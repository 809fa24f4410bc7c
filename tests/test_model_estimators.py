"""Model classes as scikit-learn estimators (issue 25): known answers that a plausible bug fails.

Each test here is fast and aimed at one mutation: the sign of the svc model's decision far from
its samples, an expected calibration error with the absolute value outside the sum over bins, a
class that does not separate two half-planes, a parameter lost by ``clone``, an unknown model
class that does not list the valid ones.
"""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.core.model.classes import (
    MODEL_CLASSES,
    learned_classes,
    make_model,
    model_class_of,
)
from kbcli.core.model.lines import LearnedModel
from kbcli.core.model.pairwise import ModelBase
from kbcli.core.model.reliability import expected_calibration_error
from kbcli.core.model.svc import SVCModel
from kbcli.errors import ConfigError

AREA = (150.0, 200.0, 650.0, 500.0)
LEFT, RIGHT = [10.0, 10.0], [20.0, 20.0]  # class 1 (lower features) and class 2


def _half_planes(ys=np.arange(300.0, 401.0, 20.0)) -> tuple[np.ndarray, np.ndarray]:
    """Samples every 20 px, heard as LEFT where x < 390 and RIGHT where x > 390."""
    g = np.stack(np.meshgrid(np.arange(160.0, 641.0, 20.0), ys), -1).reshape(-1, 2)
    heard = np.where((g[:, 0] < 390.0)[:, None], [LEFT], [RIGHT])
    return g, heard


# -- the svc model's sign, near the samples and far from them -------------------------------------
def test_svc_far_field_follows_the_nearest_sample():
    """Samples only in a band y in [300, 400]: 80 px above it (over three length scales) the
    pair's machine has faded into the nearest-sample rule. Left of x = 390 the nearer sample is
    LEFT's, right of it RIGHT's; a flipped decision (or a flipped nearest-sample rule) swaps
    them."""
    x, heard = _half_planes()
    model = SVCModel(area=AREA).fit(x, heard)
    assert model.n_classes == 3
    far = np.array([[375.0, 220.0], [405.0, 220.0], [375.0, 480.0], [405.0, 480.0]])
    # both sounds are among the nearest samples there: the pair's machine decides
    cls, _ = model._slot_scores(far)
    assert all({1, 2} <= set(row) for row in cls.tolist())
    assert model.predict_class(far).tolist() == [1, 2, 1, 2]
    p = model.predict_proba(far)
    assert (p[[0, 2], 1] > 0.5).all() and (p[[1, 3], 2] > 0.5).all()
    (code,) = model._pairs
    f = model._decision(code, far)
    assert (f[[0, 2]] < 0).all() and (f[[1, 3]] > 0).all()  # > 0 on the higher class's side


def test_svc_near_field_decision_is_signed_towards_the_higher_class():
    x, heard = _half_planes()
    model = SVCModel(area=AREA).fit(x, heard)
    (code,) = model._pairs
    q = np.array([[385.0, 350.0], [395.0, 350.0], [300.0, 350.0], [500.0, 350.0]])
    f = model._decision(code, q)
    assert f[0] < 0 < f[1] and f[2] < -1 and f[3] > 1
    lo, hi = model._pair_logp(code, q)
    np.testing.assert_allclose(np.exp(lo) + np.exp(hi), 1.0)
    assert lo[2] > np.log(0.99) and hi[3] > np.log(0.99)


# -- every learned class separates two half-planes exactly ----------------------------------------
@pytest.mark.parametrize("name", learned_classes())
def test_every_class_separates_two_half_planes(name):
    """Samples either side of x = 390 on a 20 px lattice: the max-margin boundary is x = 390, so
    every point of the sampled band more than 1 px from it gets its side's sound, and the
    samples themselves are classified as heard."""
    ys = np.arange(220.0, 481.0, 20.0)
    x, heard = _half_planes(ys)
    model = make_model(name, match_threshold=1.5, area=AREA).fit(x, heard)
    assert isinstance(model, ModelBase) and model.n_classes == 3
    rng = np.random.default_rng(0)
    q = rng.uniform((160.0, 220.0), (640.0, 480.0), size=(4000, 2))
    q = q[np.abs(q[:, 0] - 390.0) > 1.0]
    want = np.where(q[:, 0] < 390.0, 1, 2)
    np.testing.assert_array_equal(model.predict_class(q), want)
    np.testing.assert_array_equal(model.predict(x), np.where(x[:, 0] < 390.0, 1, 2))
    p = model.predict_proba(q)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    assert (p[np.arange(len(q)), want] > 0.5).all()
    # ClassifierMixin.score: the mean accuracy on the samples' own labels
    assert model.score(x, np.where(x[:, 0] < 390.0, 1, 2)) == 1.0


# -- scikit-learn's parameter protocol ---------------------------------------------------------------
@pytest.mark.parametrize("name", learned_classes())
def test_clone_and_get_params_round_trip(name):
    mc = MODEL_CLASSES.get(name)
    model = make_model(name, match_threshold=2.5, area=AREA)
    params = model.get_params()
    assert set(params) == {"match_threshold", "area", *mc.params}
    twin = clone(model)
    assert twin is not model and twin.get_params() == params
    assert type(twin)(**params).get_params() == params
    x, heard = _half_planes()
    model.fit(x, heard)
    fresh = clone(model)  # a clone is unfitted, with the same settings
    assert fresh.get_params() == params
    with pytest.raises(NotFittedError):
        fresh.predict_proba(x[:1])
    with pytest.raises(ValueError, match="Invalid parameter"):
        clone(model).set_params(no_such_parameter=1.0)


def test_set_params_recalibrates_a_fitted_lines_model():
    """The prediction-time calibration of the lines model is a parameter: set on a copy of the
    fitted model (as :func:`kbcli.core.model.reliability.assess` does), it changes the probabilities
    and leaves the original alone."""
    import copy

    x, heard = _half_planes()
    model = LearnedModel(area=AREA).fit(x, heard)
    q = np.array([[388.0, 350.0], [300.0, 350.0]])
    calibrated = copy.copy(model).set_params(noise_sd=6.0, floor=0.01)
    assert model.noise_sd == 0.0 and model.floor == 0.0
    p0, p1 = model.predict_proba(q), calibrated.predict_proba(q)
    assert p1[0, 1] < p0[0, 1]  # wider uncertainty near the boundary
    assert p1[1, 1] == pytest.approx(1 - 0.01 + 0.01 / 3)  # the floor far from it


# -- the registry --------------------------------------------------------------------------------
def test_unknown_model_class_is_one_line_listing_the_valid_ones():
    with pytest.raises(ConfigError) as err:
        MODEL_CLASSES.get("gp")
    assert str(err.value) == "unknown model class 'gp'; valid: lines, svc, forest, forest-xy, knn, exact"
    with pytest.raises(ConfigError) as err:
        make_model("exact", match_threshold=1.5, area=AREA)
    assert str(err.value) == ("model class 'exact' is not learned from samples; valid: "
                              "lines, svc, forest, forest-xy, knn")
    from kbcli.stages.learn import LearnConfig

    with pytest.raises(ConfigError) as err:
        LearnConfig(model_class="gp")
    assert "\n" not in str(err.value)
    assert str(err.value).startswith("learn.model_class: unknown model class 'gp'; valid: ")


def test_exact_is_a_model_class_and_only_its_map_is_exact():
    kb = Keyboard(KeyboardConfig())
    exact = MODEL_CLASSES.get("exact")
    assert not exact.learned and exact.params == ()
    model = exact.load(None, kb)
    assert isinstance(model, ExactModel) and model.exact_map is True
    for name in learned_classes():
        assert MODEL_CLASSES.get(name).learned
        assert make_model(name, match_threshold=1.5, area=AREA).exact_map is False
    assert model_class_of({"strategy": "exact"}) == "exact"
    assert model_class_of({"strategy": "active"}) == "lines"  # schema 1: always lines
    assert model_class_of({"strategy": "active", "model_class": "svc"}) == "svc"


# -- expected calibration error ------------------------------------------------------------------
def _two_bins() -> tuple[np.ndarray, np.ndarray]:
    """20 predictions at confidence 0.95 of which 11 are right, 20 at 0.55 of which 19 are:
    gaps of -0.40 and +0.40, which cancel if the bins' gaps are summed before the abs."""
    probs = np.array([[0.95, 0.05]] * 20 + [[0.55, 0.45]] * 20)
    hit = np.r_[np.ones(11), np.zeros(9), np.ones(19), np.zeros(1)]
    return probs, hit


def test_ece_sums_the_absolute_gap_of_every_bin():
    probs, hit = _two_bins()
    assert expected_calibration_error(probs, hit) == pytest.approx(0.40)
    # weights count as repetitions: the first bin doubled gives (2 * 0.4 + 0.4) / 3
    w = np.r_[np.full(20, 2.0), np.ones(20)]
    assert expected_calibration_error(probs, hit, weights=w) == pytest.approx(0.40)
    # one bin over-confident by 0.4, the other exact: half the weight at 0.4
    exact = np.r_[hit[:20], np.ones(11), np.zeros(9)]
    assert expected_calibration_error(probs, exact) == pytest.approx(0.20)
    # the true distribution form: the probability of the predicted class
    truth = np.column_stack([np.r_[np.full(20, 0.55), np.full(20, 0.95)],
                             np.r_[np.full(20, 0.45), np.full(20, 0.05)]])
    assert expected_calibration_error(probs, truth) == pytest.approx(0.40)


def test_debiased_ece_takes_the_binomial_noise_out_of_each_bin():
    probs, hit = _two_bins()
    # sqrt(gap^2 - a (1 - a) / (n - 1)) per bin, weighted by its share
    want = 0.5 * np.sqrt(0.16 - 0.55 * 0.45 / 19) + 0.5 * np.sqrt(0.16 - 0.95 * 0.05 / 19)
    assert expected_calibration_error(probs, hit, debiased=True) == pytest.approx(want)
    # a perfectly calibrated bin of few outcomes: the noise is not counted as an error
    calm = np.array([[0.75, 0.25]] * 4)
    assert expected_calibration_error(calm, np.array([1.0, 1.0, 1.0, 0.0]), debiased=True) == 0.0
