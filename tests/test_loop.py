"""The closed loop (``kbcli run``): play, detect the move, adapt, resume with corrected actions."""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.cli import app
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.detection.detectors import DetectorConfig
from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.melody import parse_melody
from kbcli.core.model.base import ExactModel
from kbcli.core.playing.loop import ADAPT, PLAY, closed_loop
from kbcli.errors import ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.sim import IdealReacher, SimConfig, World
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import models, perturb
from kbcli.stages.run import LoopConfig, LoopSession

KB_ART = keyboard_stage.run(KeyboardConfig())
MODEL_ART = models.exact_artifact(KB_ART)


def _scene(params):
    return perturb.run(perturb.PerturbConfig(params=params), KB_ART, rng=np.random.default_rng(0))


def test_loop_detects_adapts_and_restores_success():
    s = LoopSession(LoopConfig(steps=450), MODEL_ART, _scene((12.0, -7.0)), rng=np.random.default_rng(3))
    steps = list(s)
    a = s.summary()
    assert a["success_before"] >= 0.97
    assert a["detected_at"] is not None and 1 <= a["detection_delay"] <= 30
    assert a["false_alarms"] == 0
    assert a["success_after_perturbation"] < 0.9
    assert a["success_after_adaptation"] >= a["success_before"] - 0.05
    assert a["correction_error_px"] < 1.5
    phases = np.array([st.phase for st in steps])
    assert (phases == PLAY).sum() == 450 and 1 <= (phases == ADAPT).sum() <= 40


def test_loop_is_deterministic():
    # the adaptation on a 2 px hypothesis grid (not 0.5 px): the same loop, detection and
    # adaptation (one, here), tables 16 times smaller (2.6 s -> 0.2 s a session)
    cfg = LoopConfig(steps=300, adapt={"stop": True, "resolution": 2.0})
    arts = []
    for _ in range(2):
        s = LoopSession(cfg, MODEL_ART, _scene((-15.0, 9.0)), rng=np.random.default_rng(11))
        list(s)
        arts.append(s.artifact())
    assert arts[0].attrs["adaptations"] >= 1  # the adaptation's touches are compared too
    for key in ("action", "landed", "result", "correction"):
        np.testing.assert_array_equal(arts[0].data["steps"][key], arts[1].data["steps"][key])


def test_robot_side_learns_only_through_touch():
    """closed_loop is handed a touch callback only: it recovers whatever pose that world has."""
    kb = Keyboard(KeyboardConfig())
    model = ExactModel(kb)
    world = World(keyboard=kb, reacher=IdealReacher(SimConfig()))
    rng_world = np.random.default_rng(1)
    truth = np.array([-22.0, 5.5])

    def touch(actions):
        if world.touches >= 150:
            world.pose = truth
        return world.touch(actions, rng_world)

    steps = list(closed_loop(model, parse_melody("A:1 D:1 E:0.5 D:2 A:1", kb), touch, play_steps=300,
                             detector=DetectorConfig(), adapter=AdapterConfig(), max_adapt_steps=40,
                             rng=np.random.default_rng(2)))
    final = steps[-1].correction
    assert np.hypot(*(final - truth)) < 1.5
    # corrected actions land on the intended keys: T(a) for the moved keyboard
    late = [s for s in steps[-50:] if s.phase == PLAY]
    assert np.mean([s.result for s in late]) <= 0.05
    assert transforms.check_family("translation") == ("dx", "dy")


def test_perturb_before_detector_warmup_is_refused():
    with pytest.raises(ConfigError, match="warm-up"):
        LoopConfig(perturb_at=50)
    with pytest.raises(ConfigError, match="steps"):
        LoopConfig(steps=0)


def test_cli_run_and_plot(runner, tmp_path):
    write_artifact(KB_ART, tmp_path / "kb.h5")
    kb = read_artifact(tmp_path / "kb.h5")
    write_artifact(models.exact_artifact(kb), tmp_path / "m.h5")
    write_artifact(_scene((8.0, 6.0)), tmp_path / "s.h5")
    r = runner.invoke(app, ["run", "--model", str(tmp_path / "m.h5"), "--scene", str(tmp_path / "s.h5"),
                            "--steps", "300", "-o", str(tmp_path / "loop.h5")])
    assert r.exit_code == 0, r.output
    assert "after adaptation" in r.output
    assert "family:" not in r.stderr  # the usual family goes without saying (issue 40)
    art = read_artifact(tmp_path / "loop.h5", "closed_loop")
    spans = art.attrs["adaptation_list"]
    assert len(spans) == art.attrs["adaptations"] >= 1
    assert sum(s["touches"] for s in spans) == art.attrs["adapt_touches"]
    for i, s in enumerate(spans, 1):  # one line per adaptation
        assert f"adaptation {i}: the detector fired at touch {s['fired_at']}" in r.output
    art = read_artifact(tmp_path / "loop.h5", "closed_loop")
    assert art.inputs["model"]["sha256"] and art.inputs["scene"]["sha256"]
    r = runner.invoke(app, ["plot", "run", str(tmp_path / "loop.h5"), "-o", str(tmp_path / "loop.png")])
    assert r.exit_code == 0 and (tmp_path / "loop.png").exists()


