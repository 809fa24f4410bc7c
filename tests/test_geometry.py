"""Key geometry (issue 25): exact overlap, the half-open edge rule, the vertex bound and one-line
errors for bad keyboard tables. Known answers chosen so plausible bugs fail: a sampled overlap test
misses 0.3 px, a whole-key shift of one hexagon covers pad points twice, a closed (not half-open)
point test puts shared-edge points in two keys."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from helpers import one_line_error

from kbcli.cli import app
from kbcli.core.instrument.geometry import (
    MAX_COORD,
    OVERLAP_AREA,
    KeyShapes,
    check_overlaps,
    check_polygon,
    overlapping_pairs,
    points_in_polygon,
    segment_distance,
)
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.layouts import LAYOUTS, PolygonKey, example_config_fields
from kbcli.errors import ConfigError
from kbcli.io.config import load_toml

SQUARE = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 40.0], [0.0, 40.0]])
NAMES = ("A", "B", "C", "D")


def _keys(*polys) -> tuple[PolygonKey, ...]:
    return tuple(PolygonKey(vertices=tuple(map(tuple, p))) for p in polys)


def _coverage(shapes: KeyShapes, points: np.ndarray) -> np.ndarray:
    """(n,) how many keys each point lies in, each key tested on its own."""
    return np.sum([shapes.contains(k, points) for k in range(shapes.n_keys)], axis=0)


def _pad_points(shapes: KeyShapes, spacing: float = 1.0) -> np.ndarray:
    """A dense point set over the keys: an even grid (offset so it is not aligned with the keys)
    plus every key's vertices and points along its edges (where keys meet)."""
    x0, y0, x1, y1 = shapes.bounds
    g = np.stack(np.meshgrid(np.arange(x0 - 2, x1 + 2, spacing) + 0.37,
                             np.arange(y0 - 2, y1 + 2, spacing) + 0.21), -1).reshape(-1, 2)
    edges, _ = shapes.outline_points(spacing=2.0)
    return np.vstack([g, edges, np.vstack(shapes.polygons)])


# -- exact overlap ----------------------------------------------------------------------------------
@pytest.mark.parametrize("gap", [0.3, 0.1, 1e-3])
def test_keys_overlapping_by_a_fraction_of_a_pixel_are_refused(gap):
    """A 1 px sampling grid misses these: the overlap is a 40 x gap strip."""
    shapes = KeyShapes(polygons=[SQUARE, SQUARE + (40.0 - gap, 0.0)])
    with pytest.raises(ConfigError, match=r"^keys 0 \(A\) and 1 \(B\) overlap$"):
        check_overlaps(shapes, NAMES)
    with pytest.raises(ConfigError, match=r"keys 0 \(C3\) and 1 \(D3\) overlap"):
        KeyboardConfig(layout="polygons", origin=(300.0, 300.0),
                       keys=_keys(SQUARE, SQUARE + (40.0 - gap, 0.0)))


def test_shared_edges_and_corners_are_not_overlaps():
    shapes = KeyShapes(polygons=[SQUARE, SQUARE + (40, 0), SQUARE + (0, 40), SQUARE + (40, 40)])
    check_overlaps(shapes, NAMES)
    assert overlapping_pairs(shapes)[0].size == 0
    # a gap of 1e-6 px is not an overlap; a triangle poking 1e-3 px into its neighbour is
    check_overlaps(KeyShapes(polygons=[SQUARE, SQUARE + (40 + 1e-6, 0)]), NAMES)
    tip = np.array([[40.0 - 1e-3, 20.0], [60.0, 0.0], [60.0, 40.0]])
    with pytest.raises(ConfigError, match="overlap"):
        check_overlaps(KeyShapes(polygons=[SQUARE, tip]), NAMES)


def test_overlapping_pairs_known_answer():
    """Every overlapping pair, in order, and none of the touching ones (areas exact: 0.3 x 40 =
    12 px^2 for the first two pairs, the whole square for the last)."""
    polys = [SQUARE, SQUARE + (39.7, 0.0), SQUARE + (200.0, 0.0), SQUARE + (79.4, 0.0),
             SQUARE + (200.0, 0.0), SQUARE + (119.4, 0.0)]  # key 5 touches key 3 only
    ii, jj = overlapping_pairs(KeyShapes(polygons=polys))
    assert list(zip(ii.tolist(), jj.tolist(), strict=True)) == [(0, 1), (1, 3), (2, 4)]
    assert OVERLAP_AREA < 12.0
    discs = KeyShapes(discs=np.array([[0.0, 0.0, 10.0], [20.0, 0.0, 10.0], [39.9, 0.0, 10.0]]))
    ii, jj = overlapping_pairs(discs)  # touching at x = 10 is fine, 0.1 px into the next is not
    assert list(zip(ii.tolist(), jj.tolist(), strict=True)) == [(1, 2)]


