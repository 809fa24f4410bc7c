"""Smoke tests on the stored artifacts in data/: the golden set (one small artifact of every kind,
rebuilt by ``make data`` from pipelines/golden.toml), a stored file of every schema version ever
written (data/schema/vN/), and the rebuild itself.

- every read-only stage and every plot command runs on the golden set (figures in each format);
- every schema version of every kind is still read, and its readers run on it;
- ``make data`` into a temporary folder gives the same artifacts: of the same kinds, configs and
  datasets anywhere, and byte for byte (or numerically equal where the wall-clock time of a step is
  recorded) on the platform that built them (``data/platform.json``, :mod:`kbcli.io.platform`).
"""

from __future__ import annotations

import contextlib
import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from kbcli.cli import app
from kbcli.io.artifact import read_artifact
from kbcli.io.platform import fingerprint
from kbcli.stages.artifact import SCHEMA_VERSIONS

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data"
GOLDEN = DATA / "golden"
KINDS = tuple(SCHEMA_VERSIONS)

MAGIC = {"png": b"\x89PNG", "pdf": b"%PDF", "svg": b"<?xml"}

#: the readers of each kind: CLI invocations with {path}, {dir} (its folder) and {tmp} placeholders
#: (read-only stages, plots, and stages that read the kind to make something else from it).
READERS: dict[str, list[list[str]]] = {
    "keyboard": [["plot", "keyboard", "{path}", "-o", "{tmp}/k.png"],
                 ["perturb", "--keyboard", "{path}", "--dx", "3", "-o", "{tmp}/s.h5"],
                 ["learn", "--keyboard", "{path}", "--strategy", "exact", "-o", "{tmp}/m.h5"]],
    "model": [["plot", "model", "{path}", "-o", "{tmp}/m.png"],
              ["play", "--model", "{path}", "--steps", "5", "-o", "{tmp}/h.h5"],
              ["perturb", "--keyboard", "{path}", "--dx", "3", "-o", "{tmp}/s.h5"]],
    "scene": [["play", "--model", str(GOLDEN / "model.h5"), "--scene", "{path}", "--steps", "6",
               "--perturb-at", "3", "-o", "{tmp}/h.h5"],
              ["adapt", "--model", str(GOLDEN / "model.h5"), "--scene", "{path}", "-T", "2",
               "--resolution", "2", "--prior-halfwidth", "20", "-o", "{tmp}/r.h5"]],
    "history": [["detect", "{path}", "-o", "{tmp}/d.h5"],
                ["plot", "play", "{path}", "-o", "{tmp}/p.png"]],
    # a detection is drawn over the history it was computed on: the one stored beside it
    "detection": [["plot", "play", "{dir}/history.h5", "--detection", "{path}", "-o",
                   "{tmp}/p.png"]],
    "run": [["plot", "adapt", "{path}", "-o", "{tmp}/a.png"],
            ["animate", "{path}", "--max-frames", "3", "--dpi", "40", "-o", "{tmp}/a.gif"]],
    "closed_loop": [["plot", "run", "{path}", "-o", "{tmp}/r.png"],
                    ["animate", "{path}", "--max-frames", "3", "--dpi", "40", "-o", "{tmp}/r.gif"]],
    "evaluation": [["report", "{path}", "-o", "{tmp}/rep"]],
    "model_quality": [["report", "{path}", "-o", "{tmp}/rep"]],
}


#: A report's bootstrap replicates of each claim that differs: 2 here (readers, old schema versions,
#: figure formats): they still resample and resummarise (17 s -> 4 s a report here). The command as
#: a user types it, with the default 100, runs in tests/test_doc_examples.py (the reproduce page's
#: ``kbcli report eval.h5 -o report/``).
FEW_REPLICATES = ["--replicates", "2"]


def _fewer_replicates(argv: list[str]) -> list[str]:
    return [*argv, *FEW_REPLICATES] if argv[0] == "report" else argv


def _ok(r):
    assert r.exit_code == 0, r.output
    assert "Traceback" not in r.output
    return r


