"""The action-selection strategies (registry, each one exercised) and the Adapter loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.loop import adapt
from kbcli.core.adaptation.posteriors.posterior import Posterior
from kbcli.core.adaptation.setup import build_table
from kbcli.core.adaptation.strategies import (
    STRATEGIES,
    entropy_rows,
    outcome_distribution,
)
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.core.model.table import LikelihoodTable
from kbcli.core.options import for_part
from kbcli.errors import ConfigError
from kbcli.sim import SimConfig, World, make_reacher

KB = Keyboard(KeyboardConfig())
MODEL = ExactModel(KB)
CFG = AdapterConfig(prior_halfwidth=25.0)
TABLE = build_table(MODEL, CFG)
SOFT = LikelihoodTable.from_model(MODEL, 0.5, eps=1e-3, blur=1.5)


def make_touch(truth, family="translation", noise=0.0, seed=0):
    world = World(KB, make_reacher(SimConfig(reach_noise=noise)), np.asarray(truth, float), family)
    rng = np.random.default_rng(seed)

    def touch(a):
        landed, heard = world.touch(a[None], rng)
        return landed[0], heard[0]

    return touch


def test_registry_and_unknown_name():
    assert set(STRATEGIES) == {"random", "active", "paper-active", "infogain"}
    with pytest.raises(ConfigError, match="random, active, paper-active, infogain"):
        STRATEGIES.get("greedy")
    with pytest.raises(ConfigError, match="valid"):
        AdapterConfig(strategy="greedy")


@pytest.mark.parametrize("name", sorted(STRATEGIES))
@pytest.mark.parametrize("family", ["translation", "rigid"])
@pytest.mark.parametrize("soft", [False, True])
def test_every_strategy_proposes_an_action_in_the_area(name, family, soft):
    own = for_part(STRATEGIES, name, {"candidates": 64, "hypotheses": 64,
                                      "active_hypotheses": 256})  # those the strategy takes
    cfg = AdapterConfig(strategy=name, family=family, prior_halfwidth=10.0, max_angle=2.0,
                        angle_resolution=0.5, **own)
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(0), table=SOFT if soft else TABLE)
    touch = make_touch([3.0, -2.0] if family == "translation" else [1.0, 3.0, -2.0], family)
    x0, y0, x1, y1 = KB.area
    for _ in range(3):
        a = ad.propose()
        assert a.shape == (2,) and x0 <= a[0] <= x1 and y0 <= a[1] <= y1
        ad.observe(*touch(a))
    # same generator state, same decision
    a1 = Adapter(MODEL, cfg, rng=np.random.default_rng(7), table=TABLE).propose()
    a2 = Adapter(MODEL, cfg, rng=np.random.default_rng(7), table=TABLE).propose()
    assert np.array_equal(a1, a2)


def test_outcome_distribution_hard_equals_one_hot_soft():
    hard_table = LikelihoodTable.from_model(MODEL, 1.0, eps=1e-3)
    onehot = LikelihoodTable(hard_table.origin, 1.0, hard_table.n_classes, 1e-3,
                             probs=np.eye(hard_table.n_classes, dtype=np.float32)[
                                 hard_table.classes])
    rng = np.random.default_rng(1)
    hyp = rng.uniform(-20, 20, size=(30, 2))
    w = rng.dirichlet(np.ones(30))
    acts = rng.uniform((150, 200), (650, 500), size=(40, 2))
    p1, c1 = outcome_distribution(hard_table, "translation", hyp, w, acts, KB.centre)
    p2, c2 = outcome_distribution(onehot, "translation", hyp, w, acts, KB.centre)
    assert np.allclose(p1.sum(axis=1), 1) and np.allclose(p2.sum(axis=1), 1)
    assert np.allclose(p1, p2, atol=1e-6) and np.allclose(c1, c2, atol=1e-5)


def test_infogain_beats_random_candidates_on_the_prior():
    """On the flat prior, the chosen action's outcome entropy is near the best a touch can do."""
    cfg = AdapterConfig(prior_halfwidth=45.0)
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(2), table=TABLE)
    ctx = ad.context()
    idx, w = ctx.posterior.sample_hypotheses(2048, np.random.default_rng(3))
    hyp = ctx.posterior.grid.params(idx)
    a = STRATEGIES.get("infogain")(ctx, np.random.default_rng(4))
    rand = np.random.default_rng(5).uniform((150, 200), (650, 500), size=(200, 2))
    p, _ = outcome_distribution(TABLE, "translation", hyp, w, np.vstack([a, rand]), KB.centre)
    h = entropy_rows(p)
    assert h[0] >= np.quantile(h[1:], 0.95)
    assert h[0] > math.log(6)  # an early touch can tell ~9 keys apart


