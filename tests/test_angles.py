"""Angles a user gives are wrapped to (-180, 180] or refused outside a stated range."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from kbcli.cli import app
from kbcli.core.instrument.transforms import wrap_degrees
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact


@given(st.floats(-1e6, 1e6, allow_nan=False))
def test_wrap_degrees_is_the_same_rotation_in_range(a):
    w = wrap_degrees(a)
    assert -180.0 < w <= 180.0
    assert np.isclose(np.cos(np.deg2rad(w)), np.cos(np.deg2rad(a)), atol=1e-6)
    assert np.isclose(np.sin(np.deg2rad(w)), np.sin(np.deg2rad(a)), atol=1e-6)


def test_wrap_degrees_known_answers():
    assert wrap_degrees(190.0) == -170.0
    assert wrap_degrees(-180.0) == 180.0 and wrap_degrees(180.0) == 180.0
    assert wrap_degrees(370.0) == pytest.approx(10.0)
    np.testing.assert_allclose(wrap_degrees(np.array([0.0, 360.0, -190.0])), [0.0, 0.0, 170.0])


def test_angle_error_is_the_short_way_round():
    from kbcli.stages.adapt import estimate_errors

    _, err = estimate_errors(np.array([179.0, 0, 0]), np.array([-179.0, 0, 0]), "rigid", "rigid")
    assert err == pytest.approx(2.0)


def test_perturb_wraps_the_angle(runner, kb_path, tmp_path):
    out = tmp_path / "s.h5"
    r = runner.invoke(app, ["perturb", "--keyboard", str(kb_path), "--angle", "362", "--dx", "1",
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "wrapped" in r.stderr
    assert read_artifact(out).config["params"][0] == pytest.approx(2.0)


def test_max_angle_outside_its_range_is_refused():
    from kbcli.core.adaptation.config import AdapterConfig

    with pytest.raises(ConfigError, match=r"\[0, 180\]"):
        AdapterConfig(family="rigid", max_angle=200.0)
