"""Adding a part is one module and one registration, each part with an option of its own.

A toy posterior (``leaning``: every touch tilts the belief towards larger dx by ``lean``), a toy
strategy (``corner``: always touch one corner of the working area, ``corner = "low"`` or
``"high"``), a toy estimator (``shrunk``: the posterior mean shrunk towards no displacement by
``shrink``) and a toy layout (``row``: ``n_keys`` keys of ``key_width`` px side by side) are
registered from this file alone and run through ``kbcli adapt`` and ``kbcli keyboard`` with their
own option set; an option the chosen part does not take is refused by the part, naming it.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
import pytest
from helpers import one_line_error
from pydantic import AfterValidator

from kbcli.cli import app
from kbcli.core.adaptation.estimators import ESTIMATORS, Estimator
from kbcli.core.adaptation.posteriors import POSTERIORS, KindBase, Observation
from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.core.config import Count, Name, Number, between, member_of
from kbcli.core.instrument.geometry import KeyShapes
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.layouts import LAYOUTS, Layout, LayoutGeometry
from kbcli.core.instrument.layouts.base import base_midi
from kbcli.core.instrument.notes import scale_pitches
from kbcli.core.options import Options
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact
from kbcli.stages.perturb import PerturbConfig
from kbcli.stages.perturb import run as perturb_run


# -- a posterior with an option of its own ------------------------------------------------------
class LeaningOptions(Options):
    """``lean``: the log weight every touch adds per px of dx."""

    what: ClassVar[str] = "posterior leaning"
    lean: between(Number, 0, 10) = 1.0


@dataclass(frozen=True)
class LeaningPosterior(KindBase):
    """Hears nothing; every touch adds ``lean * dx`` to the log posterior."""

    name = "leaning"

    def term(self, obs: Observation) -> tuple[np.ndarray, None]:
        return np.broadcast_to(obs.cfg.posterior.lean * obs.grid.dx, obs.grid.shape).copy(), None


# -- a strategy with an option of its own -------------------------------------------------------
class CornerOptions(Options):
    """``corner``: the working area's ``low`` (lower-left) or ``high`` (upper-right) corner."""

    what: ClassVar[str] = "strategy corner"
    corner: Annotated[Name, AfterValidator(member_of("corner", ("low", "high")))] = "low"


def corner_strategy(ctx, rng: np.random.Generator) -> np.ndarray:
    x0, y0, x1, y1 = ctx.area
    return np.array([x0, y0] if ctx.options.corner == "low" else [x1, y1], float)


# -- an estimator with an option of its own ------------------------------------------------------
class ShrunkOptions(Options):
    """``shrink``: the fraction of the posterior mean taken off (0: the mean, 1: no displacement)."""

    what: ClassVar[str] = "estimator shrunk"
    shrink: between(Number, 0, 1) = 0.0


def shrunk_mean(post, options: ShrunkOptions) -> np.ndarray:
    return (1.0 - options.shrink) * post.mean()


# -- a layout with an option of its own ---------------------------------------------------------
class RowOptions(Options):
    """``n_keys`` keys of ``key_width`` x 60 px side by side."""

    what: ClassVar[str] = "layout row"
    n_keys: Count = 5
    key_width: between(Number, 10, 200) = 40.0


def build_row(cfg) -> LayoutGeometry:
    n, w = cfg.layout.n_keys, cfg.layout.key_width
    polys = [np.array([[i * w, 0], [(i + 1) * w, 0], [(i + 1) * w, 60], [i * w, 60]], float)
             for i in range(n)]
    shapes = KeyShapes(polygons=polys)
    tempi = cfg.tempo_base + np.arange(n) * cfg.tempo_col_step
    return LayoutGeometry(shapes, scale_pitches(base_midi(cfg), cfg.scale, n), tempi, shapes.bounds)


@contextlib.contextmanager
def toy_parts():
    """The four toy parts registered for the duration of a test."""
    with (POSTERIORS.temporarily("leaning", LeaningPosterior(), summary="leans to larger dx",
                                 traits={"options": LeaningOptions}),
          STRATEGIES.temporarily("corner", corner_strategy, summary="one corner",
                                 traits={"options": CornerOptions}),
          ESTIMATORS.temporarily("shrunk", Estimator("shrunk", "means", shrunk_mean),
                                 summary="the mean, shrunk", traits={"options": ShrunkOptions}),
          LAYOUTS.temporarily("row", Layout("row", "keys in a row", build_row, RowOptions),
                              summary="keys in a row", traits={"options": RowOptions})):
        yield
    assert "leaning" not in POSTERIORS and "corner" not in STRATEGIES and "row" not in LAYOUTS
    assert "shrunk" not in ESTIMATORS


# -- kbcli keyboard -----------------------------------------------------------------------------
def test_a_toy_layout_runs_through_kbcli_keyboard_with_its_own_option(runner, tmp_path):
    toml = tmp_path / "row.toml"
    toml.write_text('[keyboard]\nlayout = "row"\nn_keys = 7\nkey_width = 30.0\n')
    out = tmp_path / "row.h5"
    with toy_parts():
        r = runner.invoke(app, ["keyboard", "--config", str(toml), "-o", str(out)])
        assert r.exit_code == 0, r.output
        art = read_artifact(out, "keyboard")
        kb = keyboard_stage.load(art)
    assert art.attrs["layout"] == "row" and kb.n_keys == 7
    assert art.config["n_keys"] == 7 and art.config["key_width"] == 30.0  # stored flat
    x0, _, x1, _ = kb.bounds
    assert x1 - x0 == pytest.approx(7 * 30.0)
    assert len(set(kb.pitches.tolist())) == 7


