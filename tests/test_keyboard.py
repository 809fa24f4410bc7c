"""The instrument: geometry, sounds, perception and matching (Sect. III-A, Eq. 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import (
    Keyboard,
    KeyboardConfig,
    match,
    midi_to_name,
    name_to_midi,
)
from kbcli.errors import ConfigError

KB = Keyboard(KeyboardConfig())


def test_default_layout_known_answers():
    assert KB.n_keys == 32
    assert KB.bounds == (200.0, 250.0, 600.0, 450.0)
    assert KB.area == (150.0, 200.0, 650.0, 500.0)
    # key 0 is bottom-left, key 8 is the first of the second row, key 31 top-right
    pts = np.array([[201, 251], [599, 251], [201, 301], [599, 449], [199, 300], [400, 451]])
    assert KB.key_at(pts).tolist() == [0, 7, 8, 31, -1, -1]
    assert KB.names[0] == "C3" and KB.names[7] == "C4" and KB.names[12] == "A4"
    assert KB.features[0].tolist() == [48.0, 60.0]
    # key 9 = row 1, column 1: the 10th note of C major from C3 (E4 = 64), 60 + 4 + 30 bpm
    assert KB.features[9].tolist() == [64.0, 94.0]


def test_every_key_sound_is_distinct_beyond_threshold():
    f = KB.features
    d = np.abs(f[:, None] - f[None]).sum(-1) + np.eye(len(f)) * 1e9
    assert d.min() > KB.config.match_threshold


def test_note_names_round_trip():
    for midi in range(12, 128):
        assert name_to_midi(midi_to_name(midi)) == midi
    assert name_to_midi("A") == 69
    assert name_to_midi("Bb3") == name_to_midi("A#3")
    with pytest.raises(ConfigError, match="unknown note"):
        name_to_midi("H2")
    assert KB.note_key("A") == 12
    with pytest.raises(ConfigError, match="not on the keyboard"):
        KB.note_key("C1")


def test_key_centres_map_to_their_key():
    assert KB.key_at(KB.key_centres()).tolist() == list(range(32))


def test_perceive_silence_is_nan_and_noise_is_seeded():
    rng = np.random.default_rng(0)
    s = KB.perceive(np.array([[0.0, 0.0], [225.0, 275.0]]), rng=rng)
    assert np.isnan(s[0]).all() and s[1].tolist() == [48.0, 60.0]
    noisy = Keyboard(KeyboardConfig(noise_std=0.3))
    pts = KB.key_centres()
    a = noisy.perceive(pts, rng=np.random.default_rng(5))
    b = noisy.perceive(pts, rng=np.random.default_rng(5))
    assert np.array_equal(a, b) and not np.array_equal(a, KB.features)


def test_match_eq2_manhattan_threshold():
    known = KB.features
    perceived = np.vstack([known[3] + [0.5, 0.5], known[3] + [1.0, 1.0], [np.nan, np.nan]])
    assert match(perceived, known, 1.5).tolist() == [3, -1, -1]


@settings(max_examples=60, deadline=None)
@given(
    dx=st.floats(-40, 40), dy=st.floats(-40, 40), angle=st.floats(-5, 5),
    px=st.floats(150, 650), py=st.floats(200, 500),
)
def test_displaced_keyboard_plays_reference_sound_at_moved_point(dx, dy, angle, px, py):
    """Eq. 3: the key under x at the reference pose is under T(x) after the move."""
    p = np.array([[px, py]])
    for family, params in (("translation", [dx, dy]), ("rigid", [angle, dx, dy])):
        moved = transforms.apply(family, np.array(params), p, KB.centre)
        assert KB.key_at(moved, np.array(params), family)[0] == KB.key_at(p)[0] or _near_edge(p)


def _near_edge(p):
    u = (p[0] - np.array(KB.config.origin)) / KB.config.layout.key_size
    return np.min(np.abs(u - np.round(u))) < 1e-6


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"rows": 0}, "rows"),
        ({"cols": -2}, "cols"),
        ({"key_size": 0.0}, "key_size"),
        ({"key_size": -5.0}, "key_size"),
        ({"key_size": math.nan}, "key_size"),
        ({"margin": math.inf}, "margin"),
        ({"scale": "lydian"}, "scale"),
        ({"base_note": "X9"}, "note"),
        ({"match_threshold": 0.0}, "match_threshold"),
        ({"origin": (math.nan, 0.0)}, "origin"),
        ({"base_note": "C8"}, "127"),
    ],
)
def test_invalid_config_rejected_with_named_option(kwargs, fragment):
    with pytest.raises(ConfigError, match=fragment):
        KeyboardConfig(**kwargs)


def test_from_dict_rejects_unknown_keys():
    with pytest.raises(ConfigError, match="unknown keyboard option"):
        KeyboardConfig.from_dict({"rows": 4, "colz": 8})
    assert KeyboardConfig.from_dict(KeyboardConfig().to_dict()) == KeyboardConfig()
