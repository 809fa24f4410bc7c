"""The hypothesis grid, the model raster, the per-observation terms (likelihood, Eq. 7 KDE) and the
posterior of Eq. 8."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.grid import HypothesisGrid, grid_bytes
from kbcli.core.adaptation.posteriors.kde.density import binned_kde, kde_term
from kbcli.core.adaptation.posteriors.kde.samples import ActionSamples, scott_bandwidth
from kbcli.core.adaptation.posteriors.likelihood.term import cell_sigma, likelihood_term
from kbcli.core.adaptation.posteriors.posterior import Posterior, log_normalise
from kbcli.core.adaptation.setup import build_table
from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.core.model.table import LikelihoodTable
from kbcli.errors import ConfigError

KB = Keyboard(KeyboardConfig())
MODEL = ExactModel(KB)
TABLE = LikelihoodTable.from_model(MODEL, 0.5, eps=1e-3)


def grid(family="translation", half=10.0, res=0.5, max_angle=2.0, ares=0.5):
    return HypothesisGrid.build(family, prior_halfwidth=half, resolution=res, centre=KB.centre,
                                max_angle=max_angle, angle_resolution=ares)


# -- grid ----------------------------------------------------------------------------------------
def test_grid_shapes_and_default_size():
    g = HypothesisGrid.build("translation", prior_halfwidth=45, resolution=0.5, centre=KB.centre)
    assert g.shape == (181, 181) and g.size == 32761
    assert g.dx[90] == 0 and g.dx[0] == -45 and g.dx[-1] == 45
    r = HypothesisGrid.build("rigid", prior_halfwidth=45, resolution=0.5, centre=KB.centre,
                             max_angle=5, angle_resolution=0.5)
    assert r.shape == (21, 181, 181) and r.angles[0] == -5 and r.angles[10] == 0
    assert grid_bytes("rigid", 45, 0.5, 5, 0.5)[0] == r.size


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 40), st.integers(0, 40), st.integers(0, 8))
def test_grid_params_index_round_trip(i, j, k):
    g = grid("rigid")
    flat = np.ravel_multi_index((k, i, j), g.shape)
    p = g.params(np.array([flat]))[0]
    assert p[0] == g.angles[k] and p[1] == g.dx[j] and p[2] == g.dy[i]
    assert g.index_of(p) == flat


# -- the model raster ----------------------------------------------------------------------------
def test_exact_table_is_the_keyboard():
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = KB.area
    pts = rng.uniform((x0, y0), (x1, y1), size=(2000, 2))
    got = TABLE.classes_at(pts[:, 0], pts[:, 1])
    assert np.array_equal(got, MODEL.predict_class(pts))
    # outside the raster: silence
    assert TABLE.classes_at(np.array([0.0]), np.array([0.0]))[0] == 0


def test_boundary_points_find_every_key_corner():
    edges, corners = TABLE.boundary_points()
    c = KB.config
    # vertices where 3 or 4 sounds meet: all inner vertices of the key lattice and the outline's
    expected = (c.layout.rows + 1) * (c.layout.cols + 1) - 4
    assert len(corners) == expected
    assert np.allclose(np.mod(corners - np.asarray(c.origin), c.layout.key_size), 0)
    assert np.array_equal(TABLE.classes_at(edges[:, 0] + 0.3, edges[:, 1] + 0.3),
                          MODEL.predict_class(edges + 0.3))


def test_blurred_table_is_a_distribution():
    soft = LikelihoodTable.from_model(MODEL, 1.0, eps=1e-3, blur=2.0)
    assert not soft.hard
    s = soft.probs.sum(axis=-1)
    assert np.allclose(s, 1, atol=1e-4)
    # far from edges the blurred map is still (almost) one-hot, near an edge it mixes two keys
    cx, cy = KB.key_centres()[0]
    assert soft.probs[soft._index(np.array(cx), np.array(cy))[:2]].max() > 0.999
    p_edge = soft.prob_all(np.array([KB.config.origin[0] + 50.0]), np.array([cy]))[0]
    assert np.sort(p_edge)[-2] > 0.3


def test_log_prob_has_the_outlier_floor():
    eps, c = TABLE.eps, TABLE.n_classes
    x, y = KB.key_centres()[3]
    assert np.isclose(TABLE.log_prob(np.array(x), np.array(y), 4), math.log(1 - eps + eps / c))
    assert np.isclose(TABLE.log_prob(np.array(x), np.array(y), 5), math.log(eps / c))


# -- per-observation terms -----------------------------------------------------------------------
def test_likelihood_term_translation_known_answer():
    g = grid()
    a = np.array([262.0, 281.0])
    cls = int(MODEL.predict_class((a - np.array([4.0, -3.0]))[None])[0])
    term = likelihood_term(g, TABLE, a, cls)
    assert term.shape == g.shape
    dxg, dyg = np.meshgrid(g.dx, g.dy)
    pts = np.column_stack([a[0] - dxg.ravel(), a[1] - dyg.ravel()])
    expected = (MODEL.predict_class(pts) == cls).reshape(g.shape)
    assert np.array_equal(term > math.log(0.5), expected)


def test_likelihood_term_rigid_matches_transforms():
    g = grid("rigid")
    a = np.array([480.0, 420.0])
    truth = np.array([1.5, 3.0, -2.0])
    cls = int(MODEL.predict_class(transforms.inverse("rigid", truth, a[None], KB.centre))[0])
    term = likelihood_term(g, TABLE, a, cls)
    rng = np.random.default_rng(1)
    idx = rng.integers(g.size, size=300)
    pts = transforms.inverse_many("rigid", g.params(idx), a[None], KB.centre)[:, 0]
    expected = MODEL.predict_class(pts) == cls
    assert np.mean((term.reshape(-1)[idx] > math.log(0.5)) == expected) > 0.99


def test_cell_average_softens_rigid_edges():
    g = grid("rigid")
    fine = LikelihoodTable.from_model(MODEL, 0.25, eps=1e-3)
    a = np.array([560.0, 420.0])  # far from the centre: an angle step moves it ~1.5 px
    sig = cell_sigma(g, a)
    assert sig > 0.3
    term = likelihood_term(g, fine, a, 31, sig)
    p = np.exp(term)
    assert ((p > 0.05) & (p < 0.95)).any()  # soft cells along the edges
    assert np.isfinite(term).all()


def test_scott_bandwidth_of_a_key():
    rng = np.random.default_rng(2)
    s = rng.uniform(0, 50, size=(10000, 2))
    assert scott_bandwidth(s) == pytest.approx(50 / math.sqrt(12) * 10000 ** (-1 / 6), rel=0.05)


def _scott_by_numpy(s):
    """The bandwidth rule with numpy's own std and percentile (the reference of the fast one)."""
    std = s.std(axis=0)
    q75, q25 = np.percentile(s, [75, 25], axis=0)
    sig = np.minimum(std, (q75 - q25) / 1.349)
    return float(np.mean(np.where(sig > 0, sig, std)) * len(s) ** (-1 / 6))