@pytest.mark.parametrize("name, budget", [("infogain", 10), ("active", 14)])
def test_model_based_strategies_pin_the_translation(name, budget):
    cfg = AdapterConfig(strategy=name, prior_halfwidth=25.0)
    truth = np.array([7.3, -12.6])
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(8), table=TABLE)
    steps = list(adapt(ad, make_touch(truth), budget))
    err = [np.hypot(*(s.estimate - truth)) for s in steps]
    assert err[-1] < 1.0
    assert steps[-1].entropy < steps[0].entropy


def test_random_strategy_learns_slowly_but_surely():
    cfg = AdapterConfig(strategy="random", prior_halfwidth=25.0)
    truth = np.array([-4.2, 9.9])
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(9), table=TABLE)
    steps = list(adapt(ad, make_touch(truth), 30))
    assert np.hypot(*(steps[-1].estimate - truth)) < 3.0
    assert steps[-1].entropy < steps[0].entropy


def test_rigid_adaptation_recovers_angle_and_translation():
    cfg = AdapterConfig(family="rigid", prior_halfwidth=15.0, max_angle=3.0)
    truth = np.array([1.7, -6.2, 4.4])
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(10))
    steps = list(adapt(ad, make_touch(truth, "rigid"), 16))
    est = steps[-1].estimate
    assert np.hypot(*(est[1:] - truth[1:])) < 1.0 and abs(est[0] - truth[0]) < 0.5


def test_aim_only_feedback_with_noise_uses_the_blurred_model():
    cfg = AdapterConfig(prior_halfwidth=25.0, blur=2.0, raster_step=1.0)
    truth = np.array([3.1, 5.2])
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(11))
    assert not ad.table.hard
    steps = list(adapt(ad, make_touch(truth, noise=2.0, seed=3), 20, use_landed=False))
    assert np.hypot(*(steps[-1].estimate - truth)) < 2.0


def test_adapter_api_unknown_sound_stop_rule_and_kde():
    cfg = AdapterConfig(prior_halfwidth=25.0, stop_mass=0.9)
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(12), table=TABLE)
    assert not ad.should_stop()
    before = ad.entropy()
    assert ad.observe(np.array([300.0, 300.0]), np.array([1000.0, 1000.0])) == -1  # unknown
    assert ad.entropy() == before and ad.posterior.n_obs == 0
    # silence left of the keyboard: rules out the hypotheses that put a key there
    assert ad.observe(np.array([190.0, 300.0]), np.array([np.nan, np.nan])) == 0
    assert ad.entropy() < before
    truth = np.array([2.0, 3.0])
    steps = list(adapt(ad, make_touch(truth), 40, stop=True))
    assert steps[-1].stop and len(steps) < 40
    assert ad.should_stop() and ad.mass_near_estimate() >= 0.9
    e = ad.estimates()
    assert e.ml.shape == (2,) and e.mean.shape == (2,) and 0 < e.ml_prob <= 1
    kde = Adapter(MODEL, AdapterConfig(posterior="kde", prior_halfwidth=25.0, kde_samples=2000),
                  rng=np.random.default_rng(13), table=TABLE)
    steps = list(adapt(kde, make_touch(truth), 8))
    assert np.hypot(*(steps[-1].estimate - truth)) < 3.0 and len(kde.bandwidths) == 8


def test_paper_stopping_rule():
    cfg = AdapterConfig(prior_halfwidth=5.0, stop_ml=0.5, stop_mass=1.0)
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(14), table=TABLE)
    term = np.full(ad.grid.shape, -30.0)
    term[3, 4] = 0
    ad.posterior = Posterior.update(ad.posterior, term)
    assert ad.should_stop()


class _SoftWrapper:
    """A non-exact model (same geometry): gets the learned-model defaults."""

    def __init__(self, m):
        self._m = m
        self.class_features_ = m.class_features_
        self.match_threshold = m.match_threshold
        self.area = m.area

    def raster(self, step=1.0):
        return self._m.raster(step)

    def classify(self, perceived):
        return self._m.classify(perceived)

    def sample_actions(self, cls, n, rng):
        return self._m.sample_actions(cls, n, rng)


