"""The adaptation that repairs the model (issue 42): the repaired belief's known answers on a
two-key instrument, its invariants, the repaired model and its artifact."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.core.adaptation import credible
from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.likelihood.robust import Nuisance
from kbcli.core.adaptation.repair import (
    RepairBelief,
    RepairMap,
    Touches,
    absorb,
    kernel,
    repair_terms,
    repaired_map,
)
from kbcli.core.adaptation.strategies import entropy_rows
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model import accuracy as scoring
from kbcli.core.model.base import ExactModel
from kbcli.core.model.classes import fit_model
from kbcli.core.model.table import LikelihoodTable
from kbcli.errors import ConfigError
from kbcli.sim import SimConfig, World, make_reacher


@pytest.fixture(scope="module")
def keyboard():
    return Keyboard(KeyboardConfig())


@pytest.fixture(scope="module")
def exact_model(keyboard):
    return ExactModel(keyboard)


@pytest.fixture(scope="module")
def world_of(keyboard):
    """``world_of(shift)``: the default keyboard moved by ``shift``, touched by the ideal arm."""
    def make(shift):
        return World(keyboard, make_reacher(SimConfig()), np.asarray(shift, float), "translation")
    return make


@pytest.fixture(scope="module")
def weak_model(keyboard, world_of):
    """A weak forest-xy model: 150 random reaches of the ideal arm at the reference pose."""
    rng = np.random.default_rng(7)
    acts = rng.uniform(keyboard.area[:2], keyboard.area[2:], size=(150, 2))
    felt, heard = world_of(np.zeros(2)).touch(acts, rng)
    model = fit_model("forest-xy", felt, heard, match_threshold=keyboard.config.match_threshold,
                      area=keyboard.area)
    return model, keyboard, world_of


@pytest.fixture(scope="module")
def boundary_error_of():
    def berr(model, kb):
        pred, true = scoring.key_maps(model, kb, 1.0)
        return scoring.boundary_error(pred, true, 1.0)
    return berr


STEP = 1.0
H, W = 5, 20  # a 20 x 5 px raster: class 1 left of x = BOUND, class 2 right of it


def two_keys(bound: float, eps: float = 1e-3) -> LikelihoodTable:
    """A two-key instrument's map (classes 1 | 2, silence 0 unused inside), cells centred on
    integers 0..19 x 0..4."""
    probs = np.zeros((H, W, 3), np.float32)
    x = np.arange(W)
    probs[:, x < bound, 1] = 1
    probs[:, x >= bound, 2] = 1
    return LikelihoodTable(np.zeros(2), STEP, 3, eps, probs=probs)


def flat_map(table: LikelihoodTable, kappa: float, width: float) -> RepairMap:
    """A repair map with the same confidence everywhere and no local blur."""
    return RepairMap(table, np.zeros(table.shape, np.float32),
                     np.full(table.shape, kappa, np.float32), width)


def small_grid() -> HypothesisGrid:
    return HypothesisGrid.build("translation", prior_halfwidth=2.0, resolution=1.0,
                                centre=np.zeros(2))


def test_two_keys_first_touch_is_the_model_then_the_counts_by_hand():
    """kappa 2, kernel 1 px: the first touch reads the model; a second one at the same spot with
    the same sound reads (2 q + 1) / (2 + 1) at every hypothesis."""
    table = two_keys(10)
    rmap = flat_map(table, 2.0, 1.0)
    grid = small_grid()  # dx, dy in -2..2
    nz = Nuisance.build((0.0,), (0.5,))  # eps 0.5 of 3 sounds: p' = p / 2 + 1 / 6
    a = np.array([10.0, 2.0])  # under dx, the touch reads cell 10 - dx: class 2 iff dx <= 0
    first = repair_terms(grid, rmap, Touches(), a, 2, nz)[0]
    q = (grid.dx <= 0).astype(float)  # the model's p(2 | a - h), per dx column
    assert np.allclose(first, np.log(q / 2 + 1 / 6)[None, :].repeat(5, axis=0))
    second = repair_terms(grid, rmap, Touches().add(a, 2), a, 2, nz)[0]
    by_hand = (2 * q + 1) / (2 + 1)
    assert np.allclose(second, np.log(by_hand / 2 + 1 / 6)[None, :].repeat(5, axis=0))
    # the second touch says less about the shift than the first: a narrower log range
    assert np.ptp(second) < np.ptp(first)


def test_a_touch_of_another_sound_nearby_keeps_its_information():
    """Counts of other sounds only scale a term (the same at every hypothesis when kappa is
    flat): a touch next to an earlier one of another sound tells the shift as much as alone."""
    table = two_keys(10)
    rmap = flat_map(table, 2.0, 3.0)
    grid, nz = small_grid(), Nuisance.build((0.0,), (0.001,))
    a = np.array([10.0, 2.0])
    alone = repair_terms(grid, rmap, Touches(), a, 1, nz)[0]
    beside = repair_terms(grid, rmap, Touches().add(a + [0.5, 0], 2), a, 1, nz)[0]
    def normalised(term):
        p = np.exp(term - term.max())
        return p / p.sum()

    assert np.allclose(normalised(beside), normalised(alone), atol=2e-3)


def test_belief_finds_the_shift_of_a_two_key_instrument():
    """Touches of the two-key instrument moved by dx = +1 (boundary at 11 on the pad): the
    belief puts its mass on dx = 1, any dy (the map does not vary in y)."""
    table = two_keys(10)
    rmap = flat_map(table, 1.0, 1.0)
    belief = RepairBelief.start(small_grid(), rmap, (0.0,), (0.001,))
    for x, c in ((10.4, 1), (11.0, 2), (9.0, 1), (13.0, 2)):
        belief = belief.update(np.array([x, 2.0]), c)
    marg = belief.marginal().marginals()[1]  # over dx
    assert np.argmax(marg) == list(small_grid().dx).index(1.0)
    assert marg.max() > 0.9


def test_planning_keeps_one_over_k_plus_one_of_a_touched_spots_information():
    """The plan reads the model's map at the belief's hypotheses; a candidate within the radius
    of k earlier touches keeps 1 / (k + 1) of its information, the others all of it."""
    table = two_keys(10)
    grid = small_grid()
    belief = RepairBelief.start(grid, flat_map(table, 1.0, 1.0), (0.0,), (0.001,), radius=2.0)
    hyp = grid.params(np.arange(grid.size))
    w = np.full(grid.size, 1.0 / grid.size)
    actions = np.array([[10.0, 2.0], [15.0, 2.0]])
    def gain(b):
        pred, cond = b.outcome(table, hyp, w, actions)
        return pred, entropy_rows(pred) - cond

    pred0, gain0 = gain(belief)
    once = belief.update(np.array([10.5, 2.0]), 2)  # within 2 px of the first candidate only
    pred1, gain1 = gain(once)
    assert np.allclose(pred1, pred0)
    assert gain0[0] > 0.1
    assert gain1[0] == pytest.approx(gain0[0] / 2)
    assert gain1[1] == pytest.approx(gain0[1])
    twice = once.update(np.array([9.5, 2.0]), 1)
    assert gain(twice)[1][0] == pytest.approx(gain0[0] / 3)


def test_belief_rejects_a_rotating_grid():
    grid = HypothesisGrid.build("rigid", prior_halfwidth=2.0, resolution=1.0, centre=np.zeros(2),
                                max_angle=1.0, angle_resolution=0.5)
    with pytest.raises(ValueError, match="translation"):
        repair_terms(grid, flat_map(two_keys(10), 1.0, 1.0), Touches(), np.array([5.0, 2.0]), 1,
                     Nuisance.build((0.0,), (0.01,)))


@settings(max_examples=40, deadline=None)
@given(bound=st.integers(4, 16), error=st.integers(-3, 3), shift=st.integers(-2, 2),
       xs=st.lists(st.integers(0, W - 1), min_size=1, max_size=12),
       kappa=st.floats(0.05, 5.0))
def test_repair_with_the_true_shift_never_lowers_accuracy(bound, error, shift, xs, kappa):
    """A model whose edge is ``error`` px off; touches of the true instrument (moved by
    ``shift``) read on cell centres, mapped back by the true shift into a per-cell repaired map
    (a kernel far narrower than a cell): its accuracy against the instrument never falls."""
    model = two_keys(bound + error)
    rmap = flat_map(model, kappa, 0.05)
    truth = two_keys(bound).argmax()
    touches = Touches()
    for x in xs:
        pad_x = x + shift  # where the touch lands on the moved pad
        cls = 1 if x < bound else 2
        touches = touches.add(np.array([pad_x, 2.0]), cls)
    before = float(np.mean(model.argmax() == truth))
    after = float(np.mean(np.argmax(repaired_map(rmap, touches, np.array([shift, 0.0]), 0.0),
                                    axis=-1) == truth))
    assert after >= before


def test_kernel_counts_a_touch_once_at_its_spot():
    assert kernel(np.array(0.0), 2.0) == 1.0
    assert math.isclose(float(kernel(np.array(4.0), 2.0)), math.exp(-0.5))


def test_confidence_counts_training_samples_with_the_kernel():
    """kappa at a training sample is about one (the sample) plus the floor; far from any, the
    floor."""
    table = two_keys(10)
    rmap = RepairMap.build(table, np.array([[5.0, 2.0]]), width=1.0, floor=0.2)
    assert rmap.confidence(np.array(5.0), np.array(2.0)) == pytest.approx(1.2, abs=0.05)
    assert rmap.confidence(np.array(15.0), np.array(2.0)) == pytest.approx(0.2, abs=1e-3)
    assert rmap.distance[2, 8] == pytest.approx(3.0)


def test_credible_radius_of_known_posteriors():
    dx = dy = np.arange(-3.0, 4.0)
    p = np.zeros((7, 7))
    p[3, 3] = 1.0
    assert credible.radius_of(dx, dy, p, np.zeros(2)) == 0.0
    p[3, 3], p[3, 5] = 0.5, 0.5  # half the mass at (2, 0)
    assert credible.radius_of(dx, dy, p, np.zeros(2), 0.9) == pytest.approx(2.0)
    assert credible.radius_of(dx, dy, p, np.zeros(2), 0.4) == 0.0
    with pytest.raises(ValueError):
        credible.radius_of(dx, dy, p, np.zeros(2), 0.0)


def test_repair_config_is_opt_in_and_checked():
    assert AdapterConfig().posterior.repair is False
    assert AdapterConfig(repair=True).to_dict()["posterior"]["repair"] is True
    with pytest.raises(ConfigError, match="translation"):
        AdapterConfig.from_dict({"repair": True, "family": "rigid"})
    with pytest.raises(ConfigError, match="robust"):
        AdapterConfig.from_dict({"repair": True, "robust": False})
    with pytest.raises(ConfigError, match="posterior kde takes no option 'repair'"):
        AdapterConfig.from_dict({"repair": True, "posterior": "kde"})
    # the repair's own options are read only with it; the robust posterior's own ones not with it
    assert "repair_kernel" in AdapterConfig().inactive()
    inactive = AdapterConfig(repair=True).inactive()
    assert "robust_eta" in inactive and "repair_kernel" not in inactive


def test_adapter_with_repair_on_the_exact_model_finds_the_shift(exact_model, world_of):
    """The exact model (no training samples: trusted fully) with repair: the same answer as the
    map says, and repaired_model refuses (nothing to repair)."""
    cfg = AdapterConfig(repair=True, resolution=1.0, prior_halfwidth=15.0)
    ad = Adapter(exact_model, cfg, rng=np.random.default_rng(0))
    world = world_of(np.array([6.0, -4.0]))
    rng = np.random.default_rng(1)
    for _ in range(12):
        a = ad.suggest()
        felt, heard = world.touch(a[None], rng)
        ad.observe(a, heard[0], felt_position=felt[0])
    assert np.hypot(*(ad.estimate() - [6.0, -4.0])) < 1.0
    with pytest.raises(ConfigError, match="exact model"):
        ad.repaired_model()


def test_absorb_refits_with_the_touches_and_keeps_the_classes(weak_model):
    model, kb, world_of = weak_model
    truth = np.array([7.0, -5.0])
    world = world_of(truth)
    rng = np.random.default_rng(3)
    acts = rng.uniform((200, 250), (600, 450), size=(40, 2))
    felt, heard = world.touch(acts, rng)
    cls = model.classify(heard)
    new = absorb(model, felt, cls, truth)
    assert len(new.actions_) == len(model.actions_) + int((cls >= 0).sum())
    assert np.allclose(new.class_features_, model.class_features_, equal_nan=True)
    assert new is not model and len(model.actions_) == 150  # the input is left as it is
    # the touches sit where the truth says in the model's frame: the refit predicts them
    back = felt[cls >= 0] - truth
    assert np.mean(new.predict_class(back) == cls[cls >= 0]) >= \
        np.mean(model.predict_class(back) == cls[cls >= 0])


def test_absorbing_with_a_wrong_shift_is_bounded(weak_model, boundary_error_of):
    """A deliberately wrong estimate (3 px off): the model refitted with the touches mapped back
    by it ends at most 3 px worse in boundary error than it started (the stated bound: the
    touches' own mapping error)."""
    model, kb, world_of = weak_model
    truth = np.array([7.0, -5.0])
    world = world_of(truth)
    rng = np.random.default_rng(4)
    acts = rng.uniform((200, 250), (600, 450), size=(40, 2))
    felt, heard = world.touch(acts, rng)
    before = boundary_error_of(model, kb)
    wrong = absorb(model, felt, model.classify(heard), truth + [3.0, 0.0])
    assert boundary_error_of(wrong, kb) <= before + 3.0
