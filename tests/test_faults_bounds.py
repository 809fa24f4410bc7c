"""Every count a user can type is bounded before any work (issue 29, item 2): the benchmarks'
counts, the cover of ``learn --explore-radius``, the experiments of a whole evaluation or sweep;
each bound is named in the option's --help. Found by tools/fault_battery.py (the bench cases ran
at full CPU until killed)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from helpers import one_line_error

from kbcli.cli import app
from kbcli.core.model.explore import MAX_COVER_POINTS, check_cover
from kbcli.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
MODEL = str(ROOT / "data" / "golden" / "model.h5")
KB = str(ROOT / "data" / "golden" / "keyboard.h5")
BIG = "1000000000"


@pytest.mark.parametrize(("args", "words"), [
    (["bench", "arm", "--reaches", BIG], "--reaches must be a whole number in [1, 100000]"),
    (["bench", "detect", "--streams", BIG], "--streams must be a whole number in [1, 100000]"),
    (["bench", "detect", "--tune-actions", "1" + "0" * 12], "--tune-actions"),
    (["bench", "detect", "--horizon", BIG], "--horizon"),
    (["bench", "adapt", "--experiments", BIG], "--experiments must be a whole number in [1, 10000]"),
    (["bench", "robust", "--experiments", BIG], "--experiments"),
    (["bench", "robust", "-T", BIG], "--max-steps"),
    (["bench", "learn", "--seeds", BIG], "--seeds must be a whole number in [1, 1000]"),
    (["bench", "learn", "--boundary-budget", BIG], "--boundary-budget"),
    (["bench", "reliability", "--seeds", BIG], "--seeds"),
    (["bench", "reliability", "--budgets", BIG], "--budgets must be whole numbers in [1, 20000]"),
    (["bench", "animate", "--repeats", BIG], "--repeats must be a whole number in [1, 100]"),
    (["bench", "layouts", "--seeds", BIG], "--seeds"),
])
def test_bench_counts_refused_in_one_line(runner, tmp_path, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    one_line_error(runner.invoke(app, args), words)
    assert list(tmp_path.iterdir()) == []


def test_bench_workers_capped_with_a_note(capsys):
    from kbcli.cli.options import cap_workers
    from kbcli.io.processes import usable_cores

    assert cap_workers(10_000, "--workers") == usable_cores()
    assert "kbcli: --workers 10000 is more than" in capsys.readouterr().err


def test_explore_radius_cover_bounded():
    area = (150.0, 200.0, 650.0, 500.0)
    check_cover(area, 20.0)  # the default: about 9,400 points
    with pytest.raises(ConfigError, match=f"more than {MAX_COVER_POINTS:,}; use at least 1.9 px"):
        check_cover(area, 1e-6)


def test_learn_tiny_explore_radius_refused(runner, tmp_path):
    out = tmp_path / "m.h5"
    r = runner.invoke(app, ["learn", "--keyboard", KB, "--explore-radius", "1e-6", "--budget",
                            "20", "-o", str(out)])
    one_line_error(r, "explore_radius 1e-06 px", "use at least")
    assert list(tmp_path.iterdir()) == []


def test_evaluate_total_experiments_refused_before_planning(runner, tmp_path):
    r = runner.invoke(app, ["evaluate", "--model", MODEL, "--experiments", "10000", "-o",
                            str(tmp_path / "ev.h5")])
    one_line_error(r, "evaluate: 1,760,000 experiments in all, more than 1,000,000")
    assert list(tmp_path.iterdir()) == []


def test_quality_total_experiments_refused(tmp_path):
    from kbcli.stages.quality import QualityConfig
    from kbcli.stages.quality.plan import plan

    with pytest.raises(ConfigError, match="quality: .* experiments in all, more than 1,000,000"):
        plan(QualityConfig().with_overrides(experiments=10_000, budgets=None))


def test_quality_sweep_size_refused_before_any_model_is_learned(runner, tmp_path):
    """The sweep's total was checked after the learning phase, and 5000 budgets were taken: the
    battery's quality run learned models until it was killed."""
    golden = str(ROOT / "pipelines" / "golden.toml")
    base = ["quality", "--config", golden, "--keyboard", KB, "-o", str(tmp_path / "q.h5")]
    r = runner.invoke(app, [*base, "--budgets", ",".join(map(str, range(10, 5010)))])
    one_line_error(r, "quality.budgets must list at most 100 budgets, got 5000")
    r = runner.invoke(app, ["quality", "--keyboard", KB, "-o", str(tmp_path / "q.h5"),
                            "--experiments", "10000"])  # (the default sweep's config)
    one_line_error(r, "quality: ", "experiments in all, more than 1,000,000")
    assert list(tmp_path.iterdir()) == []


