"""Configs of the simulator, the detector and the play / run / serve / perturb stages on the
pydantic ``Config`` base: bad values refused with one line naming the key and the accepted range,
round trips through ``to_dict`` / ``from_dict``, and the registries (sim modes, arm presets,
detectors) answering an unknown name with the valid ones."""

from __future__ import annotations

import pytest

from kbcli.core.config import Config, Count, Number, Whole, between
from kbcli.errors import ConfigError


# -- the Config base: nested errors and intervals ---------------------------------------------
class _Inner(Config):
    what = "detector"
    n_st: Count = 10


class _Outer(Config):
    what = "loop"
    detector: _Inner = _Inner()


def test_a_nested_config_error_names_the_key_once():
    with pytest.raises(ConfigError) as e:
        _Outer(detector={"n_st": 0})
    assert str(e.value) == "loop.detector.n_st must be greater than or equal to 1, got 0"
    with pytest.raises(ConfigError) as e:
        _Outer.from_dict({"detector": {"n_sd": 3}})
    assert str(e.value).startswith("unknown loop.detector option 'n_sd'; valid: n_st")
    with pytest.raises(ConfigError) as e:  # the inner config alone keeps its own name
        _Inner(n_st=0)
    assert str(e.value) == "detector.n_st must be greater than or equal to 1, got 0"


class _Bounded(Config):
    what = "play"
    steps: between(Whole, 1, 1000) = 3
    rate: between(Number, 0, 1, low_open=True, high_open=True) = 0.5


@pytest.mark.parametrize(("kw", "line"), [
    ({"steps": 10**9}, "play.steps must be a whole number in [1, 1000], got 1000000000"),
    ({"steps": 0}, "play.steps must be a whole number in [1, 1000], got 0"),
    ({"steps": 3.0}, "play.steps must be a whole number, got 3.0"),
    ({"rate": 1.0}, "play.rate must be a number in (0, 1), got 1.0"),
    ({"rate": 0}, "play.rate must be a number in (0, 1), got 0.0"),
])
def test_between_names_the_whole_interval(kw, line):
    with pytest.raises(ConfigError) as e:
        _Bounded(**kw)
    assert str(e.value) == line