def test_the_plain_posterior_softens_learned_models_and_the_robust_one_learns_the_blur():
    from kbcli.core.adaptation.config import LEARNED_BLUR
    from kbcli.core.adaptation.posteriors.likelihood.robust import DEFAULT_BLURS
    from kbcli.core.adaptation.setup import total_blur

    soft = _SoftWrapper(MODEL)
    plain = AdapterConfig(prior_halfwidth=10.0, raster_step=1.0, robust=False)
    assert total_blur(MODEL, plain) == 0.0 and total_blur(soft, plain) == LEARNED_BLUR
    assert total_blur(soft, AdapterConfig(model_blur=0.0, blur=2.0, robust=False)) == 2.0
    # the robust posterior blurs per touch, by the blurs it weighs: the raster keeps only the
    # aim-only feedback's blur, and model_blur, when given, fixes the blur it weighs
    robust = AdapterConfig(prior_halfwidth=10.0, raster_step=1.0, blur=1.5)
    assert total_blur(soft, robust) == 1.5
    assert robust.posterior.robust_blurs is None  # resolved with the model (robust_blurs())
    assert list(robust.nuisance().blurs) == sorted(DEFAULT_BLURS)
    assert list(AdapterConfig(robust_blurs=(2.0, 0.0)).nuisance().blurs) == [0.0, 2.0]
    assert list(AdapterConfig(model_blur=3.0).nuisance().blurs) == [3.0]
    cfg = plain
    with pytest.raises(ConfigError, match="model_blur"):
        AdapterConfig(model_blur=-1.0)
    for bad in ({"model_blur": 50.5}, {"blur": 1e9}, {"robust_blurs": (0.0, 1e3)}):
        with pytest.raises(ConfigError, match="<= 50"):
            AdapterConfig(**bad)
    assert AdapterConfig(model_blur=50.0).model_blur == 50.0
    ad = Adapter(soft, cfg, rng=np.random.default_rng(15))
    assert not ad.table.hard
    truth = np.array([-3.3, 2.2])
    steps = list(adapt(ad, make_touch(truth), 12))
    assert np.hypot(*(steps[-1].estimate - truth)) < 1.5


# -- the active strategy's selection rule on a hand-made case ------------------------------------
def _four_hypotheses():
    """A posterior on four cells: h1 (0, 0) 0.3 (the maximum-likelihood one), h2 (6, 0) 0.25,
    h3 (6, 6) 0.25, h4 (0, 6) 0.2; every other cell ~1e-22."""
    cfg = AdapterConfig(strategy="active", prior_halfwidth=10.0, active_keep=2)
    ad = Adapter(MODEL, cfg, rng=np.random.default_rng(0), table=TABLE)
    g = ad.grid
    hyp = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 6.0], [0.0, 6.0]])
    w = np.array([0.3, 0.25, 0.25, 0.2])
    logp = np.full(g.shape, -50.0)
    for h, p in zip(hyp, w, strict=True):
        logp.reshape(-1)[g.index_of(h)] = math.log(p)
    ad.posterior = Posterior(g, logp)
    return ad, hyp, w


def _find(hyp, pattern):
    """An action whose outcome classes under the four hypotheses follow ``pattern`` (equal
    letters: the same class), searched on a grid of the working area."""
    xs, ys = np.meshgrid(np.arange(160.0, 640.0, 1.0), np.arange(210.0, 490.0, 1.0))
    acts = np.column_stack([xs.ravel(), ys.ravel()])
    cls = np.stack([MODEL.predict_class(acts - h) for h in hyp], axis=1)  # (n, 4)
    ok = np.ones(len(acts), bool)
    for i in range(4):
        for j in range(4):
            same = cls[:, i] == cls[:, j]
            ok &= same if pattern[i] == pattern[j] else ~same
    assert ok.any(), pattern
    return acts[np.flatnonzero(ok)[0]]


def test_active_keeps_the_most_confusing_then_simulates_the_best_hypothesis(monkeypatch):
    """S1 = {h1 | h2 h3 h4} confuses less (H(0.3) = 0.61 nats) than S2 = {h1 h4 | h2 h3}
    (H(0.5) = 0.69) but, simulated under the best hypothesis h1, settles the posterior on h1
    (entropy ~0) where S2 leaves h1 and h4 (0.67 nats). W tells nothing. Active keeps the
    ``active_keep`` most confusing candidates, then picks the lowest simulated entropy."""
    from kbcli.core.adaptation.strategies import active, infogain

    ad, hyp, w = _four_hypotheses()
    s1, s2, wasted = _find(hyp, "abbb"), _find(hyp, "aabb"), _find(hyp, "aaaa")
    fixed = np.array([s2, wasted, s1])
    monkeypatch.setattr(active, "uniform_actions", lambda area, n, rng: fixed.copy())
    pred, _ = outcome_distribution(TABLE, "translation", hyp, w, fixed, KB.centre)
    conf = entropy_rows(pred)
    assert conf[0] > conf[2] > conf[1]  # S2 most confusing, then S1, W nothing
    assert np.array_equal(ad.propose(), s1)  # keep 2 (S2, S1): S1 settles the posterior
    ad.cfg = AdapterConfig(strategy="active", prior_halfwidth=10.0, active_keep=1)
    assert np.array_equal(ad.propose(), s2)  # keep 1: only the most confusing is left
    ad.cfg = AdapterConfig(strategy="active", prior_halfwidth=10.0, active_keep=3)
    assert np.array_equal(ad.propose(), s1)
    # infogain, on the same posterior, values S2's even split above S1
    monkeypatch.setattr(infogain, "uniform_actions", lambda area, n, rng: fixed.copy())
    monkeypatch.setattr(infogain, "boundary_candidates",
                        lambda ctx, ne, nc, hyp, w, rng: np.empty((0, 2)))
    ad.cfg = AdapterConfig(strategy="infogain", prior_halfwidth=10.0)
    ad._strategy = STRATEGIES.get("infogain")
    assert np.array_equal(ad.propose(), s2)