def test_snapshots_note_stays_short(runner, tmp_path):
    r = runner.invoke(app, ["adapt", "--model", MODEL, "--scene", str(ROOT / "data" / "golden" /
                                                                       "scene.h5"),
                            "-T", "2", "--resolution", "2", "--prior-halfwidth", "15",
                            "--snapshots", ",".join(map(str, range(2000))), "-o",
                            str(tmp_path / "r.h5")])
    assert r.exit_code == 0, r.output
    note = [ln for ln in r.output.splitlines() if "note:" in ln]
    assert len(note) == 1 and "(1997 steps) beyond --max-steps 2" in note[0] and len(note[0]) < 200


COUNTS = ["keyboard", "learn", "play", "detect", "adapt", "run", "evaluate", "quality", "serve",
          "bench arm", "bench learn", "bench reliability", "bench detect", "bench adapt",
          "bench robust", "bench evaluate", "bench animate", "bench layouts"]
#: Counts bounded by another value the help names (fewer than --steps, the run's touches).
RELATIVE = {"--perturb-at", "--checkpoint-every", "--seed", "--port", "--dpi", "--max-frames"}


@pytest.mark.parametrize("command", COUNTS)
def test_every_count_names_its_bound_in_help(runner, command):
    out = runner.invoke(app, [*command.split(), "--help"], terminal_width=200).output
    for opt in re.split(r"\n  (?=-)", out.split("Options:")[1]):
        head = opt.split()[:3]
        names = [w.rstrip(",") for w in head if w.startswith("-")]
        if not any(w.startswith("<int") for w in head) or RELATIVE & set(names):
            continue
        text = " ".join(opt.split())
        assert re.search(r"at most (\d|the number of cores)", text), text


@pytest.mark.parametrize("line", ['{"op": ' + "[" * 30_000 + "]" * 30_000 + "}",
                                  "[" * 60_000 + "]" * 60_000])
def test_serve_deeply_nested_json_is_an_error_reply(line):
    """A hostile robot's deeply nested JSON (within the line limit) is refused like any bad
    message, never a RecursionError traceback that ends the session (found by the battery)."""
    import numpy as np

    from kbcli.io.artifact import read_artifact
    from kbcli.stages.serve import ServeConfig, Session

    session = Session(ServeConfig.from_dict({"resolution": 2.0, "prior_halfwidth": 15.0}),
                      read_artifact(MODEL), rng=np.random.default_rng(0), seed=0)
    reply = session.handle(line.encode())
    assert reply["type"] == "error" and "nested too deeply" in reply["error"]
    assert session.handle(b'{"op": "state"}')["type"] != "error"  # the session goes on


@pytest.mark.parametrize("args", [["inspect", "{f}"],
                                  ["adapt", "--model", "{f}", "--scene", MODEL, "-o", "{o}"],
                                  ["report", "{f}", "-o", "{o}"]])
def test_an_input_artifact_that_is_a_fifo_is_refused_not_waited_on(runner, tmp_path, args):
    """A FIFO given as an artifact blocked the read forever (found by the battery)."""
    import os

    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    r = runner.invoke(app, [a.format(f=fifo, o=tmp_path / "out") for a in args])
    one_line_error(r, f"{fifo}: is a FIFO, expected a kbcli artifact")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


@pytest.mark.parametrize(("args", "words"), [
    (["--layout", "pads", "--pad-radius", "1e-9"], "pad_radius (1e-09) must be at least 0.57 px"),
    (["--key-size", "1e-9"], "key 0 (C3) has an area of 1e-18 px^2, at least 1 needed"),
    (["--layout", "hex", "--key-size", "0.5"], "at least 1 needed"),
])
def test_keys_too_small_to_touch_refused(runner, tmp_path, args, words):
    """A pad of radius 1e-9 px made a keyboard no touch could find (found by the battery)."""
    r = runner.invoke(app, ["keyboard", *args, "-o", str(tmp_path / "k.h5")])
    one_line_error(r, words)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("melody", "words"), [
    (" ".join(["A:1"] * 5000), "play.melody must be at most 256 notes, got 5000"),
    ("A:" + "1" * 17000, "at most 256 notes of at most 64 characters each (16384 in all)"),
])
def test_long_melody_refused_in_notes(runner, tmp_path, melody, words):
    """The melody's bound is counted in notes, the unit its --help uses (it said characters)."""
    r = runner.invoke(app, ["play", "--model", MODEL, "--melody", melody, "-o",
                            str(tmp_path / "h.h5")])
    one_line_error(r, words)
    assert list(tmp_path.iterdir()) == []
