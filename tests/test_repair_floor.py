"""The samples floor of ``kbcli bench repair``: known answers on the default keyboard."""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.bench.repair_floor import STEP, model_floor, samples_floor
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model.base import ExactModel


@pytest.fixture(scope="module")
def kb():
    return Keyboard(KeyboardConfig())


def _samples(kb, n=3000, seed=0):
    x0, y0, x1, y1 = kb.area
    return np.random.default_rng(seed).uniform((x0, y0), (x1, y1), (n, 2))


@pytest.mark.parametrize("truth", [(0.0, 0.0), (7.0, -3.0), (-21.5, 12.25)])
def test_samples_labelled_by_the_keyboard_pin_the_truth(kb, truth):
    """Samples labelled with the keyboard's own keys disagree with it only off the true shift:
    the floor is within one search step of 0, wherever the keyboard moved."""
    pts = _samples(kb)
    assert samples_floor(pts, kb.key_at(pts), kb, np.array(truth)) <= STEP


@pytest.mark.parametrize("offset", [(2.0, -1.0), (-3.0, 0.0)])
def test_samples_labelled_off_by_an_offset_give_that_offset(kb, offset):
    """Samples whose keys were read ``offset`` px away are consistent only at that offset."""
    pts = _samples(kb)
    keys = kb.key_at(pts + np.array(offset))
    got = samples_floor(pts, keys, kb, np.array([5.0, 8.0]))
    assert got == pytest.approx(np.hypot(*offset), abs=STEP)


def test_model_floor_reads_the_models_classes(kb):
    """A model's class ``k + 1`` is key ``k`` and class 0 silence: a model whose samples carry
    the keyboard's own classes has a floor within one search step of 0."""
    pts = _samples(kb)
    model = ExactModel(kb)
    fake = type("M", (), {"class_features_": model.class_features_,
                          "labels_": model.predict_class(pts), "actions_": pts})()
    assert model_floor(fake, kb) <= STEP
