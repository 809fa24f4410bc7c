"""Layouts beyond the grid (issue 11): the key geometry, each layout, and bad keyboards refused."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import one_line_error as _one_line_error
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.cli import app
from kbcli.core.instrument import transforms
from kbcli.core.instrument.geometry import (
    KeyShapes,
    check_overlaps,
    check_polygon,
    points_in_polygon,
    polygon_area,
)
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig, PolygonKey
from kbcli.core.instrument.layouts import LAYOUTS, example_config_fields, example_polygon_keys
from kbcli.core.model.base import ExactModel
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.io.config import load_toml
from kbcli.sim import SimConfig, check_keyboard_reachable
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import perturb

LAYOUT_NAMES = tuple(LAYOUTS)
BOARDS = {name: Keyboard(KeyboardConfig(layout=name, **example_config_fields(name)))
          for name in LAYOUT_NAMES}


# -- the geometry ---------------------------------------------------------------------------------
def test_point_in_polygon_known_answers_and_half_open_edges():
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    pts = np.array([[5, 5], [0, 5], [10, 5], [5, 0], [5, 10], [-1, 5], [11, 5]], float)
    # left and bottom edges belong to the square, right and top edges to its neighbours
    assert points_in_polygon(pts, square).tolist() == [True, True, False, True, False, False,
                                                       False]
    ell = np.array([[0, 0], [20, 0], [20, 10], [10, 10], [10, 20], [0, 20]], float)  # non-convex
    assert points_in_polygon(np.array([[5, 15], [15, 15], [15, 5]], float), ell).tolist() == [
        True, False, True]
    assert polygon_area(ell) == 300.0


@settings(max_examples=40, deadline=None)
@given(n=st.integers(3, 9), seed=st.integers(0, 10_000))
def test_disc_and_polygon_keys_agree_with_their_definition(n, seed):
    """A regular n-gon key and a disc key: key_at is the point-in-shape test, and samples drawn
    in a key are in it."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.uniform(0, 1)
    poly = 30 * np.column_stack([np.cos(a), np.sin(a)]) + 100
    shapes = KeyShapes(polygons=[poly])
    q = rng.uniform(60, 140, size=(500, 2))
    np.testing.assert_array_equal(shapes.key_at(q) == 0, points_in_polygon(q, poly))
    assert (shapes.key_at(shapes.sample(0, 50, rng)) == 0).all()
    discs = KeyShapes(discs=np.array([[100.0, 100.0, 20.0], [150.0, 100.0, 10.0]]))
    d0 = np.hypot(q[:, 0] - 100, q[:, 1] - 100) <= 20
    d1 = np.hypot(q[:, 0] - 150, q[:, 1] - 100) <= 10
    np.testing.assert_array_equal(discs.key_at(q), np.where(d0, 0, np.where(d1, 1, -1)))


@pytest.mark.parametrize(
    "vertices, fragment",
    [
        ([[0, 0], [10, 0]], "fewer than 3"),
        ([[0, 0], [10, 0], [20, 0]], "area"),
        ([[0, 0], [10, 0], [0, 0], [10, 0]], "fewer than 3"),
        ([[0, 0], [10, 10], [10, 0], [0, 10]], "cross"),  # a bow tie
        ([[0, 0], [10, float("nan")], [0, 10]], "finite"),
        ([[0, 0, 1], [1, 0, 1], [0, 1, 1]], "pairs"),
    ],
)
def test_degenerate_polygons_are_refused(vertices, fragment):
    with pytest.raises(ConfigError, match=fragment):
        check_polygon(vertices, "key 3")


def test_check_polygon_cleans_and_orients():
    v = check_polygon([[0, 0], [0, 10], [0, 10], [10, 10], [10, 0], [0, 0]], "k")
    assert len(v) == 4 and polygon_area(v) == 100.0  # repeated and closing vertices dropped, CCW


def test_overlaps_are_found_but_shared_edges_are_not():
    a = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    names = ("A", "B")
    check_overlaps(KeyShapes(polygons=[a, a + (10, 0)]), names)  # side by side
    check_overlaps(KeyShapes(polygons=[a, a + (10, 10)]), names)  # corner to corner
    for other in (a + (5, 0), a + (3, 3), a.copy(), a * 0.5 + 2):  # shifted, crossing, equal, inside
        with pytest.raises(ConfigError, match="keys 0 .A. and 1 .B. overlap"):
            check_overlaps(KeyShapes(polygons=[a, other]), names)
    with pytest.raises(ConfigError, match="overlap"):
        check_overlaps(KeyShapes(discs=np.array([[0, 0, 10], [15, 0, 10]], float)), names)


