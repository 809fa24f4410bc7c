"""The bad-input battery: every case is refused cleanly.

Clean means: exit 1, exactly one line on stderr starting ``kbcli: error:`` and naming what is wrong,
nothing on stdout, no traceback, and no file written or changed. The cases cover the ones a new user
met (an output that is an input, a model that heard no sound, huge melodies and WAVs, folders that
cannot be created, damaged artifacts) and the usual mistakes with every command.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from kbcli.cli import app
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.sim import SimConfig
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "data" / "golden"
GOLDEN_TOML = ROOT / "pipelines" / "golden.toml"


def _edit(src: Path, dst: Path, fn) -> None:
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        fn(f)


def _replace(f: h5py.File, name: str, value) -> None:
    del f[name]
    f.create_dataset(name, data=value)


@pytest.fixture(scope="module")
def damaged(tmp_path_factory) -> dict[str, Path]:
    """Artifacts a user might hold: damaged, from elsewhere, or made by an older kbcli."""
    d = tmp_path_factory.mktemp("damaged")
    files = {}

    def add(name, src, fn):
        files[name] = d / f"{name}.h5"
        _edit(GOLDEN / f"{src}.h5", files[name], fn)

    add("model_no_group", "model", lambda f: f.__delitem__("model"))
    add("model_no_labels", "model", lambda f: f.__delitem__("model/labels"))
    add("history_short_target", "history",
        lambda f: _replace(f, "target", f["target"][:-5]))
    add("history_text_target", "history",
        lambda f: _replace(f, "target", np.array(["x"] * len(f["target"]), dtype=object).astype(
            h5py.string_dtype())))
    add("history_target_out_of_range", "history",
        lambda f: _replace(f, "target", f["target"][()] + 100))
    add("loop_no_attrs", "closed_loop", lambda f: f.attrs.__delitem__("attrs"))
    add("loop_2d_phase", "closed_loop",
        lambda f: _replace(f, "steps/phase", f["steps/phase"][()].reshape(-1, 1)))
    add("eval_no_pvalues", "evaluation", lambda f: f.__delitem__("pvalues"))
    def first_rmse(f):
        names = []
        f["curves"].visit(lambda n: names.append(n) if n.endswith("/rmse") else None)
        del f["curves/" + names[0]]

    add("eval_no_rmse", "evaluation", first_rmse)
    add("run_no_errors", "run", lambda f: f.__delitem__("errors"))
    add("detection_no_score", "detection", lambda f: f.__delitem__("score"))
    add("newer_schema", "keyboard", lambda f: f.attrs.__setitem__("schema_version", 99))
    add("attrs_cut", "history",
        lambda f: f.attrs.__setitem__("attrs", f.attrs["attrs"][: len(f.attrs["attrs"]) // 2]))
    add("kind_number", "keyboard", lambda f: f.attrs.__setitem__("kind", 3))
    add("config_missing", "scene", lambda f: f.attrs.__delitem__("config"))

    def far_angle(f):
        cfg = json.loads(f.attrs["config"])
        cfg.update(family="rigid", params=[400.0, 1.0, 1.0])
        f.attrs["config"] = json.dumps(cfg)

    add("scene_angle_400", "scene", far_angle)
    # a model that heard no sound (what `learn --budget 1` wrote before it was refused)
    kb = keyboard_stage.run(KeyboardConfig())
    write_artifact(kb, d / "kb.h5")
    mute = learn_stage.run(learn_stage.LearnConfig(budget=1, sim=SimConfig()),
                           read_artifact(d / "kb.h5"), rng=np.random.default_rng(0), seed=0)
    write_artifact(mute, d / "model_mute.h5")
    files["model_mute"] = d / "model_mute.h5"
    (d / "not_hdf5.h5").write_text("hello")
    files["not_hdf5"] = d / "not_hdf5.h5"
    data = (GOLDEN / "model.h5").read_bytes()
    (d / "cut.h5").write_bytes(data[: len(data) // 3])
    files["cut"] = d / "cut.h5"
    (d / "bad.toml").write_text("[adapt\nstrategy = 'x'\n")
    files["bad_toml"] = d / "bad.toml"
    (d / "no_table.toml").write_text("[other]\nx = 1\n")
    files["no_table"] = d / "no_table.toml"
    (d / "unknown_key.toml").write_text("[evaluate]\nexperimentz = 3\n")
    files["unknown_key"] = d / "unknown_key.toml"
    (d / "rigid_far.toml").write_text(
        GOLDEN_TOML.read_text().replace('family = "translation"', 'family = "rigid"').replace(
            "displacements = [[3.76, 1.37]]", "displacements = [[270.0, 3.76, 1.37]]").replace(
            "displacements = [[-13.59, 6.34]]", "displacements = [[1.0, -13.59, 6.34]]").replace(
            "displacements = [[19.15, 16.07]]", "displacements = [[1.0, 19.15, 16.07]]"))
    files["rigid_far"] = d / "rigid_far.toml"
    return files


M, S, K = "{golden}/model.h5", "{golden}/scene.h5", "{golden}/keyboard.h5"
H, D = "{golden}/history.h5", "{golden}/detection.h5"

#: (argv, fragments the one error line must hold). {golden}: data/golden; {out}: a fresh folder;
#: {name}: a damaged file of the fixture above.
CASES: list[tuple[list[str], list[str]]] = [
    # the cases of the issue
    (["learn", "--keyboard", K, "--budget", "1", "-o", "{out}/m.h5"], ["sound class", "--budget"]),
    (["adapt", "--model", "{model_mute}", "--scene", S, "-o", "{out}/r.h5"], ["sound class"]),
    (["evaluate", "--model", "{model_mute}", "--config", str(GOLDEN_TOML), "-o", "{out}/e.h5"],
     ["sound class"]),
    (["play", "--model", "{model_mute}", "-o", "{out}/h.h5"], ["sound class"]),
    (["run", "--model", "{model_mute}", "--scene", S, "-o", "{out}/l.h5"], ["sound class"]),
    (["play", "--model", M, "--melody", "A:1e9", "--wav", "{out}/x.wav", "-o", "{out}/h.h5"],
     ["beats"]),
    (["play", "--model", M, "--melody", "A:16", "--wav", "{out}/x.wav", "-o", "{out}/h.h5"],
     ["--wav", "s a WAV may hold"]),
    (["play", "--model", M, "--melody", " ".join(["A:1"] * 300), "-o", "{out}/h.h5"],
     ["300 notes", "256"]),
    (["report", str(GOLDEN / "evaluation.h5"), "-o", "/proc/rep"], ["/proc/rep", "cannot"]),
    (["evaluate", "--model", M, "--config", str(GOLDEN_TOML), "-o", "/proc/x.h5"],
     ["/proc/x.h5", "cannot"]),
    (["plot", "model", "{model_no_group}", "-o", "{out}/m.png"], ["model/", "missing"]),
    (["adapt", "--model", "{model_no_labels}", "--scene", S, "-o", "{out}/r.h5"],
     ["'model/labels' is missing"]),
    # an output that is an input
    (["plot", "model", M, "-o", M], ["input"]),
    (["play", "--model", M, "--wav", M, "-o", "{out}/h.h5"], ["--wav", "input"]),
    (["detect", H, "-o", H], ["input"]),
    (["adapt", "--model", M, "--scene", S, "-o", S], ["input"]),
    # damaged or foreign artifacts
    (["detect", "{history_short_target}", "-o", "{out}/d.h5"], ["target", "length"]),
    (["plot", "play", "{history_text_target}", "-o", "{out}/p.png"], ["target", "expected integers"]),
    (["plot", "play", "{history_target_out_of_range}", "-o", "{out}/p.png"], ["target", "outside"]),
    (["plot", "run", "{loop_no_attrs}", "-o", "{out}/r.png"], ["summary attribute", "missing"]),
    (["plot", "run", "{loop_2d_phase}", "-o", "{out}/r.png"], ["steps/phase", "dimension"]),
    (["report", "{eval_no_pvalues}", "-o", "{out}/rep"], ["pvalues/", "missing"]),
    (["report", "{eval_no_rmse}", "-o", "{out}/rep"], ["rmse", "missing"]),
    (["plot", "adapt", "{run_no_errors}", "-o", "{out}/a.png"], ["'errors' is missing"]),
    (["plot", "play", H, "--detection", "{detection_no_score}", "-o", "{out}/p.png"],
     ["'score' is missing"]),
    (["plot", "keyboard", "{newer_schema}", "-o", "{out}/k.png"], ["newer", "update kbcli"]),
    (["detect", "{attrs_cut}", "-o", "{out}/d.h5"], ["'attrs'", "JSON"]),
    (["inspect", "{kind_number}"], ["'kind'", "text"]),
    (["adapt", "--model", M, "--scene", "{config_missing}", "-o", "{out}/r.h5"],
     ["'config' is missing"]),
    (["adapt", "--model", M, "--scene", "{scene_angle_400}", "-o", "{out}/r.h5"],
     ["angle 400", "(-180, 180]"]),
    (["inspect", "{not_hdf5}"], ["not an HDF5"]),
    (["plot", "model", "{cut}", "-o", "{out}/m.png"], ["truncated"]),
    (["adapt", "--model", S, "--scene", S, "-o", "{out}/r.h5"], ["scene artifact, expected model"]),
    (["plot", "run", H, "-o", "{out}/r.png"], ["history artifact, expected closed_loop"]),
    (["inspect", "{out}/nope.h5"], ["no such file"]),
    # configs
    (["adapt", "--model", M, "--scene", S, "--config", "{bad_toml}", "-o", "{out}/r.h5"],
     ["invalid TOML"]),
    (["adapt", "--model", M, "--scene", S, "--config", "{no_table}", "-o", "{out}/r.h5"],
     ["no [adapt] table"]),
    (["evaluate", "--model", M, "--config", "{unknown_key}", "-o", "{out}/e.h5"], ["experimentz"]),
    (["evaluate", "--model", M, "--config", "{rigid_far}", "-o", "{out}/e.h5"],
     ["angle 270", "(-180, 180]"]),
    (["adapt", "--model", M, "--scene", S, "--config", "{out}/none.toml", "-o", "{out}/r.h5"],
     ["no such config"]),
    # options
    (["perturb", "--keyboard", K, "--dx", "nan", "-o", "{out}/s.h5"], ["finite"]),
    (["perturb", "--keyboard", K, "--dx", "3", "--category", "small", "-o", "{out}/s.h5"],
     ["either"]),
    (["perturb", "--keyboard", K, "--category", "huge", "-o", "{out}/s.h5"], ["huge"]),
    (["perturb", "--keyboard", K, "--dx", "400", "-o", "{out}/s.h5"], ["reach"]),
    (["learn", "--keyboard", K, "--mode", "warp", "-o", "{out}/m.h5"], ["warp"]),
    (["learn", "--keyboard", K, "--strategy", "lazy", "-o", "{out}/m.h5"], ["lazy"]),
    (["play", "--model", M, "--melody", "Q:1", "-o", "{out}/h.h5"], ["Q"]),
    (["play", "--model", M, "--melody", "A:-1", "-o", "{out}/h.h5"], ["beats"]),
    (["play", "--model", M, "--steps", "10", "--perturb-at", "50", "-o", "{out}/h.h5"],
     ["perturb_at"]),
    (["detect", H, "--n-st", "200", "-o", "{out}/d.h5"], ["n_st"]),
    (["run", "--model", M, "--scene", S, "--threshold", "2", "-o", "{out}/l.h5"], ["threshold"]),
    (["adapt", "--model", M, "--scene", S, "--strategy", "psychic", "-o", "{out}/r.h5"],
     ["psychic"]),
    (["adapt", "--model", M, "--scene", S, "--snapshots", "a,b", "-o", "{out}/r.h5"],
     ["--snapshots"]),
    (["evaluate", "--model", M, "--config", str(GOLDEN_TOML), "--jobs", "0", "-o", "{out}/e.h5"],
     ["--jobs"]),
    (["report", str(GOLDEN / "evaluation.h5"), "--format", "gif", "-o", "{out}/rep"], ["--format"]),
    (["plot", "keyboard", K, "-o", "{out}/k.jpg"], [".png", ".jpg"]),
    (["plot", "adapt", str(GOLDEN / "run.h5"), "-o", "{out}/adapt"], ["no suffix"]),
    (["keyboard", "-o", "{out}/missing/kb.h5"], ["does not exist"]),
    (["keyboard", "-o", "{out}"], ["is a folder"]),
    (["report", str(GOLDEN / "evaluation.h5"), "-o", str(GOLDEN / "run.h5")],
     ["not a folder"]),
]


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("argv, fragments", CASES, ids=[" ".join(c[0][:3]) for c in CASES])
def test_bad_input_is_refused_cleanly(runner, tmp_path, damaged, argv, fragments):
    values = {"golden": str(GOLDEN), "out": str(tmp_path), **{k: str(v) for k, v in damaged.items()}}
    golden_before = {p.name: p.read_bytes() for p in GOLDEN.iterdir()}
    damaged_before = _listing(next(iter(damaged.values())).parent)
    r = runner.invoke(app, [a.format(**values) for a in argv])
    assert r.exit_code == 1, r.output
    assert r.stdout == "", r.stdout
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kbcli: error:"), r.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
    assert "Traceback" not in r.output
    assert _listing(tmp_path) == []  # nothing written, no temporary file left
    assert {p.name: p.read_bytes() for p in GOLDEN.iterdir()} == golden_before
    assert _listing(next(iter(damaged.values())).parent) == damaged_before


def test_the_battery_is_large_enough():
    assert len(CASES) >= 40
