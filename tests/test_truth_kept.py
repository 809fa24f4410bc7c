"""The truth is never ruled out by an artefact (issue 39): silence beyond the working area, the
truth's place in the posterior, and the stopping rules read after the fact."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.grid import HypothesisGrid
from kbcli.core.adaptation.posteriors.kde.samples import SilentBeyond, beyond_margin
from kbcli.core.adaptation.posteriors.posterior import Posterior
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.core.model.sampling import RasterSampler
from kbcli.core.model.sounds import SILENCE
from kbcli.core.model.table import LikelihoodTable
from kbcli.stages.report import runs


def two_key_table() -> LikelihoodTable:
    """A 1 x 5 raster of 1 px cells centred on x = 0..4: silence | key 1 | 50/50 | 70/30 | key 2."""
    probs = np.array([[[1, 0, 0], [0, 1, 0], [0, 0.5, 0.5], [0, 0.7, 0.3], [0, 0, 1]]],
                     np.float32)
    return LikelihoodTable(np.zeros(2), 1.0, 3, 1e-3, probs=probs)


def test_silent_beyond_splits_silence_by_its_masses():
    t = two_key_table()
    s = SilentBeyond(RasterSampler(t), t, margin=2.0)
    # the raster spans [-0.5, 4.5] x [-0.5, 0.5]; the ring of 2 px around it: 9 x 5 - 5 x 1 = 40
    # px^2 against silence's 1 px^2 inside (one silent cell)
    assert s.beyond == pytest.approx(40 / 41)
    x = s.sample_actions(SILENCE, 41000, np.random.default_rng(0))
    inside = (np.abs(x[:, 1]) <= 0.5) & (x[:, 0] >= -0.5) & (x[:, 0] <= 4.5)
    assert inside.mean() == pytest.approx(1 / 41, abs=0.003)
    assert (np.abs(x[inside, 0]) <= 0.5).all()  # inside, silence is the silent cell only
    assert (x[:, 0] >= -2.5).all() and (x[:, 0] <= 6.5).all() and (np.abs(x[:, 1]) <= 2.5).all()
    # uniform on the ring: the strip beyond the right edge holds 2 x 1 / 40 of it
    right = (x[:, 0] > 4.5) & (np.abs(x[:, 1]) <= 0.5)
    assert right.sum() / (~inside).sum() == pytest.approx(2 / 40, abs=0.005)
    # other sounds are drawn as before, bit for bit
    a = s.sample_actions(1, 500, np.random.default_rng(3))
    b = RasterSampler(t).sample_actions(1, 500, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert SilentBeyond(RasterSampler(t), t, 0.0).beyond == 0


def test_beyond_margin_covers_every_hypothesis():
    grid = HypothesisGrid.build("translation", prior_halfwidth=15.0, resolution=0.5,
                                centre=np.array([50.0, 25.0]))
    assert beyond_margin(grid, (0.0, 0.0, 100.0, 50.0), 4.0) == pytest.approx(19.0)
    rigid = HypothesisGrid.build("rigid", prior_halfwidth=15.0, resolution=0.5,
                                 centre=np.array([50.0, 25.0]), max_angle=5.0)
    r = math.hypot(50, 25)
    assert beyond_margin(rigid, (0.0, 0.0, 100.0, 50.0), 4.0) == pytest.approx(
        19.0 + 2 * r * math.sin(math.radians(5.0) / 2))


def test_log_ratio_at_reads_the_cells_around_a_point():
    grid = HypothesisGrid.build("translation", prior_halfwidth=2.0, resolution=1.0,
                                centre=np.zeros(2))
    logp = np.full(grid.shape, -50.0)
    logp[2, 3] = 0.0  # dy = 0, dx = 1
    post = Posterior(grid, logp)
    assert post.log_ratio_at(np.array([1.0, 0.0])) == pytest.approx(0.0)
    assert post.log_ratio_at(np.array([0.6, 0.4])) == pytest.approx(0.0)  # a bracketing cell
    assert post.log_ratio_at(np.array([-1.5, 0.0])) == pytest.approx(-50.0)
    assert post.log_ratio_at(np.array([-9.0, 9.0])) == pytest.approx(-50.0)  # clipped to the box


@pytest.mark.parametrize("beyond", ["silent", "unknown"])
def test_a_silent_touch_beyond_the_area_keeps_the_truth(beyond):
    """The paper's KDE without a floor: a silent touch 2 px inside the working area's right edge,
    the keyboard moved 10 px left. Moved back by the truth the touch lies 8 px beyond the area,
    where the pad is silent; with samples that stop at the area's edge (``unknown``, a kernel of
    1 px: its reach is 4 px) the truth is ruled out; with ``silent`` it stays within the Monte-Carlo
    noise of 4000 samples spread over the silent pad (a few nats below the luckiest cell)."""
    kb = Keyboard(KeyboardConfig())
    model = ExactModel(kb)
    cfg = AdapterConfig(posterior="kde", estimator="ml", model_blur=0.0, kde_draw="fresh",
                        kde_sampler="raster", kde_floor=0.0, prior_halfwidth=15.0,
                        kde_samples=4000, kde_bandwidth=1.0, kde_beyond=beyond,
                        strategy="random")
    ad = Adapter(model, cfg, rng=np.random.default_rng(0))
    x0, y0, x1, y1 = ad.area
    touch = np.array([x1 - 2.0, (y0 + y1) / 2])
    assert model.predict_class(touch[None])[0] == SILENCE
    ad.observe_class(touch, SILENCE)
    truth = np.array([-10.0, 0.0])
    ratio = ad.posterior.log_ratio_at(truth)
    if beyond == "silent":
        assert ratio > math.log(runs.EXCLUDED) + 10
    else:
        assert ratio < math.log(runs.EXCLUDED)


def test_stop_steps_first_step_reaching_the_threshold():
    v = np.array([[0.01, 0.03, 0.01], [0.0, 0.0, 0.0], [np.nan, 0.5, 0.6]])
    np.testing.assert_array_equal(runs.stop_steps(v, 0.02), [2, 0, 2])
    np.testing.assert_array_equal(runs.stop_steps(v, 0.55), [0, 0, 3])