# -- every layout ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", LAYOUT_NAMES)
def test_every_layout_is_consistent(name):
    kb = BOARDS[name]
    k = kb.n_keys
    assert k >= 16 and kb.features.shape == (k, 2) and len(kb.names) == k
    # each key's centre is in it, and every key's samples and grid points are in it
    np.testing.assert_array_equal(kb.key_at(kb.key_centres()), np.arange(k))
    rng = np.random.default_rng(0)
    for key in (0, k // 2, k - 1):
        assert (kb.key_at(kb.sample_in_key(key, 40, rng)) == key).all()
    pts, keys = kb.key_grid_points(8)
    np.testing.assert_array_equal(kb.key_at(pts), keys)
    assert set(keys.tolist()) == set(range(k))
    # keys sound distinct beyond the matching threshold (Eq. 2)
    d = np.abs(kb.features[:, None] - kb.features[None]).sum(-1) + np.eye(k) * 1e9
    assert d.min() > kb.config.match_threshold
    # the keys are inside the bounds, the working area is the bounds plus the margin
    x0, y0, x1, y1 = kb.bounds
    for p in kb.key_outlines():
        assert (p >= (x0 - 1e-9, y0 - 1e-9)).all() and (p <= (x1 + 1e-9, y1 + 1e-9)).all()
    m = kb.config.margin
    assert kb.area == (x0 - m, y0 - m, x1 + m, y1 + m)
    check_keyboard_reachable(SimConfig(), kb)
    # the exact model's draws are in their key; silence's are outside every key
    exact = ExactModel(kb)
    assert (kb.key_at(exact.sample_actions(1, 50, rng)) == 0).all()
    assert (kb.key_at(exact.sample_actions(0, 50, rng)) == -1).all()
    # the config round-trips
    assert KeyboardConfig.from_dict(kb.config.to_dict()) == kb.config


@pytest.mark.parametrize("name", LAYOUT_NAMES)
@settings(max_examples=15, deadline=None)
@given(dx=st.floats(-40, 40), dy=st.floats(-40, 40), angle=st.floats(-5, 5),
       u=st.floats(0, 1), v=st.floats(0, 1))
def test_a_displaced_layout_plays_the_reference_sound_at_the_moved_point(name, dx, dy, angle, u,
                                                                         v):
    """Eq. 3 on every layout: the key under x at the reference pose is under T(x) after the move,
    and aiming inside every key corrected by a perfect estimate plays that key."""
    kb = BOARDS[name]
    x0, y0, x1, y1 = kb.area
    p = np.array([[x0 + u * (x1 - x0), y0 + v * (y1 - y0)]])
    params = np.array([angle, dx, dy])
    moved = transforms.apply("rigid", params, p, kb.centre)
    back = transforms.inverse("rigid", params, moved, kb.centre)
    assert kb.key_at(moved, params, "rigid")[0] == kb.key_at(back)[0]
    pts, keys = kb.key_grid_points(4)
    aim = transforms.apply("rigid", params, pts, kb.centre)
    assert np.mean(kb.key_at(aim, params, "rigid") == keys) > 0.99  # on an edge: round-off


def test_layout_known_answers():
    hexa, piano, pads = BOARDS["hex"], BOARDS["piano"], BOARDS["pads"]
    # Wicki-Hayden: right a whole tone, up-right a fifth, up-left a fourth
    c = hexa.config
    assert hexa.pitches[1] - hexa.pitches[0] == 2
    assert hexa.pitches[c.layout.cols] - hexa.pitches[0] == 7  # row 1 is shifted right: up-right
    assert hexa.pitches[c.layout.cols] - hexa.pitches[1] == 5  # and up-left of key 1
    # the piano: 12 white keys C3..G4 and their 8 black keys, chromatic by key index
    assert piano.n_keys == 20 and piano.names[0] == "C3" and piano.names[1] == "C#3"
    np.testing.assert_array_equal(np.diff(piano.pitches), 1)
    black = np.array([n[1] == "#" for n in piano.names])
    widths = np.array([np.ptp(p[:, 0]) for p in piano.key_outlines()])
    assert (widths[black] == 20).all() and (widths[~black] == 36).all()
    assert (piano.features[black, 1] - 30 >= 60).all()
    # C#3 sits in the upper row between C3 and D3; below it is C3's or D3's key
    cx, cy = piano.key_centres()[1]
    assert piano.key_at(np.array([[cx, cy], [cx - 5, 280], [cx + 5, 280]])).tolist() == [1, 0, 2]
    # pads: silence between round pads, their cells as the grid's
    assert pads.bounds == BOARDS["grid"].bounds and pads.area == BOARDS["grid"].area
    cx, cy = pads.key_centres()[0]
    assert pads.key_at(np.array([[cx + 19.9, cy], [cx + 20.1, cy], [cx + 15, cy + 15]])).tolist() \
        == [0, -1, -1]


def test_the_grid_is_unchanged():
    """The default keyboard's numbers are those of schema 1 (the paper's grid)."""
    kb = BOARDS["grid"]
    assert kb.config.origin == (200.0, 250.0) and kb.bounds == (200.0, 250.0, 600.0, 450.0)
    np.testing.assert_array_equal(kb.key_centres()[[0, 9]], [[225.0, 275.0], [275.0, 325.0]])
    rng = np.random.default_rng(3)
    got = ExactModel(kb).sample_actions(10, 5, rng)
    want = np.random.default_rng(3).uniform((250.0, 300.0), (300.0, 350.0), size=(5, 2))
    np.testing.assert_array_equal(got, want)  # the exact model's draws are the same numbers


def test_polygons_pipeline_file_is_the_example():
    d = load_toml("pipelines/layouts/polygons.toml", "keyboard")
    assert KeyboardConfig.from_dict(d) == BOARDS["polygons"].config
    for name in LAYOUT_NAMES:
        d = load_toml(f"pipelines/layouts/{name}.toml", "keyboard")
        assert KeyboardConfig.from_dict(d) == BOARDS[name].config
    keys = example_polygon_keys()
    assert keys[-2].note == "F#5" and keys[-1].tempo == 150.0


# -- bad keyboards --------------------------------------------------------------------------------
SQUARE = ((0.0, 0.0), (40.0, 0.0), (40.0, 40.0), (0.0, 40.0))


def _keys(*offsets):
    return tuple(PolygonKey(vertices=tuple((x + dx, y + dy) for x, y in SQUARE))
                 for dx, dy in offsets)


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"layout": "staggered"}, "unknown layout 'staggered'; valid: grid, hex, piano, pads"),
        ({"layout": "grid", "pad_radius": 10.0}, "layout grid takes no option 'pad_radius' (layout pads does)"),
        ({"layout": "hex", "scale": "diatonic"}, "scale does not apply to the hex layout"),
        ({"layout": "pads", "pad_radius": 30.0}, "pads would overlap"),
        ({"layout": "piano", "black_width": 40.0}, "black keys would overlap"),
        ({"layout": "piano", "base_note": "C#3"}, "is a black key"),
        ({"layout": "polygons"}, "needs its keys"),
        ({"layout": "polygons", "origin": (300.0, 300.0), "keys": _keys((0, 0), (20, 0))},
         "keys 0 (C3) and 1 (D3) overlap"),
        ({"layout": "polygons",
          "keys": (PolygonKey(vertices=((0.0, 0.0), (1.0, 1.0), (2.0, 2.0))),)},
         "key 0: degenerate polygon"),
        ({"layout": "polygons", "origin": (300.0, 300.0),
          "keys": (PolygonKey(vertices=SQUARE, note="C4", tempo=90.0),
                   PolygonKey(vertices=tuple((x + 50, y) for x, y in SQUARE), note="C4",
                              tempo=90.5))},
         "keys 0 (C4, 90 bpm) and 1 (C4, 90.5 bpm) sound alike"),
        ({"layout": "grid", "rows": 20, "cols": 20}, "at most 256 keys"),
    ],
)
def test_bad_keyboards_are_refused_naming_the_key_or_option(kwargs, fragment):
    with pytest.raises(ConfigError) as exc:
        KeyboardConfig(**kwargs)
    assert fragment in str(exc.value)