def test_strategies_rank_on_a_fixed_set_of_displacements():
    """Six fixed displacements (none a multiple of the 0.5 px grid or of the 50 px keys), 12
    touches each: the model-based strategies pin every one below 1 px; random, on the same
    displacements and seeds, does worse on average."""
    truths = np.array([[7.3, -12.6], [-3.71, 4.13], [15.2, 9.9], [-21.35, -6.07], [0.83, 18.4],
                       [-9.6, -16.9]])
    final = {}
    for name in ("random", "active", "infogain"):
        cfg = AdapterConfig(strategy=name, prior_halfwidth=25.0)
        errs = []
        for i, truth in enumerate(truths):
            ad = Adapter(MODEL, cfg, rng=np.random.default_rng(100 + i), table=TABLE)
            steps = list(adapt(ad, make_touch(truth, seed=i), 12))
            errs.append(np.hypot(*(steps[-1].estimate - truth)))
        final[name] = np.array(errs)
    assert np.all(final["infogain"] < 1.0) and np.all(final["active"] < 1.0)
    assert final["random"].mean() > 2 * max(final["active"].mean(), final["infogain"].mean())


def test_information_gain_is_the_mutual_information_not_the_predictive_entropy():
    """A known answer on a two-cell soft table: cell 0 sounds a or b (1/2 each), cell 1 sounds a.

    Two hypotheses (weight 1/2 each): at action (0, 0) one reads cell 0, the other cell 1, so the
    predictive is (3/4, 1/4) and I = H(3/4, 1/4) - (1/2 log 2 + 1/2 * 0) = 0.2158 nats, where the
    predictive entropy alone is 0.5623. When both hypotheses read cell 0's coin flip the predictive
    entropy is log 2 but nothing is learnt (I = 0): an infogain that ranked actions by predictive
    entropy would seek the coin flip.
    """
    from kbcli.core.adaptation.strategies import information_gain

    probs = np.array([[[0.0, 0.5, 0.5], [0.0, 1.0, 0.0]]], np.float32)  # (H=1, W=2, C=3)
    table = LikelihoodTable(np.zeros(2), 1.0, 3, 1e-9, probs=probs)
    hyp = np.array([[0.0, 0.0], [-1.0, 0.0]])
    w = np.array([0.5, 0.5])
    actions = np.array([[0.0, 0.0], [-1.0, 0.0], [1.0, 0.0]])
    # action 1 (-1, 0): h1 reads (-1, 0), outside -> silence; h2 reads cell 0: 1 bit of doubt
    gain = information_gain(table, "translation", hyp, w, actions, np.zeros(2))
    h = -(0.75 * np.log(0.75) + 0.25 * np.log(0.25))
    assert gain[0] == pytest.approx(h - 0.5 * np.log(2), abs=1e-6)  # 0.2158
    # (-1, 0): silence or a coin flip -> I = H(1/2, 1/4, 1/4) - 1/2 log 2 = log 2
    assert gain[1] == pytest.approx(np.log(2), abs=1e-6)
    # (1, 0): cell 1 (a) or outside (silence): fully decisive, I = log 2
    assert gain[2] == pytest.approx(np.log(2), abs=1e-6)
    same = information_gain(table, "translation", hyp[:1].repeat(2, 0), w, actions[:1],
                            np.zeros(2))
    assert same[0] == pytest.approx(0.0, abs=1e-6)  # one hypothesis: a coin flip teaches nothing
    pred, _ = outcome_distribution(table, "translation", hyp[:1].repeat(2, 0), w, actions[:1],
                                   np.zeros(2))
    assert entropy_rows(pred)[0] == pytest.approx(np.log(2), abs=1e-6)  # yet its entropy is max
