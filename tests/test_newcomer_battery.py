"""A new user's bad-input battery (issue 40): what a newcomer types wrong in a first hour.

Written from the README, the tour and ``--help`` as a new user would try things: typos, numbers
out of range or not finite, files that are damaged or disagree with themselves, outputs that are not
regular files or that name someone else's folder, a robot that sends absurd numbers. Each case is
run through the real CLI and judged *clean* when:

- the exit code is the expected one (1 for a refusal, 0 where the command goes on and says so);
- a refusal prints exactly one line on stderr, ``kbcli: error: ...``, naming what to fix (the
  case's fragments), and nothing on stdout;
- no traceback and none of pydantic's own wording anywhere in the output;
- nothing is left in the case's folder but what was there before (and what a successful case
  writes), and no input file changed.

Run it alone to count the clean cases: ``pytest -q tests/test_newcomer_battery.py``.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest

from kbcli.cli import app

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "data" / "golden"

#: Words of pydantic's own messages that must never reach a user.
PYDANTIC = ("validation error", "Input should", "Field required", "should have at",
            "after validation", "pydantic", "Value error,")


@dataclass
class Case:
    """One thing a newcomer types: ``argv`` with ``{i}`` the inputs folder and ``{d}`` the case's
    own (empty unless ``setup`` puts something there, which must stay as it was)."""

    name: str
    argv: list[str]
    says: list[str]
    code: int = 1
    stdin: str | None = None
    setup: Callable[[Path], None] | None = None
    keep: tuple[str, ...] = ()  # files a successful case writes in {d}
    shows: bool = False  # a refusal that shows the file first (inspect): stdout may hold it


M, S, K, H = "{i}/model.h5", "{i}/scene.h5", "{i}/keyboard.h5", "{i}/history.h5"
SMALL = ["--resolution", "2", "--prior-halfwidth", "15", "-T", "2"]


# -- damaged inputs --------------------------------------------------------------------------------

def _edit(src: str, dst: Path, fn) -> None:
    shutil.copy(GOLDEN / f"{src}.h5", dst)
    with h5py.File(dst, "r+") as f:
        fn(f)


def _set(path: str, value):
    def fn(f):
        data = np.asarray(f[path][()])
        del f[path]
        f.create_dataset(path, data=value(data) if callable(value) else value)
    return fn


def _nan_first(a):
    a = np.array(a, float)
    a.flat[0] = np.nan
    return a


def _inf_first(a):
    a = np.array(a, float)
    a.flat[0] = np.inf
    return a


def _curve(f, name: str) -> str:
    found = []
    f["curves"].visit(lambda n: found.append(n) if n.endswith("/" + name) else None)
    return "curves/" + found[0]


DAMAGED: dict[str, tuple[str, Callable]] = {
    "scene_nan_params": ("scene", _set("params", np.array([np.nan, np.inf]))),
    "scene_params_disagree": ("scene", _set("params", np.array([1.0, 2.0]))),
    "scene_nan_centres": ("scene", _set("key_centres", _nan_first)),
    "model_nan_actions": ("model", _set("model/actions", _nan_first)),
    "model_inf_landed": ("model", _set("samples/landed", _inf_first)),
    "model_nan_curve": ("model", _set("curve/accuracy", _nan_first)),
    "keyboard_nan_features": ("keyboard", _set("features", _nan_first)),
    "history_nan_action": ("history", _set("action", _nan_first)),
    "history_inf_perceived": ("history", _set("perceived", _inf_first)),
    "detection_inf_score": ("detection", _set("score", _inf_first)),
    "run_nan_estimates": ("run", _set("estimates", _nan_first)),
    "loop_nan_landed": ("closed_loop", _set("steps/landed", _nan_first)),
    "eval_entropy_short": ("evaluation",
                           lambda f: _set(_curve(f, "entropy_mean"), lambda a: a[:-1])(f)),
    "eval_rmse_ml_long": ("evaluation",
                          lambda f: _set(_curve(f, "rmse_ml"), lambda a: np.r_[a, 1.0])(f)),
    "eval_nan_thresholds": ("evaluation", _set("thresholds", _nan_first)),
    "quality_inf_errors": ("model_quality", _set("experiments/errors", _inf_first)),
}

#: TOML files a newcomer writes (name -> text).
TOMLS = {
    "noise_huge": "[keyboard]\nnoise_std = 1e308\n",
    "tempo_step_huge": "[keyboard]\ntempo_col_step = 1e308\n",
    "tempo_zero": "[keyboard]\ntempo_base = 0\n",
    "key_size_huge": "[keyboard]\nkey_size = 1e9\n",
    "match_huge": "[keyboard]\nmatch_threshold = 1e308\n",
    "origin_one": "[keyboard]\norigin = [200.0]\n",
    "origin_three": "[keyboard]\norigin = [200.0, 250.0, 3.0]\n",
    "origin_text": '[keyboard]\norigin = ["a", 250.0]\n',
    "rows_float": "[keyboard]\nrows = 4.5\n",
    "margin_negative": "[keyboard]\nmargin = -5\n",
    "kb_typo": "[keyboard]\nrow = 4\n",
    "arm_kp_huge": '[arm]\npreset = "servo"\nkp = 1e300\n',
    "arm_finger_huge": '[arm]\npreset = "servo"\nfinger_radius = 1e300\n',
    "arm_torque_negative": '[arm]\npreset = "servo"\nmax_torque = -1\n',
    "arm_bias_one": '[arm]\npreset = "servo"\nproprio_bias = [0.01]\n',
    "adapt_snapshots_text": '[adapt]\nsnapshot_steps = "1,2"\n',
    "adapt_snapshots_negative": "[adapt]\nsnapshot_steps = [0, -1]\n",
    "adapt_resolution_negative": "[adapt]\nresolution = -1\n",
    "adapt_typo": "[adapt]\nstrategi = \"random\"\n",
    "adapt_strategy_unknown": '[adapt]\nstrategy = "greedy"\n',
    "adapt_max_steps_huge": "[adapt]\nmax_steps = 100000000\n",
    "not_toml": "[adapt\nstrategy = 1\n",
}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """data/golden, pipelines/golden.toml, the damaged files and the TOML files: the inputs every
    case may read, checked unchanged after each."""
    d = tmp_path_factory.mktemp("newcomer-inputs")
    for p in GOLDEN.glob("*.h5"):
        shutil.copy(p, d / p.name)
    shutil.copy(ROOT / "pipelines" / "golden.toml", d / "golden.toml")
    for name, (src, fn) in DAMAGED.items():
        _edit(src, d / f"{name}.h5", fn)
    for name, text in TOMLS.items():
        (d / f"{name}.toml").write_text(text)
    return d


# -- outputs that are not regular files, folders that are not reports ------------------------------

def _fifo(name: str) -> Callable[[Path], None]:
    return lambda d: os.mkfifo(d / name)


def _link_to_devnull(name: str) -> Callable[[Path], None]:
    return lambda d: (d / name).symlink_to("/dev/null")


def _user_readme(d: Path) -> None:
    (d / "rep").mkdir()
    (d / "rep" / "README.md").write_text("# my own notes\n")


def _user_files(d: Path) -> None:
    (d / "rep").mkdir()
    (d / "rep" / "thesis.tex").write_text("\\documentclass{article}\n")


# -- the cases -------------------------------------------------------------------------------------

def _serve(message: str, says: str) -> Case:
    return Case(f"serve {message[:24]}... ({says[:30]})", ["serve", "--model", M, "-o", "{d}/s.h5", *SMALL[:4]],
                [says], code=0, stdin=message + "\n" + json.dumps({"op": "end"}) + "\n",
                keep=("s.h5",))


def _damaged(name: str, argv: list[str], dataset: str, what: str = "NaN or infinite",
             shows: bool = False) -> Case:
    return Case(f"damaged {name}, {argv[0]}", argv, [f"{name}.h5", f"'{dataset}'", what],
                shows=shows)


CASES: list[Case] = [
    # the faults of issue 40
    _serve('{"id": %s, "op": "state"}' % ("7" * 5000), "5000 digits"),
    _serve('{"heard": [%s, 90]}' % ("9" * 5000), "5000 digits"),
    _serve('{"heard": [1e400, 90]}', "heard[0] is not a finite number"),
    _serve('{"heard": ["C4", 90]}', 'heard[0] must be a number, got \\"C4\\"'),
    _serve('{"felt": [400, 1e999], "heard": null}', "felt[1] is not a finite number"),
    Case("report into a user's folder", ["report", "{i}/evaluation.h5", "-o", "{d}/rep"],
         ["rep", "not a kbcli report", "--force"], setup=_user_readme),
    Case("report into a folder of other files", ["report", "{i}/evaluation.h5", "-o", "{d}/rep"],
         ["rep", "1 other file", "--force"], setup=_user_files),
    Case("sweep report into a user's folder", ["report", "{i}/model_quality.h5", "-o", "{d}/rep"],
         ["not a kbcli report"], setup=_user_readme),
    Case("-o a FIFO", ["keyboard", "-o", "{d}/kb.h5"], ["kb.h5", "FIFO", "regular file"],
         setup=_fifo("kb.h5")),
    Case("-o a link to /dev/null", ["perturb", "--keyboard", K, "--dx", "3", "-o", "{d}/s.h5"],
         ["character device"], setup=_link_to_devnull("s.h5")),
    Case("--wav a FIFO", ["play", "--model", M, "--steps", "5", "--wav", "{d}/p.wav", "-o",
                          "{d}/h.h5"], ["p.wav", "FIFO"], setup=_fifo("p.wav")),
    Case("figure a FIFO", ["plot", "keyboard", K, "-o", "{d}/k.png"], ["FIFO"],
         setup=_fifo("k.png")),
    Case("bench --json a FIFO", ["bench", "--json", "{d}/b.json", "arm", "--reaches", "5"],
         ["b.json", "FIFO"], setup=_fifo("b.json")),
    # (never -o /dev/null itself: run as root by a kbcli without the check, the case would replace
    # the system's /dev/null with a regular file; the link shows the same refusal safely)
    Case("-o a link to /dev/zero", ["keyboard", "-o", "{d}/kb.h5"], ["character device"],
         setup=lambda d: (d / "kb.h5").symlink_to("/dev/zero")),
    Case("evaluate --resume without a checkpoint",
         ["evaluate", "--config", "{i}/golden.toml", "--model", M, "-o", "{d}/e.h5", "--resume"],
         ["no checkpoint", "starting from the first experiment"], code=0, keep=("e.h5",)),
    _damaged("scene_nan_params", ["adapt", "--model", M, "--scene", "{i}/scene_nan_params.h5",
                                  "-o", "{d}/r.h5", *SMALL], "params"),
    _damaged("scene_nan_params", ["inspect", "{i}/scene_nan_params.h5"], "params", shows=True),
    Case("scene params disagree", ["adapt", "--model", M, "--scene",
                                   "{i}/scene_params_disagree.h5", "-o", "{d}/r.h5", *SMALL],
         ["scene_params_disagree.h5", "'params'", "disagrees with config params [12, -7]"]),
    _damaged("scene_nan_centres", ["play", "--model", M, "--scene", "{i}/scene_nan_centres.h5",
                                   "--perturb-at", "3", "--steps", "6", "-o", "{d}/h.h5"],
             "key_centres"),
    _damaged("model_nan_actions", ["adapt", "--model", "{i}/model_nan_actions.h5", "--scene", S,
                                   "-o", "{d}/r.h5", *SMALL], "model/actions"),
    _damaged("model_nan_actions", ["plot", "model", "{i}/model_nan_actions.h5", "-o",
                                   "{d}/m.png"], "model/actions"),
    _damaged("model_nan_actions", ["play", "--model", "{i}/model_nan_actions.h5", "--steps", "5",
                                   "-o", "{d}/h.h5"], "model/actions"),
    _damaged("model_inf_landed", ["run", "--model", "{i}/model_inf_landed.h5", "--scene", S,
                                  "-o", "{d}/l.h5"], "samples/landed"),
    _damaged("model_nan_curve", ["plot", "model", "{i}/model_nan_curve.h5", "-o", "{d}/m.png"],
             "curve/accuracy"),
    _damaged("keyboard_nan_features", ["perturb", "--keyboard", "{i}/keyboard_nan_features.h5",
                                       "--dx", "3", "-o", "{d}/s.h5"], "features"),
    _damaged("history_nan_action", ["detect", "{i}/history_nan_action.h5", "-o", "{d}/d.h5"],
             "action"),
    _damaged("history_inf_perceived", ["plot", "play", "{i}/history_inf_perceived.h5", "-o",
                                       "{d}/p.png"], "perceived", "infinite"),
    _damaged("detection_inf_score", ["plot", "play", H, "--detection",
                                     "{i}/detection_inf_score.h5", "-o", "{d}/p.png"], "score",
             "infinite"),
    _damaged("run_nan_estimates", ["plot", "adapt", "{i}/run_nan_estimates.h5", "-o",
                                   "{d}/a.png"], "estimates"),
    _damaged("loop_nan_landed", ["animate", "{i}/loop_nan_landed.h5", "--max-frames", "3", "-o",
                                 "{d}/a.gif"], "steps/landed"),
    Case("an entropy curve one shorter", ["report", "{i}/eval_entropy_short.h5", "-o", "{d}/rep"],
         ["eval_entropy_short.h5", "entropy_mean", "length 5", "expected 6"]),
    Case("an RMSE curve one longer", ["report", "{i}/eval_rmse_ml_long.h5", "-o", "{d}/rep"],
         ["eval_rmse_ml_long.h5", "rmse_ml", "length 7", "expected 6"]),
    _damaged("eval_nan_thresholds", ["report", "{i}/eval_nan_thresholds.h5", "-o", "{d}/rep"],
             "thresholds"),
    Case("a sweep with infinite errors", ["report", "{i}/quality_inf_errors.h5", "-o",
                                          "{d}/rep"],
         ["quality_inf_errors.h5", "experiments/errors", "infinite"]),
    # physical parameters without bounds, pydantic's words
    *(Case(f"keyboard {name}", ["keyboard", "--config", f"{{i}}/{name}.toml", "-o", "{d}/k.h5"],
           says) for name, says in (
        ("noise_huge", ["noise_huge.toml", "keyboard.noise_std", "[0, 100]", "1e+308"]),
        ("tempo_step_huge", ["keyboard.tempo_col_step", "[0, 1000]"]),
        ("tempo_zero", ["keyboard.tempo_base", "(0, 10000]", "got 0"]),
        ("key_size_huge", ["keyboard.layout.key_size", "(0, 10000]"]),
        ("match_huge", ["keyboard.match_threshold", "(0, 100]"]),
        ("origin_one", ["keyboard.origin has too few values", "[200.0]"]),
        ("origin_three", ["keyboard.origin must have at most 2 values, got 3"]),
        ("origin_text", ["keyboard.origin[0] must be a number", "'a'"]),
        ("rows_float", ["keyboard.layout.rows must be a whole number", "4.5"]),
        ("margin_negative", ["keyboard.margin", "[0, 10000]", "-5"]),
        ("kb_typo", ["unknown keyboard option 'row'", "valid:"]),
        ("not_toml", ["not_toml.toml", "invalid TOML"]),
    )),
    *(Case(f"learn --arm {name}", ["learn", "--keyboard", K, "--mode", "dynamics", "--arm",
                                   f"{{i}}/{name}.toml", "--budget", "20", "-o", "{d}/m.h5"],
           says) for name, says in (
        ("arm_kp_huge", ["arm.kp", "(0, 10000000000]", "1e+300"]),
        ("arm_finger_huge", ["arm.finger_radius", "[0, 50]"]),
        ("arm_torque_negative", ["arm.max_torque", "got -1"]),
        ("arm_bias_one", ["arm.proprio_bias has too few values", "[0.01]"]),
    )),
    Case("learn --reach-noise 1e308", ["learn", "--keyboard", K, "--reach-noise", "1e308",
                                       "--budget", "20", "-o", "{d}/m.h5"],
         ["reach_noise", "[0, 100]", "1e+308"]),
    Case("play --reach-noise -1", ["play", "--model", M, "--reach-noise", "-1", "-o",
                                   "{d}/h.h5"], ["reach_noise", "[0, 100]"]),
    Case("run --reach-noise inf", ["run", "--model", M, "--scene", S, "--reach-noise", "inf",
                                   "-o", "{d}/l.h5"], ["reach_noise"]),
    *(Case(f"adapt --config {name}", ["adapt", "--model", M, "--scene", S, "--config",
                                      f"{{i}}/{name}.toml", "-o", "{d}/r.h5"], says)
      for name, says in (
        ("adapt_snapshots_text", ["adapt.snapshot_steps must be a list of steps >= 0", "'1,2'"]),
        ("adapt_snapshots_negative", ["adapt.snapshot_steps", "[0, -1]"]),
        ("adapt_resolution_negative", ["resolution", "-1"]),
        ("adapt_typo", ["unknown adapt option 'strategi'", "valid:"]),
        ("adapt_strategy_unknown", ["greedy", "infogain"]),
        ("adapt_max_steps_huge", ["max_steps", "100000000"]),
    )),
    # options a newcomer gets wrong
    Case("perturb --dx inf", ["perturb", "--keyboard", K, "--dx", "inf", "-o", "{d}/s.h5"],
         ["finite"]),
    Case("perturb --dy nan", ["perturb", "--keyboard", K, "--dy", "nan", "-o", "{d}/s.h5"],
         ["finite"]),
    Case("learn --budget 0", ["learn", "--keyboard", K, "--budget", "0", "-o", "{d}/m.h5"],
         ["budget"]),
    Case("learn --budget huge", ["learn", "--keyboard", K, "--budget", "1000000000", "-o",
                                 "{d}/m.h5"], ["budget"]),
    Case("learn --model-class typo", ["learn", "--keyboard", K, "--model-class", "forrest", "-o",
                                      "{d}/m.h5"], ["forrest", "forest"]),
    Case("play --steps -3", ["play", "--model", M, "--steps", "-3", "-o", "{d}/h.h5"],
         ["steps"]),
    Case("run --perturb-at past --steps", ["run", "--model", M, "--scene", S, "--steps", "150",
                                          "--perturb-at", "500", "-o", "{d}/l.h5"],
         ["perturb_at"]),
    Case("run --threshold nan", ["run", "--model", M, "--scene", S, "--threshold", "nan", "-o",
                                 "{d}/l.h5"], ["threshold"]),
    Case("detect --n-lt 5 --n-st 10", ["detect", H, "--n-lt", "5", "--n-st", "10", "-o",
                                       "{d}/d.h5"], ["n_st must be smaller than n_lt"]),
    Case("adapt --max-steps 0", ["adapt", "--model", M, "--scene", S, "--max-steps", "0", "-o",
                                 "{d}/r.h5"], ["max_steps"]),
    Case("adapt --snapshots 1,x", ["adapt", "--model", M, "--scene", S, "--snapshots", "1,x",
                                   "-o", "{d}/r.h5"], ["--snapshots"]),
    Case("adapt --strategy typo", ["adapt", "--model", M, "--scene", S, "--strategy",
                                   "infogian", "-o", "{d}/r.h5"], ["infogian", "infogain"]),
    Case("adapt --family typo", ["adapt", "--model", M, "--scene", S, "--family", "rigd", "-o",
                                 "{d}/r.h5"], ["rigd"]),
    Case("animate --max-frames 0 (a usage error)", ["animate", "{i}/run.h5", "--max-frames",
                                                     "0", "-o", "{d}/a.gif"],
         ["--max-frames", "must be greater than or equal to 2"], code=2),
    Case("adapt --config names the file", ["adapt", "--model", M, "--scene", S, "--config",
                                           "{i}/adapt_resolution_negative.toml", "-o", "{d}/r.h5"],
         ["adapt_resolution_negative.toml: adapt.resolution"]),
    Case("a flag over a bad file value", ["keyboard", "--config", "{i}/noise_huge.toml",
                                          "--noise", "500", "-o", "{d}/k.h5"],
         ["keyboard.noise_std must be a number in [0, 100], got 500"]),
    Case("play --melody lowercase typo", ["play", "--model", M, "--melody", "H:1", "-o",
                                          "{d}/h.h5"], ["H"]),
    # files in the wrong place
    Case("adapt a model as the scene", ["adapt", "--model", M, "--scene", M, "-o", "{d}/r.h5"],
         ["model artifact, expected scene"]),
    Case("report a run", ["report", "{i}/run.h5", "-o", "{d}/rep"],
         ["run artifact, expected evaluation"]),
    Case("plot run an adaptation", ["plot", "run", "{i}/run.h5", "-o", "{d}/r.png"],
         ["run artifact, expected closed_loop"]),
    Case("plot model a TOML", ["plot", "model", "{i}/golden.toml", "-o", "{d}/m.png"],
         ["golden.toml"]),
    Case("inspect a folder", ["inspect", "{i}"], ["folder"]),
    Case("-o onto the input", ["detect", H, "-o", H], ["input"]),
    Case("-o into a missing folder", ["keyboard", "-o", "{d}/nope/kb.h5"], ["does not exist"]),
    Case("figure as .jpg", ["plot", "keyboard", K, "-o", "{d}/k.jpg"], [".jpg"]),
    Case("learn from a model", ["learn", "--keyboard", M, "-o", "{d}/m.h5"],
         ["model artifact, expected keyboard"]),
]


def _digest(folder: Path) -> dict[str, str]:
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_a_newcomers_mistake_is_handled_cleanly(runner, inputs, tmp_path, case):
    d = tmp_path / "case"
    d.mkdir()
    if case.setup is not None:
        case.setup(d)
    before, inputs_before = _listing(d), _digest(inputs)
    argv = [a.format(i=inputs, d=d) for a in case.argv]
    r = runner.invoke(app, argv, input=case.stdin)
    output = r.stdout + r.stderr
    assert r.exit_code == case.code, output[-2000:]
    assert "Traceback" not in output and r.exception is None or isinstance(r.exception,
                                                                          SystemExit), output
    for word in PYDANTIC:
        assert word not in output, output
    if case.code == 1:
        lines = [x for x in r.stderr.splitlines() if x.strip()]
        assert len(lines) == 1 and lines[0].startswith("kbcli: error:"), r.stderr
        assert case.shows or r.stdout == "", r.stdout
        text = lines[0]
    else:
        text = output
    for fragment in case.says:
        assert fragment in text, text
    assert _listing(d) == sorted({*before, *case.keep}), "left behind or removed"
    assert _digest(inputs) == inputs_before, "an input changed"


def test_the_battery_is_a_real_one():
    assert len(CASES) >= 80
    assert len({c.name for c in CASES}) == len(CASES)