def test_golden_set_holds_every_kind():
    for kind in KINDS:
        art = read_artifact(GOLDEN / f"{kind}.h5", kind)
        assert art.schema_version == SCHEMA_VERSIONS[kind], (
            f"data/golden/{kind}.h5 is of schema {art.schema_version}: run make data")
    total = sum(p.stat().st_size for p in DATA.rglob("*.h5"))
    assert total < 5e6  # a small golden set


@pytest.mark.parametrize("kind", KINDS)
def test_inspect_every_golden_artifact(runner, kind):
    path = GOLDEN / f"{kind}.h5"
    d = json.loads(_ok(runner.invoke(app, ["inspect", "--json", str(path)])).output)
    assert d["kind"] == kind and d["problem"] is None
    assert re.fullmatch(r"[0-9a-f]{64}", d["sha256"])
    for ref in d["inputs"].values():  # full hashes of the inputs too
        assert re.fullmatch(r"[0-9a-f]{64}", ref["sha256"])
    table = _ok(runner.invoke(app, ["inspect", str(path)])).output
    for ref in d["inputs"].values():
        assert ref["sha256"] in table  # never cut, never wrapped
    assert d["sha256"] in table


@pytest.mark.parametrize("kind", KINDS)
def test_every_reader_runs_on_the_golden_set(runner, tmp_path, kind):
    for argv in READERS[kind]:
        _ok(runner.invoke(app, [a.format(path=GOLDEN / f"{kind}.h5", tmp=tmp_path, dir=GOLDEN)
                                for a in _fewer_replicates(argv)]))
    # the default format, png: what the test below checks of pdf and svg
    for fig in tmp_path.rglob("*.png"):
        assert fig.read_bytes()[:5].startswith(MAGIC["png"]), fig
    if (tmp_path / "rep" / "README.md").is_file():
        readme = (tmp_path / "rep" / "README.md").read_text()
        assert all(f"]({p.name})" in readme for p in (tmp_path / "rep").glob("*.png"))


@pytest.mark.parametrize("fmt", ["pdf", "svg"])  # png, the default: the readers' test above
def test_every_plot_writes_the_format_of_its_suffix(runner, tmp_path, fmt):
    plots = [["plot", "keyboard", GOLDEN / "keyboard.h5"], ["plot", "model", GOLDEN / "model.h5"],
             ["plot", "play", GOLDEN / "history.h5", "--detection", GOLDEN / "detection.h5"],
             ["plot", "adapt", GOLDEN / "run.h5"], ["plot", "run", GOLDEN / "closed_loop.h5"]]
    for argv in plots:
        out = tmp_path / f"{argv[1]}.{fmt}"
        _ok(runner.invoke(app, [*map(str, argv), "-o", str(out)]))
        assert out.read_bytes()[:5].startswith(MAGIC[fmt]), (argv, out.read_bytes()[:20])
    _ok(runner.invoke(app, ["report", str(GOLDEN / "evaluation.h5"), "-o", str(tmp_path / "rep"),
                            "--format", fmt, *FEW_REPLICATES]))
    figs = sorted(p for p in (tmp_path / "rep").iterdir() if p.suffix == f".{fmt}")
    assert len(figs) >= 3 and all(p.read_bytes()[:5].startswith(MAGIC[fmt]) for p in figs)
    readme = (tmp_path / "rep" / "README.md").read_text()
    for p in figs:
        assert f"]({p.name})" in readme


def test_detect_on_the_golden_history_gives_the_golden_detection(runner, tmp_path):
    """The stored detection is what detect computes today from the stored history."""
    cfg = read_artifact(GOLDEN / "detection.h5").config
    out = tmp_path / "d.h5"
    _ok(runner.invoke(app, ["detect", str(GOLDEN / "history.h5"), "--n-lt", str(cfg["n_lt"]),
                            "--n-st", str(cfg["n_st"]), "-o", str(out)]))
    new, old = read_artifact(out), read_artifact(GOLDEN / "detection.h5")
    np.testing.assert_array_equal(new.data["score"], old.data["score"])
    assert new.attrs == old.attrs


def _versions():
    for kind, current in SCHEMA_VERSIONS.items():
        for v in range(1, current + 1):
            yield pytest.param(kind, v, id=f"{kind}-v{v}")


