"""Perturbation scenes, melodies, Algorithm 1, the play stage, audio and their CLI commands."""

from __future__ import annotations

import wave

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.cli import app
from kbcli.core.instrument import audio
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.instrument.melody import DEFAULT_MELODY, parse_melody
from kbcli.core.model.base import ExactModel
from kbcli.core.playing.play import MATCH, NO_MATCH, expected_failure_rate, note_classes, play
from kbcli.errors import ConfigError, OutOfReachError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.sim import SimConfig, workspace_check
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import perturb
from kbcli.stages import play as play_stage
from kbcli.stages.models import exact_artifact

KB = Keyboard(KeyboardConfig())
KB_ART = keyboard_stage.run(KeyboardConfig())
MODEL_ART = exact_artifact(KB_ART)


def scene(params=(12.0, -7.0), family="translation"):
    return perturb.run(perturb.PerturbConfig(family=family, params=params), KB_ART,
                       rng=np.random.default_rng(0))


# -- melody ------------------------------------------------------------------------------------
def test_parse_the_papers_melody():
    m = parse_melody(DEFAULT_MELODY, KB)
    assert m.notes == ("A", "D", "E", "D", "A")
    assert m.midi == (69, 62, 64, 62, 69)
    assert m.durations == (1.0, 1.0, 0.5, 2.0, 1.0)
    assert [KB.names[k] for k in m.keys] == ["A4", "D4", "E4", "D4", "A4"]
    assert parse_melody(m.text, KB) == parse_melody("A4:1 D4:1 E4:0.5 D4:2 A4:1", KB)
    assert parse_melody("C3 G3:2", KB).durations == (1.0, 2.0)


@pytest.mark.parametrize(
    ("text", "word"),
    [
        ("A:1 H:1", "'H'"),
        ("A:1 C9:1", "'C9'"),
        ("A:0", "> 0"),
        ("A:-1", "> 0"),
        ("A:x", "'x'"),
        ("A:inf", "> 0"),
        ("   ", "empty"),
        (":1", "no note"),
    ],
)
def test_bad_melody_rejected(text, word):
    with pytest.raises(ConfigError, match=word):
        parse_melody(text, KB)


# -- audio ----------------------------------------------------------------------------------------
def test_audio_lengths_pitch_and_silence():
    assert audio.midi_to_hz(69) == pytest.approx(440.0)
    assert audio.midi_to_hz(81) == pytest.approx(880.0)
    perceived = np.array([[69.0, 60.0], [np.nan, np.nan], [60.0, 120.0]])
    samples = audio.render(perceived, np.array([1.0, 2.0, 1.0]), np.array([60.0, 60.0, 60.0]),
                           sample_rate=1000)
    assert len(samples) == 1000 + 2000 + 500  # 1 beat at 60 bpm, 2 at 60, 1 at 120
    assert samples.dtype == np.float32 and np.abs(samples).max() <= 1.0
    assert np.all(samples[1000:3000] == 0)  # the missed note is silence
    assert np.abs(samples[:1000]).max() > 0.05
    pcm = np.frombuffer(audio.to_pcm16(samples), dtype="<i2")
    np.testing.assert_allclose(pcm / 32767, samples, atol=1e-4)


# -- perturb ------------------------------------------------------------------------------------
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), category=st.sampled_from(sorted(perturb.CATEGORIES)),
       family=st.sampled_from(["translation", "rigid"]))
def test_category_draws_stay_in_their_ring(seed, category, family):
    lo, hi = perturb.CATEGORIES[category]
    p = perturb.draw(category, family, 20, rng=np.random.default_rng(seed))
    d = np.hypot(p[:, -2], p[:, -1])  # the size is the Euclidean norm of the translation
    assert p.shape == (20, 2 if family == "translation" else 3)
    assert np.all((d > lo) & (d <= hi))
    assert all(perturb.size_category(row) == category for row in p)
    if family == "rigid":
        assert np.all(np.abs(p[:, 0]) <= 5.0)


