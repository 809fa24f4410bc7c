"""The stored results are the current code's (issue 39).

Every result file (``benchmarks/results/*.json``) names the commit of the code that made it,
whether its tree was clean, and the sha256 of every input it read. The reproduction's verdicts
(``reproduce.json``) rest on a model that ``make reproduce`` learns: this suite learns it again,
the same way, and fails when the bytes differ, so a change to learning that stales the stored
verdicts is caught here, not by a reviewer.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from kbcli.cli import app
from kbcli.io.artifact import sha256_file
from kbcli.io.platform import fingerprint

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
REPRODUCE = RESULTS / "reproduce.json"
#: The commands ``benchmarks/reproduce.sh`` learns the reproduction's model with (SEED=0).
KEYBOARD = 'keyboard --config pipelines/keyboard.toml -o "$OUT/keyboard.h5"'
LEARN = 'learn --keyboard "$OUT/keyboard.h5" -o "$OUT/model.h5" --seed "$SEED"'
REGENERATE = "regenerate it: make reproduce && make results-reproduce (see the Makefile)"


def _result(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def reproduction_model(d: dict) -> str:
    """The full sha256 of the model the stored reproduction's evaluation was run with."""
    evals = [v for k, v in d.get("inputs", {}).items() if v.get("kind") == "evaluation"
             and "own" not in Path(k).name and "ablation" not in Path(k).name]
    assert evals, f"{REPRODUCE.name} names no evaluation among its inputs: {REGENERATE}"
    return evals[0]["inputs"]["model"]["sha256"]


@pytest.mark.parametrize("path", sorted(RESULTS.glob("*.json")), ids=lambda p: p.name)
def test_every_result_file_names_its_provenance(path):
    d = _result(path)
    git = d.get("git")
    assert git is not None and re.fullmatch(r"[0-9a-f]{40}", git.get("commit", "")), \
        f"{path.name} does not name the commit of the code that made it: regenerate it"
    assert git["clean"] is True, f"{path.name} was made from a tree with changes: {git['changed']}"
    for name, entry in d["inputs"].items():
        assert re.fullmatch(r"[0-9a-f]{64}", entry["sha256"]), name


def test_the_reproduction_learns_its_model_as_this_suite_does():
    text = (ROOT / "benchmarks" / "reproduce.sh").read_text(encoding="utf-8")
    assert KEYBOARD in text and LEARN in text
    assert 'SEED=${SEED:-0}' in text


def test_the_stored_reproduction_is_the_current_codes(runner, tmp_path):
    """Learn the reproduction's model as ``make reproduce`` does; its bytes are the model the
    stored verdicts were computed on (on the platform that made them: numpy's kernels decide
    the last bit of a learned model, :mod:`kbcli.io.platform`)."""
    d = _result(REPRODUCE)
    want = reproduction_model(d)
    if d.get("platform") != fingerprint():
        pytest.skip("benchmarks/results/reproduce.json was made on another platform "
                    f"({d.get('platform', {}).get('numpy_simd')}): its model's bytes are that "
                    "platform's")
    kb, model = tmp_path / "keyboard.h5", tmp_path / "model.h5"
    for args in (["keyboard", "--config", str(ROOT / "pipelines" / "keyboard.toml"), "-o", str(kb)],
                 ["learn", "--keyboard", str(kb), "-o", str(model), "--seed", "0"]):
        r = runner.invoke(app, args)
        assert r.exit_code == 0, r.output
    assert sha256_file(model) == want, (
        "the model make reproduce learns today is not the one benchmarks/results/reproduce.json "
        f"was computed on: the learning code changed since; {REGENERATE}")


def test_provenance_hashes_the_inputs_not_the_outputs(tmp_path):
    from kbcli.io.provenance import git_state, inputs

    a, out = tmp_path / "a.txt", tmp_path / "out.json"
    a.write_text("x")
    out.write_text("{}")  # an older result file the command will replace
    got = inputs(["bench", "--json", str(out), "verdicts", str(a), "--missing", "nope.h5"])
    assert list(got) == [str(a)]
    assert got[str(a)]["sha256"] == sha256_file(a)
    state = git_state(ROOT)
    if state is not None:  # a git checkout: the commit and the tree's state
        assert re.fullmatch(r"[0-9a-f]{40}", state["commit"]) and isinstance(state["clean"], bool)
    assert git_state(tmp_path) is None  # not a checkout


def test_a_result_file_written_before_another_leaves_the_code_clean(tmp_path):
    import subprocess

    from kbcli.io.provenance import git_state

    def git(*args):
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    git("init", "-q")
    git("-c", "user.email=a@b", "-c", "user.name=a", "commit", "-q", "--allow-empty", "-m", "x")
    (tmp_path / "benchmarks" / "results").mkdir(parents=True)
    (tmp_path / "benchmarks" / "results" / "arm.json").write_text("{}")
    state = git_state(tmp_path)
    assert state["clean"] is True and state["changed"] == ["benchmarks/results/arm.json"]
    (tmp_path / "code.py").write_text("x = 1\n")
    assert git_state(tmp_path)["clean"] is False


def test_a_result_file_records_the_load_it_ran_under(tmp_path, monkeypatch):
    from kbcli.cli import record

    loads = iter([(6.0, 5.0, 4.0), (2.0, 3.0, 4.0)])
    monkeypatch.setattr(record.os, "getloadavg", lambda: next(loads))
    record.start(tmp_path / "r.json")
    record.write(tmp_path / "r.json", ["bench", "arm"])
    d = json.loads((tmp_path / "r.json").read_text())
    assert d["load"]["start"] == [6.0, 5.0, 4.0] and d["load"]["end"] == [2.0, 3.0, 4.0]


def test_the_note_under_a_timing_table_prints_the_load_or_says_unknown(monkeypatch):
    from kbcli.cli import record

    monkeypatch.setattr(record.os, "getloadavg", lambda: (6.125, 5.0, 4.5))
    assert record.load_note() == "6.12 5 4.5"

    def unsupported():
        raise OSError("no load average here")

    monkeypatch.setattr(record.os, "getloadavg", unsupported)
    assert record.load_note() == "unknown"