def test_a_hexagon_shifted_by_a_whole_key_is_refused():
    """The mutation of issue 25: one hex key moved a whole key width covers its neighbour (3,789
    px^2 for 50 px keys): the overlap check and the coverage test both see it."""
    kb = Keyboard(KeyboardConfig(layout="hex"))
    polys = [p.copy() for p in kb.shapes.polygons]
    polys[5] = polys[5] + (kb.config.layout.key_size, 0.0)
    bad = KeyShapes(polygons=polys)
    with pytest.raises(ConfigError, match=r"keys 5 .* and 6 .* overlap"):
        check_overlaps(bad, kb.names)
    assert _coverage(bad, _pad_points(bad, 2.0)).max() >= 2


# -- every layout -----------------------------------------------------------------------------------
def _interior_coverage(shapes: KeyShapes, points: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """(n,) how many keys hold each point more than ``eps`` px inside their outline."""
    out = np.zeros(len(points), dtype=np.int64)
    for k in range(shapes.n_keys):
        inside = shapes.contains(k, points)
        if shapes.discs is None:
            inside[inside] = segment_distance(points[inside], shapes.polygons[k]) > eps
        else:
            cx, cy, r = shapes.discs[k]
            inside &= np.hypot(points[:, 0] - cx, points[:, 1] - cy) < r - eps
        out += inside
    return out


@pytest.mark.parametrize("name", LAYOUTS.names())
def test_every_pad_point_lies_in_at_most_one_key(name):
    """Dense points over the pad (a 1 px grid, every vertex, points along every edge): none is
    inside two keys, and key_at names the key that holds it."""
    kb = Keyboard(KeyboardConfig(layout=name, **example_config_fields(name)))
    shapes = kb.shapes
    pts = _pad_points(shapes)
    inner = _interior_coverage(shapes, pts)
    assert inner.max() <= 1, pts[inner > 1][:5]
    at = shapes.key_at(pts)
    hit = np.flatnonzero(at >= 0)
    for k in np.unique(at[hit]):  # each point key_at names is in that key (checked key by key)
        assert shapes.contains(int(k), pts[hit[at[hit] == k]]).all(), k
    assert (at[inner == 1] >= 0).all()
    assert overlapping_pairs(shapes)[0].size == 0


@pytest.mark.parametrize("name", LAYOUTS.names())
def test_every_point_on_a_shared_edge_lies_in_exactly_one_key(name):
    """The half-open rule on the layouts: points on the keys' own edges and vertices lie in at
    most one key (exactly, no tolerance), and key_at agrees."""
    shapes = Keyboard(KeyboardConfig(layout=name, **example_config_fields(name))).shapes
    pts = _pad_points(shapes)
    cover = _coverage(shapes, pts)
    assert cover.max() == 1, pts[cover > 1][:5]
    np.testing.assert_array_equal(shapes.key_at(pts) >= 0, cover == 1)


# -- the half-open rule -----------------------------------------------------------------------------
def test_points_on_a_shared_edge_belong_to_exactly_one_key():
    """Four squares meeting at (40, 40): a point on a vertical edge belongs to the key on its
    right, on a horizontal edge to the key above, the shared corner to the upper-right key."""
    polys = [SQUARE, SQUARE + (40, 0), SQUARE + (0, 40), SQUARE + (40, 40)]
    shapes = KeyShapes(polygons=polys)
    pts = np.array([[40.0, 20.0], [40.0, 60.0], [20.0, 40.0], [60.0, 40.0], [40.0, 40.0],
                    [0.0, 20.0], [80.0, 20.0], [20.0, 0.0], [20.0, 80.0]])
    np.testing.assert_array_equal(_coverage(shapes, pts), [1, 1, 1, 1, 1, 1, 0, 1, 0])
    assert shapes.key_at(pts).tolist() == [1, 3, 2, 3, 3, 0, -1, 0, -1]
    # the same rule on a slanted shared edge: exactly one of the two triangles of a square
    lower = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 40.0]])
    upper = np.array([[0.0, 0.0], [40.0, 40.0], [0.0, 40.0]])
    diag = np.array([[10.0, 10.0], [20.0, 20.0], [30.0, 30.0]])
    both = points_in_polygon(diag, lower).astype(int) + points_in_polygon(diag, upper)
    assert both.tolist() == [1, 1, 1]


# -- the vertex bound -------------------------------------------------------------------------------
def test_a_vertex_far_off_the_pad_is_refused_before_anything_is_built():
    far = [[0.0, 0.0], [1e7, 0.0], [0.0, 40.0]]
    tracemalloc.start()
    try:
        with pytest.raises(ConfigError, match=r"key 0: vertices must lie within -10000\.\.10000"):
            check_polygon(far, "key 0")
        with pytest.raises(ConfigError) as exc:
            KeyboardConfig.from_dict({"layout": "polygons", "keys": [{"vertices": far}]})
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 5e6  # no raster over a 1e7 px box
    msg = str(exc.value)
    assert "\n" not in msg and "keys[0].vertices" in msg and "10000" in msg
    check_polygon([[0.0, 0.0], [MAX_COORD, 0.0], [0.0, 40.0]], "key 0")  # the bound itself is fine
    with pytest.raises(ConfigError, match="within -10000..10000 px .* move origin"):
        KeyboardConfig(layout="polygons", origin=(MAX_COORD - 10.0, 0.0), keys=_keys(SQUARE))