def test_size_categories_are_euclidean_and_uniform_over_the_ring():
    # (8, 8) is 11.3 px: medium, though neither axis exceeds 10 px
    assert perturb.size_category((8.0, 8.0)) == "medium"
    assert perturb.size_category((0.0, 10.0)) == "small"
    assert perturb.size_category((30.0, 30.0)) is None  # 42.4 px: beyond large
    p = perturb.draw("large", "translation", 4000, rng=np.random.default_rng(5))
    r = np.hypot(*p.T)
    # uniform over the ring 20 < r <= 40: P(r <= 30) = (30^2 - 20^2) / (40^2 - 20^2) = 5/12
    assert abs(np.mean(r <= 30) - 5 / 12) < 0.03
    # every direction: the four quadrants hold a quarter each
    quad = (p[:, 0] > 0) * 2 + (p[:, 1] > 0)
    assert np.all(np.abs(np.bincount(quad, minlength=4) / len(p) - 0.25) < 0.03)


def test_scene_artifact_holds_the_truth(tmp_path):
    art = scene((3.0, 12.0, -7.0), "rigid")
    assert art.kind == "scene" and art.config["family"] == "rigid"
    assert art.config["params"] == [3.0, 12.0, -7.0]
    family, params = perturb.pose(art)
    assert family == "rigid" and np.allclose(params, [3, 12, -7])
    write_artifact(art, tmp_path / "s.h5")
    back = read_artifact(tmp_path / "s.h5", "scene")
    assert back.config == art.config and back.inputs["keyboard"]["kind"] == "keyboard"
    drawn = perturb.run(perturb.PerturbConfig(category="medium"), KB_ART,
                        rng=np.random.default_rng(4), seed=4)
    again = perturb.run(perturb.PerturbConfig(category="medium"), KB_ART,
                        rng=np.random.default_rng(4), seed=4)
    assert drawn.seed == 4 and drawn.config["params"] == again.config["params"]
    assert 10 < np.abs(drawn.config["params"]).max() <= 20


def test_out_of_reach_refused_and_large_moves_fit():
    with pytest.raises(OutOfReachError, match="outside the arm's reach"):
        perturb.check_reach(KB, "translation", np.array([300.0, 0.0]), SimConfig())
    for params in ([40.0, 40.0], [-40.0, 40.0], [40.0, -40.0], [-40.0, -40.0]):
        perturb.check_reach(KB, "translation", np.array(params), SimConfig())
    pts, keys = perturb.key_outline(KB)
    # every key's outline, every 5 px: a 50 px square has 40 points
    assert pts.shape == (40 * KB.n_keys, 2) and workspace_check(SimConfig(), pts).all()
    np.testing.assert_array_equal(np.bincount(keys), np.full(KB.n_keys, 40))


@pytest.mark.parametrize(
    ("kw", "word"),
    [
        ({"params": (1.0, 2.0), "category": "small"}, "not both"),
        ({}, "either"),
        ({"params": (1.0,)}, "takes 2 parameters"),
        ({"category": "huge"}, "valid: small, medium, large"),
        ({"family": "affine", "params": (1.0, 2.0)}, "unknown transform family"),
    ],
)
def test_bad_perturb_config(kw, word):
    with pytest.raises(ConfigError, match=word):
        perturb.PerturbConfig(**kw)


# -- Algorithm 1 ------------------------------------------------------------------------------------
def test_play_without_a_move_always_matches_and_loops():
    model = ExactModel(KB)
    melody = parse_melody(DEFAULT_MELODY, KB)
    rng = np.random.default_rng(0)

    def touch(actions):
        return actions, KB.perceive(actions, rng=rng)

    steps = [next(it) for it in [play(model, melody, touch, rng=rng)] for _ in range(12)]
    assert all(s.result == MATCH for s in steps)
    assert [s.target for s in steps] == [0, 1, 2, 3, 4, 0, 1, 2, 3, 4, 0, 1]
    classes = note_classes(model, melody)
    assert [s.cls for s in steps[:5]] == list(classes) == [k + 1 for k in melody.keys]