@pytest.mark.parametrize("n", [10000, 9999, 1000, 101, 12, 11])
def test_scott_bandwidth_is_numpys_bit_for_bit(n):
    # keys (uniform: the IQR is not the smaller spread, the quartiles are skipped), normal,
    # heavy-tailed and two-cluster samples (the IQR decides), rounded (ties)
    rng = np.random.default_rng(n)
    for s in (rng.uniform(0, 50, (n, 2)), rng.normal(3, 7, (n, 2)), rng.standard_t(1, (n, 2)),
              np.where(rng.random((n, 1)) < 0.5, 0.0, 100.0) + rng.uniform(0, 9, (n, 2)),
              np.round(rng.uniform(0, 4, (n, 2)))):
        assert scott_bandwidth(s) == _scott_by_numpy(s)


def test_kde_term_peaks_where_the_likelihood_does():
    g = grid(half=30)
    a = np.array([262.0, 281.0])
    cls = int(MODEL.predict_class(a[None])[0])
    logk, bw = kde_term(g, MODEL, a, cls, np.random.default_rng(3), n_samples=5000, eps=1e-3)
    assert logk.shape == g.shape and np.isfinite(logk).all()
    assert g.resolution <= bw <= 4.0
    lik = likelihood_term(g, TABLE, a, cls) > math.log(0.5)
    # well inside the consistent region the KDE is high, far outside it is at the floor
    assert logk[lik].mean() > logk[~lik].mean() + 3


