"""What the figures and the animation show, measured on the drawn artists (issue 28): byte-identical
SVG, key labels legible and inside their keys, titles and labels inside their axes, the true and
the believed keyboard drawn apart, touch labels that do not overlap, the rigid posterior panels
saying what they do with the angle, one key palette for plots and animation, and an animation
legend that covers no touch."""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.path import Path as MplPath

from kbcli.cli import app
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.io.artifact import read_artifact
from kbcli.stages import adapt as adapt_stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import perturb
from kbcli.stages.models import exact_artifact, load_model
from kbcli.viz import adapt as viz_adapt
from kbcli.viz import keyboard as viz_keyboard
from kbcli.viz import loop as viz_loop
from kbcli.viz import model as viz_model
from kbcli.viz.animator import Animator
from kbcli.viz.common import KEY_FONT_SIZES
from kbcli.viz.palette import BELIEF, TRUTH, key_colours
from kbcli.viz.replay import load_replay

GOLDEN = Path(__file__).resolve().parent.parent / "data" / "golden"


@pytest.fixture
def capture(monkeypatch):
    """Keep the figures the plot functions would save (drawn, not closed)."""
    figs = []

    def keep(fig, path, dpi=110):
        fig.canvas.draw()
        figs.append(fig)

    for mod in (viz_keyboard, viz_model, viz_loop, viz_adapt):
        monkeypatch.setattr(mod, "save", keep)
    yield figs
    for fig in figs:
        plt.close(fig)


def _box(artist):
    """An artist's drawn box (a text's rounded background box when it has one)."""
    patch = getattr(artist, "get_bbox_patch", lambda: None)()
    return (patch or artist).get_window_extent()


def _disjoint(a, b) -> bool:
    return a.x1 <= b.x0 or b.x1 <= a.x0 or a.y1 <= b.y0 or b.y1 <= a.y0


def _inside(inner, outer, tol: float = 0.5) -> bool:
    return (inner.x0 >= outer.x0 - tol and inner.x1 <= outer.x1 + tol
            and inner.y0 >= outer.y0 - tol and inner.y1 <= outer.y1 + tol)


# -- SVG, byte for byte ------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["svg", "pdf", "png"])
def test_the_same_figure_twice_gives_the_same_bytes(runner, tmp_path, fmt):
    for argv in (["plot", "run", str(GOLDEN / "closed_loop.h5")],
                 ["plot", "keyboard", str(GOLDEN / "keyboard.h5")]):
        out = [tmp_path / f"{argv[1]}{i}.{fmt}" for i in (1, 2)]
        for o in out:
            r = runner.invoke(app, [*argv, "-o", str(o)])
            assert r.exit_code == 0, r.output
        a, b = (o.read_bytes() for o in out)
        assert a == b, (argv, fmt)
    if fmt == "svg":
        assert b"<dc:date>" not in a and b"clip-path" in a  # no date; ids of clip paths are fixed