def test_play_restarts_at_note_zero_on_silence_and_on_a_wrong_melody_note():
    model = ExactModel(KB)
    melody = parse_melody(DEFAULT_MELODY, KB)
    rng = np.random.default_rng(0)
    silent = play(model, melody, lambda a: (a, np.full((1, 2), np.nan)), rng=rng)
    steps = [next(silent) for _ in range(5)]
    assert all(s.result == NO_MATCH and s.target == 0 and s.heard == -1 for s in steps)
    # the finger always lands on D4, a note of the melody but not the one aimed for at first
    d4 = KB.features[melody.keys[1]][None]
    wrong = play(model, melody, lambda a: (a, d4.copy()), rng=rng)
    first = next(wrong)
    assert first.target == 0 and first.result == NO_MATCH and first.heard == 1
    assert next(wrong).target == 0


def test_expected_failure_rate_matches_the_geometry():
    model = ExactModel(KB)
    melody = parse_melody(DEFAULT_MELODY, KB)
    params = np.array([[12.0, -7.0], [0.0, 0.0], [60.0, 0.0]])
    r = expected_failure_rate(model, KB, melody, "translation", params,
                              rng=np.random.default_rng(0), n_samples=4000)
    assert r[0] == pytest.approx(1 - (1 - 12 / 50) * (1 - 7 / 50), abs=0.02)
    assert r[1] == 0.0 and r[2] == 1.0


# -- the play stage --------------------------------------------------------------------------------
def test_play_stage_is_deterministic_and_fails_after_the_move():
    cfg = play_stage.PlayConfig(steps=120, perturb_at=60)
    a = play_stage.run(cfg, MODEL_ART, scene(), rng=np.random.default_rng(5), seed=5)
    b = play_stage.run(cfg, MODEL_ART, scene(), rng=np.random.default_rng(5), seed=5)
    for name in ("action", "landed", "perceived", "target", "result", "heard"):
        np.testing.assert_array_equal(a.array(name), b.array(name))
    res = a.array("result")
    assert res[:60].sum() == 0 and res[60:].mean() > 0.15
    assert a.attrs["failure_rate_before"] == 0.0 and a.attrs["perturb_at"] == 60
    assert a.array("perturbed").sum() == 60 and a.seed == 5
    assert set(a.inputs) == {"model", "scene"}
    # the robot's draws do not depend on the world: same actions before the move without a scene
    still = play_stage.run(play_stage.PlayConfig(steps=60), MODEL_ART, rng=np.random.default_rng(5))
    np.testing.assert_array_equal(still.array("action"), a.array("action")[:60])


def test_play_stage_in_dynamics_mode():
    cfg = play_stage.PlayConfig(steps=12, perturb_at=6, mode="dynamics", reach_noise=0.5)
    art = play_stage.run(cfg, MODEL_ART, scene((30.0, 30.0)), rng=np.random.default_rng(1))
    landed, action = art.array("landed"), art.array("action")
    assert np.all(np.hypot(*(landed - action).T) < 5.0)  # the arm lands near its targets
    assert art.config["sim"]["mode"] == "dynamics"


def test_play_stage_bad_input():
    with pytest.raises(ConfigError, match="needs a scene"):
        play_stage.run(play_stage.PlayConfig(steps=10, perturb_at=5), MODEL_ART,
                       rng=np.random.default_rng(0))
    with pytest.raises(ConfigError, match="perturb_at must be a step"):
        play_stage.PlayConfig(steps=10, perturb_at=10)
    other_kb = keyboard_stage.run(KeyboardConfig(rows=3))
    other = perturb.run(perturb.PerturbConfig(params=(1.0, 1.0)), other_kb,
                        rng=np.random.default_rng(0))
    with pytest.raises(ConfigError, match="different keyboard"):
        play_stage.run(play_stage.PlayConfig(steps=10), MODEL_ART, other,
                       rng=np.random.default_rng(0))


# -- CLI -----------------------------------------------------------------------------------------------
@pytest.fixture
def model_path(tmp_path):
    path = tmp_path / "model.h5"
    write_artifact(MODEL_ART, path)
    return path