def test_keys_table_from_toml_is_checked():
    with pytest.raises(ConfigError,
                       match=r"unknown keys\[1\] option 'colour'; valid: vertices, note, tempo"):
        KeyboardConfig.from_dict({"layout": "polygons", "keys": [
            {"vertices": [list(v) for v in SQUARE]}, {"vertices": [[0, 0]], "colour": 3}]})
    with pytest.raises(ConfigError, match=r"keys\[0\].vertices is required"):
        KeyboardConfig.from_dict({"layout": "polygons", "keys": [{"note": "C4"}]})


def test_out_of_reach_key_is_named():
    far = KeyboardConfig(layout="polygons", keys=_keys((250, 250), (950, 250)))
    with pytest.raises(Exception, match=r"1 key\(s\) out of reach: D3"):
        check_keyboard_reachable(SimConfig(), Keyboard(far))


def test_keyboard_cli_every_layout_and_bad_input(runner, tmp_path):
    for name in LAYOUT_NAMES:
        out = tmp_path / f"{name}.h5"
        args = ["keyboard", "-o", str(out)]
        args += (["--config", "pipelines/layouts/polygons.toml"] if name == "polygons"
                 else ["--layout", name])
        r = runner.invoke(app, args)
        assert r.exit_code == 0, r.output
        assert f"{name} layout" in " ".join(r.output.split())
        art = read_artifact(out, "keyboard")
        assert art.schema_version == 2 and art.attrs["layout"] == name
        kb = keyboard_stage.load(art)
        assert kb.config == BOARDS[name].config
        off = art.data["outlines"]["offsets"]
        assert len(off) == kb.n_keys + 1 and off[-1] == len(art.data["outlines"]["vertices"])
        r = runner.invoke(app, ["plot", "keyboard", str(out), "-o", str(tmp_path / f"{name}.png")])
        assert r.exit_code == 0 and (tmp_path / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
    bad = tmp_path / "bad.h5"
    cases = [
        (["--layout", "staggered"], ["unknown layout", "grid, hex, piano, pads, polygons"]),
        (["--layout", "pads", "--pad-radius", "40"], ["pad_radius", "overlap"]),
        (["--layout", "grid", "--key-height", "3"], ["--key-height does not apply to this layout", "layout grid takes no option 'key_height'"]),
        (["--layout", "grid", "--origin-x", "700"], ["out of reach"]),
    ]
    for args, fragments in cases:
        r = runner.invoke(app, ["keyboard", "-o", str(bad), *args])
        _one_line_error(r, *fragments)
        assert not bad.exists()
    toml = tmp_path / "overlap.toml"
    toml.write_text('[keyboard]\nlayout = "polygons"\norigin = [300.0, 300.0]\n'
                    '[[keyboard.keys]]\nvertices = [[0, 0], [40, 0], [40, 40], [0, 40]]\n'
                    '[[keyboard.keys]]\nvertices = [[20, 20], [60, 20], [60, 60], [20, 60]]\n')
    r = runner.invoke(app, ["keyboard", "--config", str(toml), "-o", str(bad)])
    _one_line_error(r, "keys 0 (C3) and 1 (D3) overlap")
    assert not bad.exists()


def test_schema_1_grid_keyboard_still_loads(tmp_path):
    art = read_artifact("data/schema/v1/keyboard.h5", "keyboard")
    assert art.schema_version == 1 and "layout" not in art.config
    assert keyboard_stage.load(art).config == KeyboardConfig()
    write_artifact(keyboard_stage.run(KeyboardConfig()), tmp_path / "kb.h5")
    assert read_artifact(tmp_path / "kb.h5").schema_version == 2


@pytest.mark.parametrize("name", ("hex", "piano", "pads", "polygons"))
def test_perturb_on_every_layout(name):
    kb = BOARDS[name]
    art = keyboard_stage.run(kb.config)
    scene = perturb.run(perturb.PerturbConfig(category="large", family="rigid"), art,
                        rng=np.random.default_rng(1), seed=1)
    assert scene.config["keyboard"]["layout"] == name
    with pytest.raises(Exception, match="outside the arm's reach"):
        perturb.check_reach(kb, "translation", np.array([0.0, 400.0]), SimConfig())