@pytest.mark.parametrize("kind, version", list(_versions()))
def test_every_schema_version_ever_written_is_read(runner, tmp_path, kind, version):
    # the current version is the golden file itself; older ones are kept in data/schema/vN/
    path = (GOLDEN if version == SCHEMA_VERSIONS[kind] else DATA / "schema" / f"v{version}") / \
        f"{kind}.h5"
    assert path.is_file(), (f"{path.relative_to(ROOT)} is missing: before you bump a kind's "
                            f"schema, copy its golden file there (cp data/golden/{kind}.h5 "
                            f"{path.parent})")
    art = read_artifact(path, kind)
    assert art.schema_version == version
    for argv in READERS[kind]:
        _ok(runner.invoke(app, [a.format(path=path, tmp=tmp_path, dir=path.parent)
                                for a in _fewer_replicates(argv)]))


# -- artifacts stored with the flat robot options of kbcli before issue 41 -----------------------
#: data/schema/flat/: the golden files of the kinds that record the robot's options, as stored
#: before the strategy and the posterior held their own (run 3, closed_loop 3, evaluation 2,
#: model_quality 1). They are migrated on read (kbcli.io.schema.migrate).
FLAT = DATA / "schema" / "flat"


def _robots(tree, out):
    if isinstance(tree, dict):
        for k, v in tree.items():
            if k == "robot" and isinstance(v, dict):
                out.append(v)
            else:
                _robots(v, out)
    elif isinstance(tree, list):
        for v in tree:
            _robots(v, out)
    return out


@pytest.mark.parametrize("kind", ["run", "closed_loop", "evaluation", "model_quality"])
def test_a_flat_stored_artifact_reads_as_the_golden_one(runner, tmp_path, kind):
    """The same numbers, and once migrated the same robot configs (the parts' options in the
    parts, the options of parts not chosen dropped) as the golden artifact the current kbcli
    makes from the same inputs; and its readers run on it."""
    from kbcli.core.adaptation.config import recorded

    old, new = read_artifact(FLAT / f"{kind}.h5", kind), read_artifact(GOLDEN / f"{kind}.h5", kind)
    assert old.schema_version < new.schema_version
    (do, _), (dn, _) = _tree(FLAT / f"{kind}.h5"), _tree(GOLDEN / f"{kind}.h5")
    assert sorted(do) == sorted(dn)
    for k in do:
        if not TIMING.search(k):
            np.testing.assert_array_equal(do[k], dn[k], err_msg=k)
    ro = _robots(old.config, []) + _robots(old.attrs, [])
    rn = _robots(new.config, []) + _robots(new.attrs, [])
    assert ro and len(ro) == len(rn)
    assert [recorded(r) for r in ro] == [recorded(r) for r in rn]
    assert all(isinstance(r["posterior"], dict) for r in ro)  # migrated
    for argv in READERS[kind]:
        _ok(runner.invoke(app, [a.format(path=FLAT / f"{kind}.h5", tmp=tmp_path, dir=GOLDEN)
                                for a in _fewer_replicates(argv)]))


# -- make data rebuilds the same artifacts ------------------------------------------------------
#: datasets and summary attributes that hold wall-clock times (never equal between two runs)
TIMING = re.compile(r"(^|/)timing(/|$)|_ms$|_s$|seconds|elapsed")


def _tree(path: Path) -> dict[str, np.ndarray]:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset)
                     else None)
        attrs = {k: f.attrs[k] for k in f.attrs}
    return out, attrs


def _strip_times(obj):
    if isinstance(obj, dict):
        return {k: _strip_times(v) for k, v in obj.items() if not TIMING.search(k)}
    return obj


def _same_numbers(new: Path, old: Path) -> None:
    (dn, an), (do, ao) = _tree(new), _tree(old)
    assert sorted(dn) == sorted(do), new.name
    for k in dn:
        if not TIMING.search(k):
            np.testing.assert_array_equal(dn[k], do[k], err_msg=f"{new.name}: {k}")
    assert sorted(an) == sorted(ao)
    for k in an:
        if k in ("inputs",) or k.startswith("input_sha256."):
            continue  # hashes of inputs that hold times themselves
        if k == "attrs":
            assert _strip_times(json.loads(an[k])) == _strip_times(json.loads(ao[k])), new.name
        else:
            assert an[k] == ao[k], f"{new.name}: attribute {k}"