def test_cli_run_bad_inputs(runner, tmp_path):
    write_artifact(KB_ART, tmp_path / "kb.h5")
    write_artifact(_scene((8.0, 6.0)), tmp_path / "s.h5")
    out = tmp_path / "loop.h5"
    r = runner.invoke(app, ["run", "--model", str(tmp_path / "kb.h5"), "--scene", str(tmp_path / "s.h5"), "-o", str(out)])
    assert r.exit_code == 1 and "expected model" in r.output and not out.exists()
    write_artifact(models.exact_artifact(read_artifact(tmp_path / "kb.h5")), tmp_path / "m.h5")
    r = runner.invoke(app, ["run", "--model", str(tmp_path / "m.h5"), "--scene", str(tmp_path / "s.h5"),
                            "--strategy", "psychic", "-o", str(out)])
    assert r.exit_code == 1 and "psychic" in r.output and not out.exists()
    r = runner.invoke(app, ["run", "--model", str(tmp_path / "m.h5"), "--scene", str(tmp_path / "s.h5"),
                            "--perturb-at", "20", "-o", str(out)])
    assert r.exit_code == 1 and "warm-up" in r.output and not out.exists()


def _two_adaptations():
    """The golden closed loop with its one adaptation split in two by play touches (as a session
    looks when the detector fires again after the first adaptation)."""
    from pathlib import Path

    art = read_artifact(Path(__file__).resolve().parent.parent / "data" / "golden" /
                        "closed_loop.h5")
    phase = np.asarray(art.data["steps"]["phase"]).astype(int)
    t = np.flatnonzero(phase == ADAPT)
    assert len(t) >= 4
    phase[t[len(t) // 2 - 1]] = PLAY  # one play touch inside the block: two adaptations
    art.data["steps"]["phase"] = phase
    return art, [(int(t[0]), int(t[len(t) // 2 - 2])), (int(t[len(t) // 2]), int(t[-1]))]


def test_adaptation_blocks_finds_every_run_of_adaptation_touches():
    from kbcli.core.playing.loop import adaptation_blocks

    phase = np.zeros(50, int)
    phase[10:14] = ADAPT
    phase[30:31] = ADAPT
    phase[45:] = ADAPT
    assert adaptation_blocks(phase) == [(10, 13), (30, 30), (45, 49)]
    assert adaptation_blocks(np.zeros(5, int)) == []


def test_plot_run_and_animate_show_every_adaptation(tmp_path, monkeypatch):
    """Issue 40: a second adaptation had no detector line, and animate drew one band over the
    play touches between two adaptations."""
    import matplotlib.pyplot as plt

    from kbcli.viz import loop as viz_loop
    from kbcli.viz.animator import Animator
    from kbcli.viz.replay import load_replay

    art, blocks = _two_adaptations()
    figs = []
    monkeypatch.setattr(viz_loop, "save", lambda fig, path: figs.append(fig))
    viz_loop.plot_loop(art.data["steps"], art.attrs, keyboard_stage.load(art),
                       tmp_path / "r.png", config=art.config)
    success = figs[0].axes[0]

    def bands(ax):
        return sorted((round(p.get_x() + 0.5), round(p.get_x() + p.get_width() - 0.5))
                      for p in ax.patches if p.get_width() > 0)

    assert bands(success) == blocks
    fired = sorted(round(ln.get_xdata()[0]) for ln in success.lines
                   if ln.get_color() == "crimson" and len(set(ln.get_xdata())) == 1)
    assert fired == [a - 1 for a, _ in blocks]
    assert "2 adaptations" in " ".join(t.get_text() for t in success.get_legend().get_texts())
    plt.close(figs[0])
    anim = Animator(load_replay(art), dpi=40)
    curves = anim.ax_c1  # touches count from 1 there
    assert bands(curves) == [(a + 1, b + 1) for a, b in blocks]


def test_run_says_when_the_model_is_weak(capsys):
    """Issue 40: the tour's model played 89 % before anything moved, and nothing said why the
    detector then fired twice."""
    from pathlib import Path

    from kbcli.cli.run import WEAK_MODEL, _report_loop

    def attrs(before):
        ad = {"fired_at": 214, "first": 215, "touches": 20, "correction": {"dx": 11.6, "dy": -7.0},
              "error_px": 0.4}
        again = {**ad, "fired_at": 387, "first": 388, "touches": 17}
        return {"success_before": before, "success_after_perturbation": 0.7,
                "success_after_adaptation": 0.9, "perturbed_at": 200, "detected_at": 214,
                "truth": {"dx": 12.0, "dy": -7.0}, "adapt_touches": 37,
                "adaptation_list": [ad, again]}

    _report_loop(attrs(WEAK_MODEL - 0.06), Path("l.h5"))
    cap = capsys.readouterr()
    assert "a weak model" in cap.err and "--budget" in cap.err
    assert "adaptation 1: the detector fired at touch 214 (15 touches after the move)" in cap.out
    assert "adaptation 2: the detector fired at touch 387 (again, 153 touches after " \
           "adaptation 1)" in cap.out
    _report_loop(attrs(1.0), Path("l.h5"))
    assert "weak" not in capsys.readouterr().err
