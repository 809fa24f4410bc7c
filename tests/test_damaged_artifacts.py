"""Property test: a damaged artifact never gives a traceback.

Hypothesis mutates a copy of the golden artifact of each kind (deletes, retypes and truncates its
datasets, groups, root attributes and the entries of its summary and config) and runs every reader
of that kind on it: the loaders (read_artifact and the stage loaders) must either work or raise a
:class:`~kbcli.errors.KbcliError`; the commands that read the kind must either succeed or exit 1
with one line, never with another exception.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
from pathlib import Path
from unittest import mock

import h5py
import matplotlib.pyplot as plt
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from kbcli.cli import app
from kbcli.errors import KbcliError
from kbcli.io.artifact import read_artifact
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import SCHEMA_VERSIONS

GOLDEN = Path(__file__).resolve().parent.parent / "data" / "golden"
M, S, H = str(GOLDEN / "model.h5"), str(GOLDEN / "scene.h5"), str(GOLDEN / "history.h5")

#: the commands that read each kind ({path}: the damaged file, {tmp}: a scratch folder)
COMMANDS: dict[str, list[list[str]]] = {
    "keyboard": [["plot", "keyboard", "{path}", "-o", "{tmp}/k.png"],
                 ["perturb", "--keyboard", "{path}", "--dx", "3", "-o", "{tmp}/s.h5"]],
    "model": [["plot", "model", "{path}", "-o", "{tmp}/m.png"],
              ["play", "--model", "{path}", "--steps", "3", "-o", "{tmp}/h.h5"]],
    "scene": [["play", "--model", M, "--scene", "{path}", "--steps", "4", "--perturb-at", "2",
               "-o", "{tmp}/h.h5"],
              ["adapt", "--model", M, "--scene", "{path}", "-T", "1", "--resolution", "4",
               "--prior-halfwidth", "12", "--snapshots", "0,1", "-o", "{tmp}/r.h5"]],
    "history": [["detect", "{path}", "-o", "{tmp}/d.h5"],
                ["plot", "play", "{path}", "-o", "{tmp}/p.png"]],
    "detection": [["plot", "play", H, "--detection", "{path}", "-o", "{tmp}/p.png"]],
    "run": [["plot", "adapt", "{path}", "-o", "{tmp}/a.png"],
            ["animate", "{path}", "--max-frames", "2", "--dpi", "40", "-o", "{tmp}/a.gif"]],
    "closed_loop": [["plot", "run", "{path}", "-o", "{tmp}/r.png"],
                    ["animate", "{path}", "--max-frames", "2", "--dpi", "40", "-o",
                     "{tmp}/r.gif"]],
    # two bootstrap replicates, not the default 100: each still resamples and resummarises the
    # damaged file; 100 of them per example were 85 % of this test's time
    "evaluation": [["report", "{path}", "-o", "{tmp}/rep", "--replicates", "2"]],
    "model_quality": [["report", "{path}", "-o", "{tmp}/rep"]],
}


def _loaders(kind: str, path: Path) -> None:
    """The stage loaders of a kind (each may raise only KbcliError)."""
    art = read_artifact(path, kind)
    if kind in ("keyboard", "model", "scene", "history", "closed_loop"):
        keyboard_stage.load(art)
    if kind == "model":
        from kbcli.stages.models import load_model

        model = load_model(art)
        model.predict_proba(np.array([[300.0, 300.0], [420.0, 380.0]]))
    if kind == "scene":
        from kbcli.stages.perturb import pose

        pose(art)


def _targets(path: Path) -> list[tuple[str, str]]:
    """(what, name) of everything that can be damaged in a file."""
    out: list[tuple[str, str]] = []
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.append(
            ("dataset" if isinstance(o, h5py.Dataset) else "group", n)))
        out += [("attribute", k) for k in f.attrs]
        for key in ("attrs", "config"):
            if key in f.attrs:
                out += [(key, k) for k in json.loads(f.attrs[key])]
    return out


#: Damaged copies tried per artifact kind: 10 in the suite (the same 10 every run: derandomized),
#: as many as asked with KBCLI_DAMAGE_EXAMPLES (``make fuzz``: 200 per kind, a longer sweep).
EXAMPLES = int(os.environ.get("KBCLI_DAMAGE_EXAMPLES", "10"))
PHASES = (Phase.explicit, Phase.reuse, Phase.generate)  # no shrinking: the report shows the mutations
OPS = ("delete", "retype", "truncate")
RETYPES = ("text", "float", "int", "scalar", "bool")


def _mutate(f: h5py.File, what: str, name: str, op: str, how: str, frac: float) -> None:
    if what in ("dataset", "group"):
        if name not in f:
            return
        node = f[name]
        if op == "delete" or what == "group":
            del f[name]
            return
        data = node[()]
        if op == "truncate":
            arr = np.asarray(data)
            new = arr[: int(frac * len(arr))] if arr.ndim else arr.reshape(1)[:0]
        else:
            arr = np.asarray(data)
            new = {"text": lambda: np.full(arr.shape, "x", dtype=object).astype(
                       h5py.string_dtype()),
                   "float": lambda: arr.astype(float) + 0.5 if arr.dtype.kind in "fiub"
                   else np.zeros(arr.shape),
                   "int": lambda: np.zeros(arr.shape, np.int64) - 1,
                   "scalar": lambda: np.float64(1.0),
                   "bool": lambda: np.ones(arr.shape, bool)}[how]()
        del f[name]
        f.create_dataset(name, data=new)
    elif what == "attribute":
        if name not in f.attrs:
            return
        if op == "delete":
            del f.attrs[name]
        elif op == "retype":
            f.attrs[name] = {"text": "x", "float": 1.5, "int": 7, "scalar": np.arange(3),
                             "bool": True}[how]
        else:
            v = f.attrs[name]
            f.attrs[name] = str(v)[: int(frac * len(str(v)))]
    else:  # an entry of the attrs or config JSON
        try:
            doc = json.loads(f.attrs[what])
        except (KeyError, TypeError, ValueError):  # already deleted or damaged
            return
        if not isinstance(doc, dict) or name not in doc:
            return
        if op == "delete":
            del doc[name]
        elif op == "retype":
            doc[name] = {"text": "x", "float": 1.5, "int": -3, "scalar": [1, 2],
                         "bool": None}[how]
        else:
            v = doc[name]
            doc[name] = v[: int(frac * len(v))] if isinstance(v, (list, str)) else None
        f.attrs[what] = json.dumps(doc)


def _fast_save(fig, path, dpi: int = 110) -> None:
    """Render at a low resolution into memory (drawing errors still surface) and close."""
    try:
        fig.savefig(io.BytesIO(), format="png", dpi=12)
    finally:
        plt.close(fig)


_SAVERS = ("kbcli.viz.adapt.save", "kbcli.viz.loop.save", "kbcli.viz.model.save",
           "kbcli.viz.play.save", "kbcli.viz.keyboard.save", "kbcli.viz.report.save")


def _mutation(kind: str):
    targets = _targets(GOLDEN / f"{kind}.h5")
    one = st.tuples(st.sampled_from(targets), st.sampled_from(OPS), st.sampled_from(RETYPES),
                    st.floats(0.0, 0.95))
    return st.lists(one, min_size=1, max_size=3)


@pytest.mark.parametrize("kind", list(SCHEMA_VERSIONS))
def test_every_reader_fails_cleanly_on_a_damaged_artifact(kind, tmp_path_factory):
    import kbcli.viz.adapt  # noqa: F401  (import the figure modules before patching them)
    import kbcli.viz.keyboard  # noqa: F401
    import kbcli.viz.loop  # noqa: F401
    import kbcli.viz.model  # noqa: F401
    import kbcli.viz.play  # noqa: F401
    import kbcli.viz.report  # noqa: F401

    runner = CliRunner()

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow], phases=PHASES)
    @given(mutations=_mutation(kind))
    def check(mutations):
        tmp = tmp_path_factory.mktemp(kind)
        path = tmp / f"{kind}.h5"
        shutil.copy(GOLDEN / f"{kind}.h5", path)
        with h5py.File(path, "r+") as f:
            for (what, name), op, how, frac in mutations:
                _mutate(f, what, name, op, how, frac)
        try:
            _loaders(kind, path)
        except KbcliError:
            pass
        with contextlib.ExitStack() as stack:
            for target in _SAVERS:
                stack.enter_context(mock.patch(target, _fast_save))
            for argv in [["inspect", "{path}"], *COMMANDS[kind]]:
                r = runner.invoke(app, [a.format(path=path, tmp=tmp) for a in argv])
                if r.exit_code not in (0, 1) or (r.exception is not None
                                                 and not isinstance(r.exception, SystemExit)):
                    import traceback

                    tb = "".join(traceback.format_exception(r.exception)) if r.exception else ""
                    raise AssertionError(f"{argv[:2]} on {mutations}: exit {r.exit_code}\n"
                                         f"{r.output}\n{tb}")
                if r.exit_code == 1:
                    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
                    assert len(lines) == 1 and lines[0].startswith("kbcli: error:"), r.stderr
        shutil.rmtree(tmp, ignore_errors=True)

    check()