@pytest.fixture(scope="module")
def rebuilt(tmp_path_factory):
    """`make data` (its recipe, data-files) into a temporary folder, once for the tests below: the
    recipe as ``make -n`` prints it, its ``kbcli`` commands run in this process (a dozen fresh
    interpreters cost 20 s of imports), the others by the shell."""
    if shutil.which("make") is None:
        pytest.skip("make is not installed (it is needed for `make test` itself)")
    out = tmp_path_factory.mktemp("data")
    r = subprocess.run(["make", "-n", "--no-print-directory", "-s", "data-files", f"DATA={out}",
                        "KBCLI=kbcli", f"PY={sys.executable}"], cwd=ROOT, capture_output=True,
                       text=True, check=True)
    recipe = r.stdout.replace("\\\n", " ").splitlines()
    assert sum(line.startswith("kbcli ") for line in recipe) >= 9, r.stdout
    with contextlib.chdir(ROOT):
        for line in recipe:
            if line.startswith("kbcli "):
                _ok(CliRunner().invoke(app, shlex.split(line)[1:]))
            else:
                subprocess.run(line, shell=True, check=True)
    return out


def _h5(folder: Path) -> list[Path]:
    return sorted(p.relative_to(folder) for p in folder.rglob("*.h5") if "schema" not in p.parts)


def _stored_platform() -> dict | None:
    path = DATA / "platform.json"
    return json.loads(path.read_text()) if path.is_file() else None


def test_make_data_rebuilds_the_same_kinds_of_artifact_on_any_platform(rebuilt):
    """Wherever it runs, `make data` writes the stored files: the same artifacts, kinds, schemas,
    configs and datasets, and a default model as good as the stored one. (On another platform
    than the one that built data/, its pymunk arm's last bits differ and 800 reaches in dynamics
    mode grow them into another model: the numbers are compared by the test below.)"""
    assert _h5(rebuilt) == _h5(DATA)
    assert json.loads((rebuilt / "platform.json").read_text()) == fingerprint()
    for rel in _h5(rebuilt):
        new, old = read_artifact(rebuilt / rel), read_artifact(DATA / rel)
        assert (new.kind, new.schema_version, new.seed) == (old.kind, old.schema_version,
                                                             old.seed), rel
        assert new.config == old.config, rel
        (dn, an), (do, ao) = _tree(rebuilt / rel), _tree(DATA / rel)
        assert sorted(dn) == sorted(do), rel
        assert sorted(an) == sorted(ao), rel
        assert sorted(json.loads(an["attrs"])) == sorted(json.loads(ao["attrs"])), rel
    # no simulator behind the keyboard: its bytes are the same everywhere
    assert (rebuilt / "keyboard.h5").read_bytes() == (DATA / "keyboard.h5").read_bytes()
    new, old = (read_artifact(p / "default-model.h5").attrs for p in (rebuilt, DATA))
    assert abs(new["accuracy"] - old["accuracy"]) <= 0.005
    assert abs(new["boundary_error_px"] - old["boundary_error_px"]) <= 0.5


def test_make_data_rebuilds_the_stored_bytes_on_the_platform_that_built_them(rebuilt):
    """On the platform of data/platform.json, `make data` gives the stored artifacts, byte for
    byte (or numerically equal where the wall-clock time of a step is recorded)."""
    stored = _stored_platform()
    if stored != fingerprint():
        pytest.skip("data/ was built on another platform (data/platform.json: "
                    f"{json.dumps(stored, sort_keys=True)}), where numpy's SIMD kernels or BLAS "
                    "round differently in the last bit: run `make data` to rebuild it here")
    for rel in _h5(rebuilt):
        new, old = rebuilt / rel, DATA / rel
        if new.read_bytes() != old.read_bytes():  # only wall-clock timings may differ
            _same_numbers(new, old)