def test_degenerate_outlines_are_refused_by_shapely_validity():
    for v, fragment in (([[0, 0], [10, 10], [10, 0], [0, 10]], "cross"),  # bow tie
                        ([[0, 0], [10, 0], [20, 0]], "area"),
                        ([[0, 0], [20, 0], [20, 20], [10, 0], [0, 20]], "cross")):  # touches itself
        with pytest.raises(ConfigError, match=fragment):
            check_polygon(v, "key 2")


# -- bad TOML values ----------------------------------------------------------------------------------
GOOD_KEYS = '[[keyboard.keys]]\nvertices = [[300, 300], [340, 300], [340, 340], [300, 340]]\n'


@pytest.mark.parametrize(
    "body, fragments",
    [
        ("rows = 2.5", ["keyboard.layout.rows", "whole number"]),
        ("rows = 0", ["keyboard.layout.rows", "greater than or equal to 1"]),
        ("rows = true", ["keyboard.layout.rows", "whole number"]),
        ('key_size = "big"', ["keyboard.layout.key_size", "number"]),
        ("margin = -1.0", ["keyboard.margin", "in [0, 10000], got -1.0"]),
        ("match_threshold = 0.0", ["keyboard.match_threshold", "in (0, 100], got 0.0"]),
        ("noise_std = 1e308", ["keyboard.noise_std", "in [0, 100], got 1e+308"]),
        ("tempo_col_step = 1e308", ["keyboard.tempo_col_step", "in [0, 1000]"]),
        ("tempo_base = 1e308", ["keyboard.tempo_base", "in (0, 10000]"]),
        ("key_size = 1e9", ["keyboard.layout.key_size", "in (0, 10000]"]),
        ("origin = [1.0, 2.0, 3.0]", ["keyboard.origin must have at most 2 values, got 3"]),
        ("origin = [1.0]", ["keyboard.origin has too few values (no value [1]), got [1.0]"]),
        ("origin = [20000.0, 0.0]", ["keyboard.origin[0]", "less than or equal to 10000"]),
        ('layout = "staggered"', ["unknown layout 'staggered'", "grid, hex, piano, pads, polygons"]),
        ('scale = "lydian"', ["unknown scale 'lydian'", "diatonic"]),
        ("colour = 3", ["unknown keyboard option 'colour'", "valid:"]),
        ('layout = "polygons"\n' + GOOD_KEYS + "tempo = 0.0",
         ["keys[0].tempo", "greater than 0"]),
        ('layout = "polygons"\n' + GOOD_KEYS + "note = true", ["keys[0].note"]),
        ('layout = "polygons"\n' + GOOD_KEYS + "colour = 1",
         ["unknown keys[0] option 'colour'", "vertices, note, tempo"]),
        ('layout = "polygons"\n[[keyboard.keys]]\nvertices = [[0, 0, 1], [1, 0, 1], [0, 1, 1]]',
         ["keys[0].vertices"]),
    ],
)
def test_bad_toml_values_give_one_line_naming_table_and_key(tmp_path, body, fragments):
    toml = tmp_path / "kb.toml"
    toml.write_text(f"[keyboard]\n{body}\n")
    with pytest.raises(ConfigError) as exc:
        KeyboardConfig.from_dict(load_toml(toml, "keyboard"))
    msg = str(exc.value)
    assert "\n" not in msg, msg
    for f in fragments:
        assert f in msg, msg


def test_bad_toml_through_the_cli_is_one_line_and_writes_nothing(runner, tmp_path):
    toml = tmp_path / "kb.toml"
    toml.write_text('[keyboard]\nlayout = "polygons"\norigin = [300.0, 300.0]\n'
                    "[[keyboard.keys]]\nvertices = [[0, 0], [40, 0], [40, 40], [0, 40]]\n"
                    "[[keyboard.keys]]\nvertices = [[39.7, 0], [80, 0], [80, 40], [39.7, 40]]\n")
    out = tmp_path / "kb.h5"
    r = runner.invoke(app, ["keyboard", "--config", str(toml), "-o", str(out)])
    one_line_error(r, "keys 0 (C3) and 1 (D3) overlap")
    assert not out.exists()
    toml.write_text("[keyboard]\nrows = 2.5\n")
    r = runner.invoke(app, ["keyboard", "--config", str(toml), "-o", str(out)])
    one_line_error(r, "keyboard.layout.rows", "whole number")
    assert not out.exists()