# -- the keyboard's labels and title -----------------------------------------------------------------
LAYOUTS = {"grid": {}, "piano": {"layout": "piano"}, "hex": {"layout": "hex"},
           "pads": {"layout": "pads"}}


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_key_labels_are_legible_inside_their_keys_and_the_title_inside_the_axes(capture, tmp_path,
                                                                               layout):
    kb = keyboard_stage.load(keyboard_stage.run(KeyboardConfig(**LAYOUTS[layout])))
    viz_keyboard.plot_keyboard(kb, tmp_path / "k.png")
    ax = capture[0].axes[0]
    labels = [t for t in ax.texts if t.get_text()]
    assert len(labels) >= kb.n_keys - (kb.n_keys // 2 if layout == "piano" else 0)
    polys = kb.key_outlines()
    boxes = []
    for t in labels:
        assert t.get_fontsize() >= min(KEY_FONT_SIZES) >= 7
        (k,) = [k for k, p in enumerate(polys) if MplPath(p).contains_point(t.get_position())]
        assert kb.names[k] == t.get_text().split("\n")[0]
        path = MplPath(ax.transData.transform(polys[k]))
        e = t.get_window_extent().padded(-0.5)
        corners = [(e.x0, e.y0), (e.x0, e.y1), (e.x1, e.y0), (e.x1, e.y1)]
        assert path.contains_points(corners).all(), (layout, t.get_text())
        boxes.append(e)
    assert all(_disjoint(a, b) for a, b in itertools.combinations(boxes, 2))
    title = ax.title.get_window_extent()
    frame = ax.get_window_extent()
    assert frame.x0 <= title.x0 and title.x1 <= frame.x1, (layout, ax.title.get_text())


def test_the_piano_labels_every_key_with_note_and_tempo(capture, tmp_path):
    kb = keyboard_stage.load(keyboard_stage.run(KeyboardConfig(layout="piano")))
    viz_keyboard.plot_keyboard(kb, tmp_path / "k.png")
    texts = [t.get_text() for t in capture[0].axes[0].texts]
    assert sorted(t.split("\n")[0] for t in texts) == sorted(kb.names)
    assert all("\n" in t for t in texts)  # the tempo too


# -- plot model ----------------------------------------------------------------------------------------
def test_the_99_percent_label_is_inside_the_curve_panel(capture, tmp_path):
    art = read_artifact(GOLDEN / "model.h5", "model")
    viz_model.plot_model(art, load_model(art), keyboard_stage.load(art), tmp_path / "m.png")
    fig = capture[0]
    (label,) = [t for ax in fig.axes for t in ax.texts if t.get_gid() == "target-label"]
    assert label.get_text() == "99 %"
    assert _inside(_box(label), label.axes.get_window_extent().padded(-1.0), tol=0.0)
    layout = fig.axes[1]  # the true layout's labels stay legible too
    assert layout.texts and min(t.get_fontsize() for t in layout.texts) >= 7


# -- plot run -------------------------------------------------------------------------------------------
def _crowded_loop() -> tuple[dict, dict]:
    """A closed loop whose 12 adaptation touches land within 8 px of each other."""
    n, moved, fired = 80, 40, 44
    phase = np.zeros(n, int)
    phase[45:57] = 1
    landed = np.full((n, 2), 400.0)
    landed[45:57] = np.array([400.0, 350.0]) + np.random.default_rng(3).uniform(-8, 8, (12, 2))
    steps = {"phase": phase, "result": np.zeros(n, int), "score": np.ones(n), "landed": landed}
    attrs = {"perturbed_at": moved, "detected_at": fired, "detection_delay": fired - moved,
             "truth": {"dx": 12.0, "dy": -7.0}, "correction": {"dx": 11.9, "dy": -7.05},
             "success_before": 1.0, "success_after_perturbation": 1.0,
             "success_after_adaptation": 1.0}
    return steps, attrs


def test_plot_run_draws_truth_and_belief_apart_and_touch_labels_apart(capture, tmp_path):
    steps, attrs = _crowded_loop()
    kb = keyboard_stage.load(keyboard_stage.run(KeyboardConfig()))
    viz_loop.plot_loop(steps, attrs, kb, tmp_path / "r.png")
    ax = capture[0].axes[-1]
    outlines = [p for p in ax.patches if not p.get_fill()]
    truth = [p for p in outlines if np.allclose(p.get_edgecolor()[:3], to_rgb(TRUTH["color"]))]
    belief = [p for p in outlines if np.allclose(p.get_edgecolor()[:3], to_rgb(BELIEF["color"]))]
    assert len(truth) == len(belief) == kb.n_keys
    assert truth[0].get_linestyle() == "-" and belief[0].get_linestyle() != "-"
    assert belief[0].get_zorder() > truth[0].get_zorder()  # the dashes on top
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(t.startswith("where it is") for t in legend)
    assert any(t.startswith("where the robot believes") for t in legend)
    # the touch labels: several placed, apart, inside the axes, never over a touch
    labels = [t for t in ax.texts if t.get_text()]
    assert len(labels) >= 4
    boxes = [_box(t) for t in labels]
    assert all(_disjoint(a, b) for a, b in itertools.combinations(boxes, 2))
    frame = ax.get_window_extent()
    assert all(_inside(b, frame) for b in boxes)
    touches = ax.transData.transform(steps["landed"][steps["phase"] == 1])
    assert not any(b.contains(x, y) for b in boxes for x, y in touches)


# -- plot adapt: the angle ----------------------------------------------------------------------------
KB_ART = keyboard_stage.run(KeyboardConfig())
MODEL_ART = exact_artifact(KB_ART)


def _adapt(family: str, scene_family: str = "rigid"):
    params = (3.0, 8.0, -5.0) if scene_family == "rigid" else (8.0, -5.0)
    scene = perturb.run(perturb.PerturbConfig(family=scene_family, params=params), KB_ART,
                        rng=np.random.default_rng(0))
    cfg = adapt_stage.AdaptConfig.flat(family=family, max_steps=3, resolution=2.0,
                                       prior_halfwidth=16.0)
    return adapt_stage.run(cfg, MODEL_ART, scene, rng=np.random.default_rng(0), seed=0,
                           snapshot_steps=(0, 1, 3))


@pytest.fixture(scope="module")
def rigid_run():
    return _adapt("rigid")


@pytest.mark.parametrize("family, scene, note", [
    ("rigid", "rigid", "angle marginalised"), ("translation", "rigid", "angle not estimated"),
    ("translation", "translation", None)])
def test_posterior_panels_say_what_they_do_with_the_angle(capture, tmp_path, rigid_run, family,
                                                          scene, note):
    run = rigid_run if family == scene == "rigid" else _adapt(family, scene)
    viz_adapt.plot_adapt(run, tmp_path / "a.png")
    panels = [ax for ax in capture[0].axes if ax.get_images()]
    assert len(panels) == 3
    for ax in panels:
        title = ax.get_title()
        assert (note in title) if note else ("angle" not in title), title


# -- the animation ---------------------------------------------------------------------------------------
def _check_animator(anim: Animator, kb) -> None:
    # the keys in the plots' colours
    if kb is not None:
        faces = anim.pad.keys.get_facecolors()[:, :3]
        np.testing.assert_allclose(faces, key_colours(kb.n_keys)[:, :3], atol=1e-6)
    # the pad's legend outside every axes (it covers no touch) and inside the figure
    anim.canvas.draw()
    renderer = anim.canvas.get_renderer()
    legend = anim.ax_pad.get_legend().get_window_extent(renderer)
    assert _disjoint(legend, anim.ax_pad.get_window_extent(renderer))
    for ax in (anim.ax_post, anim.ax_c1, anim.ax_c2):
        if ax is not None:
            assert _disjoint(legend, ax.get_tightbbox(renderer)), ax
    assert _inside(legend, anim.fig.bbox)
    xy = anim.ax_pad.transData.transform(anim.rep.landed[np.isfinite(anim.rep.landed).all(1)])
    assert not any(legend.contains(x, y) for x, y in xy)


def test_the_animation_shares_the_plots_palette_and_its_legend_covers_no_touch(rigid_run):
    loop = load_replay(read_artifact(GOLDEN / "closed_loop.h5"))
    anim = Animator(loop, dpi=60, blit=True)
    _check_animator(anim, loop.keyboard)
    anim.draw(loop.n)
    assert "(dx, dy)" in anim.ax_post.get_title()
    run = load_replay(rigid_run)
    anim = Animator(run, dpi=60, blit=True)
    _check_animator(anim, run.keyboard)
    anim.draw(run.n)
    assert "angle marginalised" in anim.ax_post.get_title()
    unknown = dataclasses.replace(load_replay(read_artifact(GOLDEN / "run.h5")), truth=None)
    _check_animator(Animator(unknown, dpi=60, blit=True), None)  # a real robot's longer legend


def test_the_reports_posterior_figure_says_when_the_angle_is_marginalised(monkeypatch, tmp_path):
    from kbcli.viz import report

    figs = []
    monkeypatch.setattr(report, "save", lambda fig, path: figs.append(fig))
    art = read_artifact(GOLDEN / "evaluation.h5", "evaluation")
    report.plot_posterior(art, tmp_path / "p.png")
    assert "angle" not in figs[-1]._suptitle.get_text()  # a translation evaluation
    for opts in art.attrs["methods"]["kbcli"]["options"]["ideal"].values():
        opts["robot"]["family"] = "rigid"
    report.plot_posterior(art, tmp_path / "p.png")
    assert "angle marginalised" in figs[-1]._suptitle.get_text()
    for fig in figs:
        plt.close(fig)


def test_model_boundaries_are_drawn_only_where_they_separate_keys():
    """Issue 40: a fitted line was drawn across the whole pad, outside the keyboard too."""
    from kbcli.core.instrument.keyboard import Keyboard
    from kbcli.core.model.base import grid_points

    kb = Keyboard(KeyboardConfig())
    _, pts = grid_points(kb.area, viz_model.MAP_STEP)
    keys = kb.key_at(pts.reshape(-1, 2)).reshape(pts.shape[:2])
    lines = np.array([[1.0, 0.0, 300.0],   # x = 300: between two columns of keys
                      [1.0, 0.0, 625.0],   # x = 625: silence on both sides
                      [0.0, 2.0, 700.0]])  # y = 350 (a normal of length 2): between two rows
    seg = viz_model.boundary_segments(lines, keys, kb.area)
    drawn = seg[np.isfinite(seg).all(axis=1)]
    assert len(drawn) and np.all(np.isclose(drawn[:, 0], 300.0) | np.isclose(drawn[:, 1], 350.0))
    on_x = drawn[np.isclose(drawn[:, 0], 300.0)]
    assert 250 <= on_x[:, 1].min() < 255 and 445 < on_x[:, 1].max() <= 450  # the keys' rows only
    on_y = drawn[np.isclose(drawn[:, 1], 350.0)]
    assert 200 <= on_y[:, 0].min() < 205 and 595 < on_y[:, 0].max() <= 600