@pytest.mark.parametrize("body, args, fragments", [
    ('layout = "row"\nrows = 2\n', [],
     ["layout row takes no option 'rows'", "layout grid, hex and pads do", "n_keys, key_width"]),
    ('layout = "row"\n', ["--pad-radius", "12"],
     ["keyboard: --pad-radius does not apply to this layout", "layout row takes no option"]),
    ('layout = "grid"\nn_keys = 3\n', [], ["layout grid takes no option 'n_keys' (layout row does)"]),
])
def test_a_toy_layout_refuses_a_foreign_option_naming_it(runner, tmp_path, body, args, fragments):
    toml = tmp_path / "kb.toml"
    toml.write_text("[keyboard]\n" + body)
    out = tmp_path / "kb.h5"
    with toy_parts():
        r = runner.invoke(app, ["keyboard", "--config", str(toml), "-o", str(out), *args])
    one_line_error(r, *fragments)
    assert not out.exists()


# -- kbcli adapt --------------------------------------------------------------------------------
@pytest.fixture
def scene_files(tmp_path):
    kb = keyboard_stage.run(KeyboardConfig())
    write_artifact(exact_artifact(kb), tmp_path / "model.h5")
    scene = perturb_run(PerturbConfig(params=(2.0, -1.0)), kb, rng=np.random.default_rng(0))
    write_artifact(scene, tmp_path / "scene.h5")
    return ["--model", str(tmp_path / "model.h5"), "--scene", str(tmp_path / "scene.h5")]


def _adapt_toy(runner, tmp_path, scene_files, steps: int, adapt: str):
    """``kbcli adapt`` with the toy parts registered and ``adapt`` (TOML lines) in its ``[adapt]``
    table (prior half-width 5 px): the run artifact."""
    toml = tmp_path / "toy.toml"
    toml.write_text(f"[adapt]\n{adapt}prior_halfwidth = 5.0\n")
    out = tmp_path / "run.h5"
    with toy_parts():
        r = runner.invoke(app, ["adapt", *scene_files, "--config", str(toml), "-o", str(out),
                                "--max-steps", str(steps), "--seed", "1"])
        assert r.exit_code == 0, r.output
        return read_artifact(out, "run")


def test_a_toy_strategy_and_posterior_run_through_kbcli_adapt(runner, tmp_path, scene_files):
    art = _adapt_toy(runner, tmp_path, scene_files, 4,
                     'strategy = "corner"\ncorner = "high"\nposterior = "leaning"\nlean = 2.0\n')
    robot = art.config["adapt"]["robot"]
    assert robot["strategy"] == {"name": "corner", "corner": "high"}
    assert robot["posterior"] == {"name": "leaning", "lean": 2.0}
    area = Keyboard(KeyboardConfig()).area
    assert np.allclose(art.data["actions"], [area[2], area[3]])  # every touch at the high corner
    assert np.allclose(art.data["estimates"][1:, -2], 5.0)  # leaning: dx at the prior's edge


def test_a_toy_estimator_runs_through_kbcli_adapt(runner, tmp_path, scene_files):
    art = _adapt_toy(runner, tmp_path, scene_files, 3, 'estimator = "shrunk"\nshrink = 0.5\n')
    assert art.config["adapt"]["robot"]["estimator"] == {"name": "shrunk", "shrink": 0.5}
    half = 0.5 * np.asarray(art.data["means"])[:, -2:]  # the errors are those of half the mean
    assert np.allclose(art.data["errors"], np.hypot(*(half - [2.0, -1.0]).T))


@pytest.mark.parametrize("body, args, fragments", [
    ('strategy = "corner"\ncandidates = 64\n', [],
     ["adapt: candidates (in", "does not apply", "strategy corner takes no option 'candidates'"]),
    ('strategy = "corner"\n', ["--candidates", "64"],
     ["adapt: --candidates does not apply to this method", "strategy corner takes no option"]),
    ('strategy = "infogain"\ncorner = "low"\n', [],
     ["strategy infogain takes no option 'corner' (strategy corner does)"]),
    ('posterior = "leaning"\nkde_samples = 100\n', [],
     ["posterior leaning takes no option 'kde_samples' (posterior kde does)"]),
    ('posterior = "likelihood"\nlean = 1.0\n', [],
     ["posterior likelihood takes no option 'lean' (posterior leaning does)"]),
    ('estimator = "mean"\nshrink = 0.5\n', [],
     ["estimator mean takes no option 'shrink' (estimator shrunk does)"]),
    ('shrink = 0.5\n', ["--estimator", "ml"],
     ["estimator ml takes no option 'shrink' (estimator shrunk does)"]),
])
def test_a_toy_part_refuses_a_foreign_option_naming_it(runner, tmp_path, scene_files, body, args,
                                                       fragments):
    toml = tmp_path / "toy.toml"
    toml.write_text("[adapt]\n" + body)
    out = tmp_path / "run.h5"
    with toy_parts():
        r = runner.invoke(app, ["adapt", *scene_files, "--config", str(toml), "-o", str(out),
                                "--max-steps", "2", *args])
    one_line_error(r, *fragments)
    assert not out.exists()


def test_a_toy_part_refuses_a_foreign_option_in_python():
    with toy_parts():
        with pytest.raises(ConfigError, match="layout row takes no option 'pad_radius'"):
            KeyboardConfig(layout="row", pad_radius=10.0)
        assert KeyboardConfig(layout="row", n_keys=3).layout == RowOptions(name="row", n_keys=3)
        # a typo lists the keys a user may type: the keyboard's and the layout's own
        with pytest.raises(ConfigError, match="unknown keyboard option 'n_key'; valid: layout, "
                                              "n_keys, key_width, origin"):
            KeyboardConfig(layout="row", n_key=3)
