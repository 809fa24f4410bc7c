"""The Python API: ``from kbcli import Adapter, Detector`` (ask/tell), the same objects the stages use."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import kbcli
from kbcli.core.adaptation.adapter import Adapter as CoreAdapter
from kbcli.core.detection.detectors import Detector as CoreDetector
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.core.model.base import ExactModel
from kbcli.errors import ArtifactError, ConfigError, ObservationError
from kbcli.io.artifact import write_artifact
from kbcli.sim import IdealReacher, SimConfig, World
from kbcli.stages import adapt as adapt_stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact

ROOT = Path(__file__).resolve().parents[1]
KB_ART = keyboard_stage.run(KeyboardConfig())
KB = keyboard_stage.load(KB_ART)
MODEL = ExactModel(KB)


def test_import_kbcli_stays_light():
    code = "import sys, kbcli; print(sorted(m for m in ('numpy', 'h5py', 'typer', 'matplotlib') " \
           "if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_public_names_are_the_core_objects():
    from kbcli import Adapter, Detector

    # kbcli.Adapter is the core's, plus reading a model file (kbcli.api: the core reads no files)
    assert issubclass(Adapter, CoreAdapter) and Adapter.__init__ is CoreAdapter.__init__
    assert Detector is CoreDetector
    assert {"Adapter", "Detector", "load_model"} <= set(dir(kbcli))
    with pytest.raises(AttributeError):
        kbcli.NoSuchThing  # noqa: B018


def test_ask_tell_is_the_stage_code_path():
    """Driving the Adapter by hand gives the very estimates the adapt stage records."""
    cfg = adapt_stage.AdaptConfig(strategy="infogain", max_steps=8, resolution=1.0,
                                  prior_halfwidth=20.0)
    truth = np.array([6.3, -4.1])
    res = adapt_stage.experiment(cfg, MODEL, KB, truth, rng=np.random.default_rng(5))
    robot_rng, world_rng = np.random.default_rng(5).spawn(2)
    ad = kbcli.Adapter(MODEL, cfg.adapter_config(), rng=robot_rng)
    world = World(KB, IdealReacher(SimConfig()), truth)
    means = []
    for _ in range(cfg.max_steps):
        action = ad.suggest()
        felt, heard = world.touch(action[None], world_rng)
        ad.observe(action, heard[0], felt_position=felt[0])
        means.append(ad.estimate())
    np.testing.assert_array_equal(np.array(means), res["means"])
    assert np.hypot(*(means[-1] - truth)) < 1.0


def test_from_model_file_done_and_budget(tmp_path):
    write_artifact(exact_artifact(KB_ART), tmp_path / "model.h5")
    ad = kbcli.Adapter.from_model(tmp_path / "model.h5", strategy="infogain", seed=3,
                                  max_steps=30, resolution=1.0, prior_halfwidth=20.0)
    assert ad.cfg.strategy.name == "infogain" and ad.cfg.resolution == 1.0
    world = World(KB, IdealReacher(SimConfig()), np.array([-9.0, 5.0]))
    rng = np.random.default_rng(0)
    assert not ad.done()
    while not ad.done():
        a = ad.suggest()
        felt, heard = world.touch(a[None], rng)
        ad.observe(a, heard[0], felt_position=felt[0])
    assert ad.touches < 30  # the stopping rule ended it, not the budget
    assert ad.should_stop() and np.hypot(*(ad.estimate() - [-9.0, 5.0])) < 1.0
    assert ad.entropy() < np.log(ad.grid.size) and ad.posterior.n_obs == ad.touches
    tight = kbcli.Adapter.from_model(MODEL, seed=0, max_steps=2, resolution=1.0,
                                     prior_halfwidth=10.0)
    for _ in range(2):
        tight.observe(tight.suggest(), None)
    assert tight.done() and not tight.should_stop()


def test_from_model_bad_input(tmp_path):
    write_artifact(KB_ART, tmp_path / "kb.h5")
    with pytest.raises(ArtifactError, match="keyboard artifact, expected model"):
        kbcli.Adapter.from_model(tmp_path / "kb.h5")
    with pytest.raises(ArtifactError, match="no such file"):
        kbcli.Adapter.from_model(tmp_path / "missing.h5")
    with pytest.raises(ConfigError, match="unknown adapt option"):
        kbcli.Adapter.from_model(MODEL, strategy="random", colour="red")
    with pytest.raises(ConfigError, match="unknown strategy"):
        kbcli.Adapter.from_model(MODEL, strategy="psychic")
    with pytest.raises(ConfigError, match="seed or rng"):
        kbcli.Adapter.from_model(MODEL, seed=1, rng=np.random.default_rng(1))
    # the core reads no files: only kbcli.Adapter (kbcli.api) does
    with pytest.raises(ConfigError, match="needs a sound model"):
        CoreAdapter.from_model(tmp_path / "kb.h5")


@pytest.mark.parametrize("action, heard, felt, fragment", [
    ((300.0, 300.0), ("a", 100.0), None, "heard features must be"),
    ((300.0, 300.0), (60.0,), None, "must be 2 numbers"),
    ((300.0, 300.0), (60.0, np.nan), None, "all finite"),
    ((300.0, 300.0), (60.0, np.inf), None, "all finite"),
    ((5000.0, 300.0), (60.0, 100.0), None, "outside the working area"),
    ((300.0,), (60.0, 100.0), None, "two finite numbers"),
    ((300.0, 300.0), (60.0, 100.0), (np.nan, 1.0), "felt_position must be two finite"),
    ((300.0, 300.0), (60.0, 100.0), "here", "felt_position must be two"),
])
def test_observe_rejects_bad_input_and_changes_nothing(action, heard, felt, fragment):
    ad = kbcli.Adapter(MODEL, kbcli.AdapterConfig(resolution=1.0, prior_halfwidth=10.0),
                       rng=np.random.default_rng(0))
    ad.observe((330.0, 330.0), KB.features[10])
    before = ad.posterior.logp.copy()
    with pytest.raises(ObservationError, match=fragment):
        ad.observe(action, heard, felt_position=felt)
    np.testing.assert_array_equal(ad.posterior.logp, before)
    assert ad.touches == 1 and ad.posterior.n_obs == 1


def test_felt_position_is_where_the_update_happens():
    """The same sound at the same aim moves the posterior by where the robot felt it landed."""
    cfg = kbcli.AdapterConfig(resolution=1.0, prior_halfwidth=20.0)
    a = kbcli.Adapter(MODEL, cfg, rng=np.random.default_rng(0))
    b = kbcli.Adapter(MODEL, cfg, rng=np.random.default_rng(0))
    aim, heard = np.array([325.0, 325.0]), KB.features[10]
    a.observe(aim, heard)
    b.observe(aim, heard, felt_position=aim + [7.0, 0.0])
    # the hypothesis d under the felt point is a's hypothesis d - 7 px (grid step 1 px)
    diff = b.posterior.logp[:, 7:] - a.posterior.logp[:, :-7]
    np.testing.assert_allclose(diff, diff[0, 0], atol=1e-9)
    assert not np.allclose(a.posterior.logp, b.posterior.logp)


def test_detector_public_form():
    det = kbcli.Detector(detector="binomial", n_lt=100, n_st=10, threshold=0.01)
    fired = [det.update(r) for r in ["MATCH"] * 110 + ["NO_MATCH"] * 3]
    assert fired.index(True) == 111
    same = kbcli.Detector(kbcli.DetectorConfig())
    assert [same.update(x) for x in [0] * 110 + [1] * 3] == fired
    assert det.update(True) is False  # a bool: True is a failure (the warm-up restarted)
    with pytest.raises(ConfigError, match="unknown result"):
        det.update("MAYBE")
    with pytest.raises(ConfigError, match="0 \\(MATCH\\) or 1"):
        det.update(2)
    with pytest.raises(ConfigError, match="unknown detector option"):
        kbcli.Detector(window=3)
    with pytest.raises(ConfigError, match="either cfg or options"):
        kbcli.Detector(kbcli.DetectorConfig(), threshold=0.1)


def _readme_example(doc: str = "README.md") -> str:
    text = (ROOT / doc).read_text()
    m = re.search(r"<!-- api-example -->\s*```python\n(.*?)```", text, re.S)
    assert m, f"{doc} has no API example block"
    return m.group(1)


@pytest.mark.parametrize("doc", ["docs/tutorials/robot.md"])
def test_readme_api_example_runs(doc, monkeypatch, capsys):
    """The robot tutorial's example (the README points to it) drives Adapter with the bundled
    simulator and recovers the move."""
    monkeypatch.chdir(ROOT)
    exec(compile(_readme_example(doc), doc, "exec"), {"__name__": "readme"})
    out = capsys.readouterr().out
    m = re.search(r"estimate dx ([-+.\d]+), dy ([-+.\d]+)", out)
    assert m, out
    assert np.hypot(float(m.group(1)) - 12.0, float(m.group(2)) + 7.0) < 1.0