@pytest.mark.parametrize("bandwidth,res", [(1.0, 0.5), (2.5, 0.5), (1.5, 1.0)])
def test_fft_kde_matches_the_direct_sum(bandwidth, res):
    """The binned FFT KDE against the direct sum of Gaussians at every grid cell (Eq. 7)."""
    rng = np.random.default_rng(11)
    # a lumpy sample: two clusters and points scattered past the grid's edge
    pts = np.vstack([rng.normal((-3.0, 2.0), 1.5, size=(150, 2)),
                     rng.normal((4.0, -5.0), 0.7, size=(80, 2)),
                     rng.uniform(-14, 14, size=(70, 2))])
    n, x0 = 31 if res == 0.5 else 17, -7.5 if res == 0.5 else -8.0
    dens = binned_kde(pts, x0, x0 + 0.25, res, n, bandwidth)
    gx = x0 + res * np.arange(n)
    gy = x0 + 0.25 + res * np.arange(n)
    d2 = ((gx[None, :, None] - pts[None, None, :, 0]) ** 2
          + (gy[:, None, None] - pts[None, None, :, 1]) ** 2)
    direct = np.exp(-0.5 * d2 / bandwidth**2).sum(axis=-1) / (2 * math.pi * bandwidth**2 * len(pts))
    assert dens.shape == (n, n)
    # linear binning errs by O((res / bandwidth)^2) of the local density
    tol = 0.25 * (res / bandwidth) ** 2 * direct.max()
    assert np.max(np.abs(dens - direct)) < tol
    assert np.max(np.abs(dens - direct)) < 0.1 * direct.max()
    # a different sample does not match: the check can fail
    other = binned_kde(pts + 1.0, x0, x0 + 0.25, res, n, bandwidth)
    assert np.max(np.abs(other - direct)) > tol


def test_fft_kde_batches_are_independent():
    rng = np.random.default_rng(12)
    a, b = rng.normal(0, 2, size=(2, 100, 2))
    both = binned_kde(np.stack([a, b]), -5.0, -5.0, 0.5, 21, 1.0)
    assert np.allclose(both[0], binned_kde(a, -5.0, -5.0, 0.5, 21, 1.0))
    assert np.allclose(both[1], binned_kde(b, -5.0, -5.0, 0.5, 21, 1.0))


def test_action_samples_are_drawn_once_per_class_in_any_order():
    s1 = ActionSamples(MODEL, 500, 3)
    s2 = ActionSamples(MODEL, 500, 3)
    a5, bw5 = s1.get(5)
    s2.get(9)
    b5, _ = s2.get(5)
    assert np.array_equal(a5, b5)  # the order classes are heard in does not matter
    assert s1.get(5)[0] is a5 and len(s1) == 1  # cached, not redrawn
    # class 5 is key 4: every sample lies on that key
    assert (MODEL.predict_class(a5) == 5).all()
    assert 0.5 <= bw5 <= 4.0
    g = grid(half=20)
    act = np.array([262.0, 281.0])
    cls = int(MODEL.predict_class(act[None])[0])
    cached, _ = kde_term(g, MODEL, act, cls, n_samples=500, eps=1e-3, samples=s1)
    again, _ = kde_term(g, MODEL, act, cls, n_samples=500, eps=1e-3, samples=s1)
    assert np.array_equal(cached, again)


def test_kde_term_rigid_runs_every_angle():
    """Each angle slice is its own KDE; the angle-0 slice is the translation family's KDE of the
    same samples, and a turned slice differs from it."""
    g = grid("rigid", half=10)
    a = np.array([262.0, 281.0])
    samples = ActionSamples(MODEL, 2000, 4)
    logk, _ = kde_term(g, MODEL, a, 1, n_samples=2000, eps=1e-3, samples=samples)
    assert logk.shape == g.shape and np.isfinite(logk).all()
    flat, _ = kde_term(grid(half=10), MODEL, a, 1, n_samples=2000, eps=1e-3, samples=samples)
    zero = int(np.flatnonzero(g.angles == 0)[0])
    np.testing.assert_allclose(logk[zero], flat, atol=1e-9)
    assert np.max(np.abs(logk[0] - flat)) > 0.1


