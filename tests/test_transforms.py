"""Transform families: inverse, composition with hypotheses, computeTransform (Algorithm 2)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from kbcli.core.instrument import transforms
from kbcli.errors import ConfigError

CENTRE = np.array([400.0, 350.0])
coords = st.floats(-500, 1000, allow_nan=False)
pts_strategy = arrays(float, (5, 2), elements=coords)


@settings(max_examples=80, deadline=None)
@given(pts=pts_strategy, angle=st.floats(-10, 10), dx=st.floats(-50, 50), dy=st.floats(-50, 50))
def test_inverse_undoes_apply(pts, angle, dx, dy):
    for family, params in (("translation", [dx, dy]), ("rigid", [angle, dx, dy])):
        back = transforms.inverse(family, params, transforms.apply(family, params, pts, CENTRE), CENTRE)
        np.testing.assert_allclose(back, pts, atol=1e-8)


@settings(max_examples=60, deadline=None)
@given(pts=pts_strategy, angle=st.floats(-10, 10), dx=st.floats(-50, 50), dy=st.floats(-50, 50))
def test_rigid_preserves_distances(pts, angle, dx, dy):
    moved = transforms.apply("rigid", [angle, dx, dy], pts, CENTRE)
    d0 = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    d1 = np.linalg.norm(moved[:, None] - moved[None], axis=-1)
    np.testing.assert_allclose(d0, d1, atol=1e-7)


@settings(max_examples=60, deadline=None)
@given(src=pts_strategy, angle=st.floats(-10, 10), dx=st.floats(-50, 50), dy=st.floats(-50, 50))
def test_translation_mapping_recovers_the_transform(src, angle, dx, dy):
    """computeTransform(a_i, a_t) with the true angle gives back the true translation."""
    target = transforms.apply("rigid", [angle, dx, dy], src, CENTRE)
    d = transforms.translation_mapping("rigid", angle, src, target, CENTRE)
    np.testing.assert_allclose(d, np.tile([dx, dy], (len(src), 1)), atol=1e-7)


def test_many_matches_one():
    params = np.array([[1.0, 2.0, 3.0], [-2.0, 0.5, -1.0]])
    pts = np.array([[10.0, 20.0], [400.0, 350.0]])
    many = transforms.apply_many("rigid", params, pts, CENTRE)
    for h in range(2):
        np.testing.assert_allclose(many[h], transforms.apply("rigid", params[h], pts, CENTRE))
    # rotation about the centre keeps the centre fixed up to the translation
    np.testing.assert_allclose(many[:, 1], CENTRE + params[:, 1:])


def test_bad_family_and_arity():
    with pytest.raises(ConfigError, match="valid: translation, rigid"):
        transforms.apply("affine", [1, 2], np.zeros((1, 2)), CENTRE)
    with pytest.raises(ConfigError, match="takes 3 parameters"):
        transforms.apply("rigid", [1, 2], np.zeros((1, 2)), CENTRE)