def test_cli_perturb_play_detect_plot(runner, kb_path, model_path, tmp_path):
    s, h, w, d, png = (tmp_path / n for n in ("s.h5", "h.h5", "h.wav", "d.h5", "p.png"))
    r = runner.invoke(app, ["perturb", "--keyboard", str(kb_path), "--dx", "12", "--dy", "-7",
                            "--angle", "3", "-o", str(s)])
    assert r.exit_code == 0, r.output
    assert read_artifact(s, "scene").config["family"] == "rigid"
    r = runner.invoke(app, ["play", "--model", str(model_path), "--scene", str(s), "--steps", "150",
                            "--perturb-at", "120", "--seed", "3", "-o", str(h), "--wav", str(w)])
    assert r.exit_code == 0, r.output
    assert "after" in r.output and h.exists()
    with wave.open(str(w)) as f:
        assert f.getnchannels() == 1 and f.getsampwidth() == 2
        assert f.getframerate() == audio.SAMPLE_RATE and f.getnframes() > audio.SAMPLE_RATE * 30
    r = runner.invoke(app, ["detect", str(h), "-o", str(d)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["plot", "play", str(h), "--detection", str(d), "-o", str(png)])
    assert r.exit_code == 0, r.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_perturb_category(runner, kb_path, tmp_path):
    out = tmp_path / "s.h5"
    r = runner.invoke(app, ["perturb", "--keyboard", str(kb_path), "--category", "large",
                            "--family", "rigid", "--seed", "9", "-o", str(out)])
    assert r.exit_code == 0, r.output
    art = read_artifact(out, "scene")
    assert art.seed == 9 and art.config["category"] == "large" and len(art.config["params"]) == 3


@pytest.mark.parametrize(
    ("args", "word"),
    [
        (["--dx", "400", "--dy", "0"], "outside the arm's reach"),
        (["--dx", "5", "--category", "small"], "not both"),
        ([], "give a displacement"),
        (["--category", "huge"], "unknown category"),
        (["--dx", "1", "--angle", "2", "--family", "translation"], "--angle makes a rigid move"),
    ],
)
def test_cli_perturb_bad_input(runner, kb_path, tmp_path, args, word):
    out = tmp_path / "s.h5"
    r = runner.invoke(app, ["perturb", "--keyboard", str(kb_path), *args, "-o", str(out)])
    assert r.exit_code == 1
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and word in lines[0] and not out.exists()


@pytest.mark.parametrize(
    ("args", "word"),
    [
        (["--melody", "A:1 H:1"], "unknown note 'H'"),
        (["--melody", "A:1 C9:1"], "'C9' is not on the keyboard"),
        (["--perturb-at", "5"], "needs a scene"),
        (["--mode", "teleport"], "unknown sim mode"),
    ],
)
def test_cli_play_bad_input(runner, model_path, tmp_path, args, word):
    out, wav = tmp_path / "h.h5", tmp_path / "h.wav"
    r = runner.invoke(app, ["play", "--model", str(model_path), "--steps", "20", *args,
                            "-o", str(out), "--wav", str(wav)])
    assert r.exit_code == 1
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and word in lines[0]
    assert not out.exists() and not wav.exists()


def test_cli_play_wrong_kind(runner, kb_path, tmp_path):
    out = tmp_path / "h.h5"
    r = runner.invoke(app, ["play", "--model", str(kb_path), "-o", str(out)])
    assert r.exit_code == 1 and "expected model" in r.output and not out.exists()


def test_cli_plot_play_refuses_a_detection_of_another_history(runner, model_path, tmp_path):
    h1, h2, d, png = (tmp_path / n for n in ("h1.h5", "h2.h5", "d.h5", "p.png"))
    for seed, h in ((1, h1), (2, h2)):
        r = runner.invoke(app, ["play", "--model", str(model_path), "--steps", "30", "--seed",
                                str(seed), "-o", str(h)])
        assert r.exit_code == 0, r.output
    assert runner.invoke(app, ["detect", str(h1), "-o", str(d)]).exit_code == 0
    r = runner.invoke(app, ["plot", "play", str(h2), "--detection", str(d), "-o", str(png)])
    assert r.exit_code == 1 and "another history" in r.output and not png.exists()
    r = runner.invoke(app, ["plot", "play", str(h1), "-o", str(png)])
    assert r.exit_code == 0 and png.exists()