# -- the posterior -------------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(shape=st.tuples(st.integers(1, 5), st.integers(1, 5)), axis=st.sampled_from([None, 0, 1]),
       seed=st.integers(0, 2**32 - 1))
def test_log_normalise_sums_to_one_along_its_axis(shape, axis, seed):
    from scipy.special import logsumexp

    logw = np.random.default_rng(seed).normal(0.0, 30.0, size=shape)
    logp, p = log_normalise(logw, axis=axis)
    np.testing.assert_allclose(p.sum(axis=axis), 1.0, rtol=1e-12)
    np.testing.assert_allclose(logp, logw - logsumexp(logw, axis=axis, keepdims=True), atol=1e-9)
    np.testing.assert_allclose(np.exp(logp), p, rtol=1e-9)


def test_uniform_posterior():
    g = grid()
    p = Posterior.uniform(g)
    assert p.probs.sum() == pytest.approx(1)
    assert p.entropy() == pytest.approx(math.log(g.size))
    assert np.allclose(p.mean(), 0)
    frac = p.mass_within(np.zeros(2), 3.0)
    assert frac == pytest.approx(np.pi * 9 / (20.5**2), rel=0.1)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_update_is_normalised_and_immutable(seed):
    g = grid(half=5)
    rng = np.random.default_rng(seed)
    p0 = Posterior.uniform(g)
    term = rng.normal(0, 5, size=g.shape)
    p1 = p0.update(term)
    assert p0.entropy() == pytest.approx(math.log(g.size))  # unchanged
    assert p1.probs.sum() == pytest.approx(1) and p1.n_obs == 1
    assert np.allclose(p1.logp, term - np.log(np.exp(term).sum()))
    assert 0 <= p1.entropy() <= math.log(g.size) + 1e-9
    m = p1.mean()
    assert -5 <= m[0] <= 5 and -5 <= m[1] <= 5  # the estimate stays inside the prior box
    with pytest.raises(ValueError):
        p1.logp[0, 0] = 0.0


def test_product_of_observations_keeps_the_truth():
    g = grid(half=20)
    truth = np.array([6.3, -4.8])
    rng = np.random.default_rng(5)
    post = Posterior.uniform(g)
    for a in rng.uniform((200, 250), (600, 450), size=(40, 2)):
        cls = int(KB.key_at(a[None], truth)[0] + 1)
        post = post.update(likelihood_term(g, TABLE, a, cls))
    assert np.hypot(*(post.mean() - truth)) < 1.0
    assert post.mass_within(truth, 1.5) > 0.9
    # a contradicting observation lowers the truth but cannot zero it (the floor)
    a = KB.key_centres()[0] + truth
    bad = post.update(likelihood_term(g, TABLE, a, 20))
    assert np.isfinite(bad.logp).all()
    assert np.hypot(*(bad.mean() - truth)) < 1.0


def test_sample_hypotheses():
    g = grid(half=5)
    rng = np.random.default_rng(6)
    p = Posterior.uniform(g)
    idx, w = p.sample_hypotheses(50, rng)
    assert len(idx) <= 50 and w.sum() == pytest.approx(1) and len(np.unique(idx)) == len(idx)
    term = np.full(g.shape, -50.0)
    term[10, 10:13] = 0
    q = p.update(term)
    idx, w = q.sample_hypotheses(50, rng)
    assert sorted(idx) == [10 * 21 + 10, 10 * 21 + 11, 10 * 21 + 12]
    assert np.allclose(w, 1 / 3)


def test_memory_refusal_names_the_size():
    with pytest.raises(ConfigError, match=r"would need .* GB"):
        AdapterConfig(resolution=0.01)
    with pytest.raises(ConfigError, match="model raster"):
        build_table(MODEL, AdapterConfig(raster_step=0.001, max_memory_mb=100))
