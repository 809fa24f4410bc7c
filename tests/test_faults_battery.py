"""Faults found by tools/fault_battery.py (issue 29), each at its cause: one line naming the path
and the cause, the right exit code, nothing left half-written."""

from __future__ import annotations

import contextlib
import errno
import importlib
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import one_line_error

import kbcli.cli.record as record
from kbcli.cli import app
from kbcli.errors import ArtifactError, KbcliError

cli_app = importlib.import_module("kbcli.cli.app")  # (kbcli.cli.app is also the Typer app)


def test_bench_json_in_an_unwritable_folder_refused_before_the_benchmark(runner, tmp_path,
                                                                          monkeypatch):
    """``bench --json`` into a read-only folder ran the benchmark, then ended in a traceback."""
    ran = []
    monkeypatch.setattr(cli_app, "probe_writable", lambda folder, target: (_ for _ in ()).throw(
        KbcliError(f"{target}: cannot write in {folder} (Read-only file system)")))
    monkeypatch.setattr(record, "machine", lambda: ran.append(1) or "m")
    r = runner.invoke(app, ["bench", "--json", str(tmp_path / "x" / "b.json"), "arm",
                            "--reaches", "2"])
    one_line_error(r, "b.json: cannot write in", "(Read-only file system)")
    assert ran == [] and list(tmp_path.iterdir()) == []


def test_bench_json_on_a_full_disk_is_one_line(runner, tmp_path, monkeypatch):
    """The result file is written after the benchmark, outside the commands' error boundary: a
    full disk there was a traceback with exit 0."""
    def full(path, argv=None):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(record, "write", full)
    out = tmp_path / "b.json"
    r = runner.invoke(app, ["bench", "--json", str(out), "arm", "--reaches", "2"])
    assert r.exit_code == 1, r.output
    assert r.output.strip().splitlines()[-1] == f"kbcli: error: {out}: No space left on device"
    assert "Traceback" not in r.output and list(tmp_path.iterdir()) == []


@contextlib.contextmanager
def _file_size_limit(nbytes: int):
    """Every write past ``nbytes`` of a file fails with EFBIG, as on a full disk (a real OS error
    at matplotlib's own writes, no root or tmpfs needed)."""
    old_sig = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old_sig)


@pytest.mark.parametrize(("suffix", "limit"), [(".pdf", 0), (".pdf", 1000), (".pdf", 2000),
                                              (".png", 1000), (".svg", 1000)])
def test_figure_write_failure_is_one_error_naming_the_file(tmp_path, suffix, limit):
    """A full disk under matplotlib's PDF writer ended in a zlib.error (or AttributeError)
    traceback raised by its own cleanup (the battery's disk-*-plot-model); the figure is now
    drawn in memory and written like any file."""
    import matplotlib.pyplot as plt

    from kbcli.viz.common import save

    fig, ax = plt.subplots()
    ax.plot(np.arange(1000), np.arange(1000) ** 2 % 97)
    out = tmp_path / f"m{suffix}"
    with _file_size_limit(limit), pytest.raises(ArtifactError) as info:
        save(fig, out)
    assert str(info.value) == f"{out}: cannot write (File too large)"
    assert list(tmp_path.iterdir()) == []


_DEAF = """
import os
from joblib import Parallel, delayed
from kbcli.io.processes import children_deaf_to_ctrl_c

def blocked():
    return open(f"/proc/{os.getpid()}/status").read().split("SigBlk:")[1].split()[0]

with children_deaf_to_ctrl_c():
    out = Parallel(n_jobs=2, backend="loky", return_as="generator_unordered")(
        delayed(blocked)() for _ in range(4))
print(" ".join(out))
"""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_workers_never_see_ctrl_c():
    """Ctrl-C reaches the whole process group: each loky worker printed a KeyboardInterrupt
    traceback beside the parent's one line (battery sigint-evaluate*). The workers start with
    SIGINT blocked, even after Python 3.11's resource tracker unblocked it while starting."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    r = subprocess.run([sys.executable, "-c", _DEAF], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    masks = r.stdout.split()
    assert len(masks) == 4 and all(int(m, 16) & (1 << (signal.SIGINT - 1)) for m in masks), masks


@pytest.mark.parametrize(("sig", "code", "word"), [(signal.SIGTERM, 143, "terminated"),
                                                   (signal.SIGINT, 130, "interrupted")])
def test_signal_while_kbcli_loads_is_one_line(tmp_path, sig, code, word):
    """SIGTERM while kbcli's modules were loading killed it silently (exit -15, battery
    sigterm-learn on a busy machine), and Ctrl-C printed an import's traceback."""
    if sig == signal.SIGINT and signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        pytest.skip("SIGINT is ignored here (a background job): the child would ignore it too")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    p = subprocess.Popen([sys.executable, "-m", "kbcli", "learn", "--budget", "20", "-o",
                          str(tmp_path / "m.h5")], env=env, stderr=subprocess.PIPE, text=True)
    time.sleep(0.3)  # Python is up, kbcli's imports (seconds) are not done
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    assert (p.returncode, err) == (code, f"kbcli: {word}\n")
    assert list(tmp_path.iterdir()) == []


def test_checkpoint_whose_meta_cannot_be_written_leaves_no_folder(tmp_path, monkeypatch):
    """A full disk at the checkpoint's first file left an empty OUTPUT.ckpt/ that the error line
    did not mention and no --resume could use (battery disk-full-evaluate)."""
    import kbcli.io.checkpoint as checkpoint_io
    from kbcli.io.checkpoint import Checkpoint

    def full(path, data, suffix=".tmp"):
        raise ArtifactError(f"{path}: cannot write (No space left on device)")

    monkeypatch.setattr(checkpoint_io, "write_bytes", full)
    ckpt = Checkpoint(tmp_path / "ev.h5.ckpt", {"a": 1})
    with pytest.raises(ArtifactError, match="meta.json: cannot write"):
        ckpt.start()
    assert list(tmp_path.iterdir()) == []


_REFUSE_BEFORE_DRAWING = """
import sys
from typer.testing import CliRunner
from kbcli.cli import app
g = sys.argv[1] + "/"
bad = "/no/such/folder/"
for args in (["plot", "keyboard", g + "keyboard.h5", "-o", bad + "k.png"],
             ["plot", "model", g + "model.h5", "-o", bad + "m.png"],
             ["plot", "play", g + "history.h5", "-o", bad + "p.png"],
             ["plot", "adapt", g + "run.h5", "-o", bad + "a.png"],
             ["plot", "run", g + "closed_loop.h5", "-o", bad + "r.png"],
             ["report", g + "evaluation.h5", "-o", bad + "rep"],
             ["animate", g + "run.h5", "-o", bad + "a.gif"]):
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 1 and "does not exist" in r.output, (args, r.output)
print("matplotlib" in sys.modules)
"""


def test_figure_commands_refuse_before_loading_matplotlib():
    """An output that cannot be written was refused only after matplotlib had loaded (seconds: the
    battery's read-only plot, report and animate cases were slow refusals)."""
    root = Path(__file__).resolve().parents[1]
    r = subprocess.run([sys.executable, "-c", _REFUSE_BEFORE_DRAWING, str(root / "data" / "golden")],
                       capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(root)},
                       timeout=120)
    assert (r.returncode, r.stdout.strip()) == (0, "False"), r.stderr
