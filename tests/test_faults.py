"""Faults of the machine, the input and the robot: nothing crashes, hangs or litters (issue 29).

Each case asserts the exit code, the single error line and what is left on disk: a full disk and
other OS errors (patched writes), SIGTERM and SIGINT sent to real subprocesses, two writers on one
output, leftovers of a killed run, oversized counts, hostile ``serve`` clients.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import one_line_error

import kbcli.io.artifact as artifact_io
from kbcli.cli import app
from kbcli.errors import ArtifactError, KbcliError
from kbcli.io import atomic, lock, processes, signals
from kbcli.io.artifact import read_artifact, sha256_file, write_artifact
from kbcli.io.checkpoint import Checkpoint

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "data" / "golden"
MODEL = str(GOLDEN / "model.h5")
SCENE = str(GOLDEN / "scene.h5")
KB = str(GOLDEN / "keyboard.h5")
EVALUATION = str(GOLDEN / "evaluation.h5")
CAUSES = {errno.ENOSPC: "No space left on device", errno.EIO: "Input/output error",
          errno.EROFS: "Read-only file system", errno.EDQUOT: "Disk quota exceeded",
          errno.EFBIG: "File too large"}


def _dead_pid() -> int:
    """The pid of a process that has ended."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


class _Failing:
    """A file object whose writes fail with ``code`` (what a full disk does)."""

    def __init__(self, code: int) -> None:
        self.code = code

    def write(self, data):
        raise OSError(self.code, os.strerror(self.code))

    def flush(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


@pytest.fixture
def full_disk(monkeypatch):
    """Make every artifact write (and every atomic byte write) fail with ENOSPC."""

    def install(code: int = errno.ENOSPC, only: str | None = None):
        real = open

        def fake(path, mode="r", *a, **k):
            if "w" in mode and (only is None or str(path).endswith(only)
                                or only in os.path.basename(str(path))):
                return _Failing(code)
            return real(path, mode, *a, **k)

        monkeypatch.setattr(artifact_io, "open", fake, raising=False)
        monkeypatch.setattr(atomic, "open", fake, raising=False)

    return install


def _listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# -- a full disk and other OS errors: the writers ---------------------------------------------------
@pytest.mark.parametrize("code", sorted(CAUSES))
def test_write_artifact_os_error_is_one_line_and_leaves_nothing(tmp_path, full_disk, code):
    art = read_artifact(KB)
    full_disk(code)
    with pytest.raises(ArtifactError) as e:
        write_artifact(art, tmp_path / "k.h5")
    assert str(e.value) == f"{tmp_path / 'k.h5'}: cannot write ({CAUSES[code]})"
    assert _listing(tmp_path) == []


def test_write_artifact_failure_keeps_the_old_file(tmp_path, full_disk):
    art = read_artifact(KB)
    write_artifact(art, tmp_path / "k.h5")
    before = sha256_file(tmp_path / "k.h5")
    full_disk()
    with pytest.raises(ArtifactError, match="No space left"):
        write_artifact(art, tmp_path / "k.h5")
    assert sha256_file(tmp_path / "k.h5") == before
    assert _listing(tmp_path) == ["k.h5"]


def test_write_artifact_fsync_failure(tmp_path, monkeypatch):
    """A full disk noticed only at fsync (delayed allocation)."""

    def fail(path):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic, "_fsync", fail)
    with pytest.raises(ArtifactError, match=r"k\.h5: cannot write \(No space left on device\)"):
        write_artifact(read_artifact(KB), tmp_path / "k.h5")
    assert _listing(tmp_path) == []


def test_write_artifact_in_memory_is_byte_identical(tmp_path):
    """Building the file in memory gives the bytes HDF5 wrote to disk (same seeds, same bytes)."""
    for name in ("keyboard.h5", "model.h5", "run.h5"):
        art = read_artifact(GOLDEN / name)
        digest = write_artifact(art, tmp_path / name)
        assert digest == sha256_file(GOLDEN / name) == sha256_file(tmp_path / name)


def test_hdf5_image_leaves_no_open_file():
    import h5py

    before = h5py.h5f.get_obj_count(h5py.h5f.OBJ_ALL, h5py.h5f.OBJ_FILE)
    with pytest.raises(RuntimeError):
        artifact_io.hdf5_image(lambda f: (_ for _ in ()).throw(RuntimeError("boom")))
    artifact_io.hdf5_image(lambda f: f.create_dataset("x", data=np.arange(3)))
    assert h5py.h5f.get_obj_count(h5py.h5f.OBJ_ALL, h5py.h5f.OBJ_FILE) == before


def test_no_segfault_after_a_failed_write_in_a_subprocess(tmp_path):
    """The crash of issue 29: after a failed write, the interpreter's exit finalised h5py objects
    of a file HDF5 could not flush. Now the process exits 1 with one line."""
    code = (
        "import errno, sys\n"
        "import kbcli.io.atomic as a\n"
        "def f(p): raise OSError(errno.ENOSPC, 'No space left on device')\n"
        "a._fsync = f\n"
        "from kbcli.cli import main\n"
        f"sys.argv = ['kbcli', 'keyboard', '-o', {str(tmp_path / 'k.h5')!r}]\n"
        "main()\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 1, r.stderr
    assert r.stderr.strip().splitlines() == [
        f"kbcli: error: {tmp_path / 'k.h5'}: cannot write (No space left on device)"]
    assert _listing(tmp_path) == []


def test_checkpoint_flush_on_a_full_disk(tmp_path, full_disk):
    ck = Checkpoint(tmp_path / "o.h5.ckpt", {"a": 1}, every=100)
    ck.add(0, {"x": np.arange(3)})
    ck.flush()
    full_disk(only="part-")
    ck.add(1, {"x": np.arange(3)})
    with pytest.raises(ArtifactError, match="part-000002.h5: cannot write .No space left"):
        ck.flush()
    assert _listing(tmp_path / "o.h5.ckpt") == ["meta.json", "part-000001.h5"]
    again = Checkpoint(tmp_path / "o.h5.ckpt", {"a": 1})
    assert sorted(again.load(resume=True)) == [0]  # what was written is valid


def test_checkpoint_folder_on_a_read_only_parent(tmp_path, monkeypatch):
    def fail(self, *a, **k):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(Path, "mkdir", fail)
    ck = Checkpoint(tmp_path / "o.h5.ckpt", {"a": 1})
    ck.add(0, {"x": np.zeros(1)})
    with pytest.raises(KbcliError, match="cannot create the checkpoint folder .Read-only"):
        ck.flush()


def test_atomic_paths_all_or_none(tmp_path):
    (tmp_path / "a").write_text("old a")
    (tmp_path / "b").write_text("old b")
    with pytest.raises(ArtifactError, match=r"b: cannot write \(No space left on device\)"), \
            atomic.atomic_paths([tmp_path / "a", tmp_path / "b"]) as (ta, tb):
        Path(ta).write_text("new a")
        raise OSError(errno.ENOSPC, "No space left on device", tb)
    assert (tmp_path / "a").read_text() == "old a" and (tmp_path / "b").read_text() == "old b"
    assert _listing(tmp_path) == ["a", "b"]


def test_atomic_path_interrupted_leaves_nothing(tmp_path):
    with pytest.raises(KeyboardInterrupt), atomic.atomic_path(tmp_path / "x.h5") as tmp:
        Path(tmp).write_text("half")
        raise signals.Terminated()
    assert _listing(tmp_path) == []


def test_atomic_path_in_a_missing_folder(tmp_path):
    with pytest.raises(ArtifactError, match="cannot write in"), \
            atomic.atomic_path(tmp_path / "nope" / "x.h5"):
        pass


def test_temporary_names_are_recognisable(tmp_path):
    with atomic.atomic_path(tmp_path / "x.h5") as tmp:
        name = Path(tmp).name
        assert name.startswith(f".x.h5{atomic.TMP_MARK}{os.getpid()}-")


def test_stale_temporary_files_of_a_killed_run_are_cleaned(tmp_path):
    dead = _dead_pid()
    stale = tmp_path / f".x.h5{atomic.TMP_MARK}{dead}-abcd.tmp"
    stale.write_text("half")
    stale_dir = tmp_path / f".rep{atomic.TMP_MARK}{dead}-abcd"
    stale_dir.mkdir()
    live = tmp_path / f".x.h5{atomic.TMP_MARK}{os.getppid()}-abcd.tmp"  # a running writer's
    live.write_text("busy")
    other = tmp_path / ".x.h5.mine"
    other.write_text("user")
    write_artifact(read_artifact(KB), tmp_path / "x.h5")
    assert not stale.exists() and live.exists() and other.exists()
    atomic.clean_stale(tmp_path / "rep")
    assert not stale_dir.exists()


# -- folders written aside --------------------------------------------------------------------------
def test_atomic_folder_new(tmp_path):
    with atomic.atomic_folder(tmp_path / "rep") as tmp:
        (tmp / "README.md").write_text("r")
        (tmp / "fig.png").write_text("f")
    assert _listing(tmp_path / "rep") == ["README.md", "fig.png"]
    assert _listing(tmp_path) == ["rep"]


def test_atomic_folder_error_leaves_no_folder(tmp_path):
    with pytest.raises(ArtifactError, match="No space left"), \
            atomic.atomic_folder(tmp_path / "rep") as tmp:
        (tmp / "fig.png").write_text("f")
        raise OSError(errno.ENOSPC, "No space left on device")
    assert _listing(tmp_path) == []


def test_atomic_folder_interrupted_keeps_the_old_report(tmp_path):
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "README.md").write_text("old")
    with pytest.raises(KeyboardInterrupt), atomic.atomic_folder(rep) as tmp:
        (tmp / "README.md").write_text("new")
        raise KeyboardInterrupt
    assert (rep / "README.md").read_text() == "old"
    assert _listing(tmp_path) == ["rep"]


def test_atomic_folder_replaces_stale_files_keeps_the_users(tmp_path):
    rep = tmp_path / "rep"
    rep.mkdir()
    for name in ("README.md", "fig6_entropy.png", "fig7_error_dynamics.png", "notes.txt"):
        (rep / name).write_text("old")
    with atomic.atomic_folder(rep, owned=("README.md", "fig*.png")) as tmp:
        (tmp / "README.md").write_text("new")
        (tmp / "fig6_entropy.png").write_text("new")
    assert _listing(rep) == ["README.md", "fig6_entropy.png", "notes.txt"]
    assert (rep / "README.md").read_text() == "new"


# -- the CLI: one line, exit 1, nothing left --------------------------------------------------------
def test_cli_keyboard_on_a_full_disk(runner, tmp_path, full_disk):
    full_disk()
    r = runner.invoke(app, ["keyboard", "-o", str(tmp_path / "k.h5")])
    one_line_error(r, f"{tmp_path / 'k.h5'}: cannot write (No space left on device)")
    assert _listing(tmp_path) == []


def test_cli_perturb_on_a_read_only_disk(runner, tmp_path, full_disk):
    full_disk(errno.EROFS)
    r = runner.invoke(app, ["perturb", "--keyboard", KB, "--dx", "3", "--dy", "1",
                            "-o", str(tmp_path / "s.h5")])
    one_line_error(r, "s.h5: cannot write (Read-only file system)")
    assert _listing(tmp_path) == []


def test_cli_play_wav_failure_keeps_no_history(runner, tmp_path, full_disk):
    full_disk(only=".wav")
    r = runner.invoke(app, ["play", "--model", MODEL, "--steps", "20", "-o",
                            str(tmp_path / "h.h5"), "--wav", str(tmp_path / "h.wav")])
    assert r.exit_code == 1, r.output
    assert "wrote" not in r.output
    assert r.output.strip().splitlines()[-1] == \
        f"kbcli: error: {tmp_path / 'h.wav'}: cannot write (No space left on device)"
    assert _listing(tmp_path) == []


def test_cli_play_history_failure_keeps_no_wav(runner, tmp_path, full_disk):
    full_disk(only=".h.h5.")
    r = runner.invoke(app, ["play", "--model", MODEL, "--steps", "20", "-o",
                            str(tmp_path / "h.h5"), "--wav", str(tmp_path / "h.wav")])
    one_line_error(r, "h.h5: cannot write (No space left on device)")
    assert _listing(tmp_path) == []


def test_cli_report_failure_leaves_no_folder(runner, tmp_path, monkeypatch):
    import matplotlib.figure

    def fail(self, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", fail)
    r = runner.invoke(app, ["report", EVALUATION, "-o", str(tmp_path / "rep"),
                            "--replicates", "2"])  # bootstrap replicates: 2, not 100 (faster)
    one_line_error(r, "No space left on device")
    assert _listing(tmp_path) == []


def test_cli_report_failure_keeps_the_old_report(runner, tmp_path, monkeypatch):
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "README.md").write_text("# old report\n\nGenerated by `kbcli report` from e.h5\n")
    import matplotlib.figure

    def fail(self, *a, **k):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", fail)
    r = runner.invoke(app, ["report", EVALUATION, "-o", str(rep), "--replicates", "2"])
    one_line_error(r, "Input/output error")
    assert _listing(rep) == ["README.md"] and (rep / "README.md").read_text().startswith(
        "# old report")
    assert _listing(tmp_path) == ["rep"]


def test_cli_os_error_names_the_path(runner, tmp_path, monkeypatch):
    from kbcli.stages import keyboard as keyboard_stage

    def fail(*a, **k):
        raise PermissionError(errno.EACCES, "Permission denied", "/some/file")

    monkeypatch.setattr(keyboard_stage, "run", fail)
    r = runner.invoke(app, ["keyboard", "-o", str(tmp_path / "k.h5")])
    one_line_error(r, "/some/file: Permission denied")
    assert _listing(tmp_path) == []


# -- two writers --------------------------------------------------------------------------------------
def test_second_writer_is_refused(runner, tmp_path):
    out = tmp_path / "k.h5"
    lf = lock.lock_file(out)
    lf.write_text(f"{os.getppid()}\n")  # a live process holds it
    r = runner.invoke(app, ["keyboard", "-o", str(out)])
    one_line_error(r, f"{out}: another kbcli (pid {os.getppid()}) is writing it")
    assert _listing(tmp_path) == [lf.name] and lf.read_text() == f"{os.getppid()}\n"


def test_lock_of_a_killed_run_is_taken_over(runner, tmp_path):
    out = tmp_path / "k.h5"
    lock.lock_file(out).write_text(f"{_dead_pid()}\n")
    r = runner.invoke(app, ["keyboard", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert _listing(tmp_path) == ["k.h5"]  # the lock is gone too


def test_lock_released_after_a_failure(runner, tmp_path, full_disk):
    full_disk()
    r = runner.invoke(app, ["keyboard", "-o", str(tmp_path / "k.h5")])
    assert r.exit_code == 1
    assert lock.held() == [] and _listing(tmp_path) == []


def test_lock_is_reentrant_and_released(tmp_path):
    a = lock.acquire(tmp_path / "x")
    b = lock.acquire(tmp_path / "x")
    assert a == b and a.exists()
    lock.release(a)
    assert a.exists()
    lock.release(b)
    assert not a.exists() and lock.held() == []


def test_lock_in_an_unwritable_folder_is_skipped(tmp_path):
    assert lock.acquire(tmp_path / "missing" / "x") is None


def test_two_writers_in_real_processes(tmp_path):
    """Another process holds the output's lock (as a running kbcli does): a real ``kbcli
    keyboard`` on that output is refused with one line and leaves the lock alone."""
    out = tmp_path / "k.h5"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom kbcli.io import lock\n"
         f"lock.acquire({str(out)!r})\nprint('held', flush=True)\nsys.stdin.read()\n"
         "lock.release_all()\n"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    assert holder.stdout.readline().strip() == "held"
    second = subprocess.run([sys.executable, "-m", "kbcli", "keyboard", "-o", str(out)],
                            capture_output=True, text=True, env=env, timeout=60)
    holder.communicate("", timeout=30)
    assert second.returncode == 1
    assert second.stderr.strip().splitlines() == [
        f"kbcli: error: {out}: another kbcli (pid {holder.pid}) is writing it; wait for it to "
        f"finish or choose another output name"]
    assert _listing(tmp_path) == []  # the holder released its lock; nothing was written


# -- signals -----------------------------------------------------------------------------------------
def test_exit_codes():
    assert signals.exit_code(signals.Terminated()) == 143
    assert signals.exit_code(KeyboardInterrupt()) == 130
    assert signals.what(signals.Terminated()) == "terminated"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as fh:  # a zombie waiting for its reaper is gone too
        return fh.read().split()[2] != "Z"


def _wait_gone(pids, seconds: float = 10.0) -> list[int]:
    deadline = time.monotonic() + seconds
    left = list(pids)
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = [p for p in left if _alive(p)]
    return left


def test_evaluate_sigterm_keeps_the_checkpoint_and_stops_the_workers(tmp_path):
    # 1800 experiments, far more than run before the signal: on a loaded machine the parent can
    # get the workers' results late and in one burst, and a short run (180) was once all written
    # and exiting (status 0) by the time SIGTERM arrived
    out = tmp_path / "e.h5"
    cmd = [sys.executable, "-m", "kbcli", "evaluate", "--config",
           str(ROOT / "pipelines" / "golden.toml"), "--model", MODEL, "--experiments", "200",
           "--checkpoint-every", "1", "--jobs", "2", "-o", str(out)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    part = Checkpoint.beside(out) / "part-000001.h5"
    # the first part is written within seconds on an idle machine; at a load average of 12 on 2
    # cores it took over 60 s, SIGTERM came before any experiment had finished, and the test failed
    deadline = time.monotonic() + 300
    while not part.exists() and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)
    children = [int(x) for x in subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True,
                                               text=True).stdout.split()]
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 143, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kbcli: terminated; "), err
    assert f"kept in {Checkpoint.beside(out)}: rerun with --resume to continue" in lines[0]
    assert _listing(tmp_path) == ["e.h5.ckpt"]  # no output, no lock, no temporary file
    ck = _listing(tmp_path / "e.h5.ckpt")
    assert ck[0] == "meta.json" and all(n.startswith("part-") for n in ck[1:]) and len(ck) > 1
    assert children and _wait_gone(children) == []


def test_a_worker_never_outlives_its_killed_parent():
    """A local worker (:func:`kbcli.io.runner.run_local_tasks`) exits when its parent is killed
    with SIGKILL, which no handler can catch."""
    worker = ("import os, sys, time\nfrom kbcli.io.processes import watch_parent\n"
              "watch_parent(os.getppid(), every=0.05)\nprint('ready', flush=True)\n"
              "time.sleep(60)\n")
    parent = ("import subprocess, sys\n"
              f"w = subprocess.Popen([sys.executable, '-c', {worker!r}], stdout=subprocess.PIPE, "
              "text=True)\n"
              "w.stdout.readline()\nprint(w.pid, flush=True)\nimport time\ntime.sleep(60)\n")
    p = subprocess.Popen([sys.executable, "-c", parent], stdout=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    wpid = int(p.stdout.readline())
    assert _alive(wpid)
    p.kill()
    p.wait()
    assert _wait_gone([wpid], 5.0) == []


@pytest.fixture
def sigint_heard():
    """Children that hear Ctrl-C (a test suite started in the background inherits an ignored
    SIGINT, and so would its children; a handled one is reset to the default at exec)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


@pytest.mark.parametrize(("sig", "code", "line"), [(signal.SIGTERM, 143, "kbcli: terminated"),
                                                   (signal.SIGINT, 130, "kbcli: interrupted")])
def test_learn_signal(tmp_path, sig, code, line, sigint_heard):
    out = tmp_path / "m.h5"
    p = subprocess.Popen([sys.executable, "-m", "kbcli", "learn", "--keyboard", KB, "--budget",
                          "20000", "-o", str(out)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    lf = lock.lock_file(out)
    deadline = time.monotonic() + 60
    while not lf.exists() and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)
    time.sleep(0.3)
    p.send_signal(sig)
    _, err = p.communicate(timeout=30)
    assert p.returncode == code, err
    assert err.strip().splitlines() == [line]
    assert _listing(tmp_path) == []


# -- bounds ------------------------------------------------------------------------------------------
def test_jobs_capped_with_a_note():
    cores = processes.usable_cores()
    jobs, note = processes.cap_jobs(10_000)
    assert jobs == cores and f"--jobs 10000 is more than the {cores} cores" in note
    assert processes.cap_jobs(1) == (1, None)
    assert processes.cap_jobs(0) == (0, None)  # refused later, with its own message


def test_jobs_option_notes_on_stderr(capsys):
    from kbcli.cli.options import _cap_jobs

    assert _cap_jobs(10_000) == processes.usable_cores()
    assert "kbcli: --jobs 10000 is more than" in capsys.readouterr().err


@pytest.mark.parametrize("args", [
    ["play", "--model", MODEL, "--steps", "1000000000", "-o", "{out}"],
    ["run", "--model", MODEL, "--scene", SCENE, "--steps", "1000000000", "-o", "{out}"],
    ["run", "--model", MODEL, "--scene", SCENE, "--max-adapt-steps", "1000000000", "-o",
     "{out}"],
    ["play", "--model", MODEL, "--melody", " ".join(["A:1"] * 5000), "-o", "{out}"],
])
def test_oversized_counts_refused_quickly(runner, tmp_path, args):
    t0 = time.monotonic()
    r = runner.invoke(app, [a.replace("{out}", str(tmp_path / "o.h5")) for a in args])
    assert r.exit_code in (1, 2), r.output
    assert "Traceback" not in r.output
    assert time.monotonic() - t0 < 5
    assert _listing(tmp_path) == []


def test_serve_max_steps_bounded():
    from kbcli.errors import ConfigError
    from kbcli.stages.serve import MAX_SERVE_STEPS, ServeConfig

    with pytest.raises((ConfigError, ValueError)):
        ServeConfig.from_dict({"max_steps": MAX_SERVE_STEPS + 1})


# -- no silent guesses -------------------------------------------------------------------------------
def test_adapt_snapshots_beyond_max_steps_noted(runner, tmp_path):
    r = runner.invoke(app, ["adapt", "--model", MODEL, "--scene", SCENE, "-T", "2",
                            "--resolution", "2", "--prior-halfwidth", "15",
                            "--snapshots", "0,1,50", "-o", str(tmp_path / "r.h5")])
    assert r.exit_code == 0, r.output
    assert "--snapshots 50 beyond --max-steps 2: not recorded" in r.output


def test_run_follows_the_scene_family(runner, tmp_path, monkeypatch):
    from kbcli.stages import run as run_stage

    seen = {}

    class Stop(Exception):
        pass

    def capture(cfg, *a, **k):
        seen["family"] = cfg.adapt.family
        raise KbcliError("stop here")

    monkeypatch.setattr(run_stage, "LoopSession", capture)
    scene = tmp_path / "rigid.h5"
    r = runner.invoke(app, ["perturb", "--keyboard", KB, "--dx", "5", "--dy", "2", "--angle",
                            "3", "-o", str(scene)])
    assert r.exit_code == 0, r.output
    runner.invoke(app, ["run", "--model", MODEL, "--scene", str(scene), "-o",
                        str(tmp_path / "l.h5")])
    assert seen["family"] == "rigid"
    runner.invoke(app, ["run", "--model", MODEL, "--scene", SCENE, "-o", str(tmp_path / "l.h5")])
    assert seen["family"] == "translation"


# -- hostile serve clients ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def session_factory():
    from kbcli.stages.serve import ServeConfig, Session

    model = read_artifact(MODEL)

    def make(**cfg):
        base = {"resolution": 2.0, "prior_halfwidth": 15.0, "max_steps": 5}
        return Session(ServeConfig.from_dict({**base, **cfg}), model,
                       rng=np.random.default_rng(0), seed=0)

    return make


def _sound(session) -> list[float]:
    """The features of a sound the model knows."""
    return [float(v) for v in np.asarray(session.model.class_features_)[1]]


@pytest.mark.parametrize(("felt", "words"), [
    ("[1000000, 1000000]", "far outside the working area"),
    ("[-1e6, 300]", "far outside the working area"),
    ("[1e999, 0]", "felt[0] is not a finite number"),
    ("[NaN, 0]", "not a number JSON allows"),
    ("[Infinity, 0]", "not a number JSON allows"),
    ("[1, 2, 3]", "felt must be a list of 2 numbers"),
    ("[\"1\", 2]", "felt[0] must be a number"),
    ("[true, 2]", "felt[0] must be a number"),
])
def test_serve_refuses_bad_felt(session_factory, felt, words):
    s = session_factory()
    heard = json.dumps(_sound(s))
    reply = s.handle(f'{{"heard": {heard}, "felt": {felt}, "id": 7}}')
    assert reply["type"] == "error" and words in reply["error"]
    assert reply.get("id") == (None if "JSON" in words else 7)
    assert s.steps == 0 and s.errors == 1


def test_serve_accepts_felt_near_the_area(session_factory):
    s = session_factory()
    x0, y0, x1, y1 = (float(v) for v in s.adapter.area)
    reply = s.handle(json.dumps({"heard": _sound(s), "felt": [x0 - 3.0, y0]}))
    assert reply["type"] == "step" and s.steps == 1


@pytest.mark.parametrize("heard", ["[1e9, 1e9]", "[-5000, 3]"])
def test_serve_refuses_a_sound_the_model_does_not_know(session_factory, heard):
    s = session_factory()
    reply = s.handle(f'{{"heard": {heard}}}')
    assert reply["type"] == "error" and "matches no sound of the model" in reply["error"]
    assert s.steps == 0 and s.errors == 1
    reply = s.handle(f'{{"heard": {heard}, "insist": true}}')
    assert reply["type"] == "step" and reply["class"] == -1 and s.steps == 1


@pytest.mark.parametrize("insist", ['"yes"', "1", "null"])
def test_serve_insist_must_be_a_flag(session_factory, insist):
    s = session_factory()
    reply = s.handle(f'{{"heard": null, "insist": {insist}}}')
    assert reply["type"] == "error" and "insist must be true or false" in reply["error"]
    assert s.steps == 0


@pytest.mark.parametrize(("line", "words"), [
    ('{"heard": [1e999, 2]}', "heard[0] is not a finite number"),
    ('{"heard": null, "action": [1e9, 1e9]}', "outside the working area"),
    ('{"heard": "loud"}', "heard must be a list"),
    ("[]", "a message is a JSON object"),
    ('{"heard": null, "felt": {"x": 1}}', "felt must be a list"),
    ("\x00\x01", "not JSON"),
])
def test_serve_hostile_messages_are_not_touches(session_factory, line, words):
    s = session_factory()
    reply = s.handle(line)
    assert reply["type"] == "error" and words in reply["error"]
    assert s.steps == 0


def test_serve_stdio_hostile_client(tmp_path):
    """A real ``kbcli serve`` over stdio: garbage, an oversized line, a million-px felt, then a
    good touch and the end: every bad line gets an error reply, the artifact holds one touch."""
    out = tmp_path / "s.h5"
    from kbcli.stages.serve import MAX_LINE

    lines = ["not json", "x" * (MAX_LINE + 10), '{"heard": null, "felt": [1e6, 1e6]}',
             '{"heard": [1e9, 1e9]}', '{"heard": null}', '{"op": "end"}']
    p = subprocess.run(
        [sys.executable, "-m", "kbcli", "serve", "--model", MODEL, "--resolution", "2",
         "--prior-halfwidth", "15", "-o", str(out)],
        input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=60,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr
    replies = [json.loads(x) for x in p.stdout.splitlines()]
    kinds = [r["type"] for r in replies]
    assert kinds == ["hello", "error", "error", "error", "error", "step", "bye"], kinds
    art = read_artifact(out)
    assert art.attrs["message_errors"] == 4 and len(art.data["actions"]) == 1
    assert _listing(tmp_path) == ["s.h5"]


# -- config files that are not files -----------------------------------------------------------------
def test_config_folder(tmp_path):
    from kbcli.errors import ConfigError
    from kbcli.io.config import load_toml

    with pytest.raises(ConfigError, match="is a folder, expected a TOML config file"):
        load_toml(tmp_path)


def test_config_device():
    from kbcli.errors import ConfigError
    from kbcli.io.config import load_toml

    with pytest.raises(ConfigError, match="/dev/null: is a device"):
        load_toml("/dev/null")


def test_config_fifo_does_not_block(tmp_path):
    from kbcli.errors import ConfigError
    from kbcli.io.config import load_toml

    fifo = tmp_path / "c.toml"
    os.mkfifo(fifo)
    t0 = time.monotonic()
    with pytest.raises(ConfigError, match="is a FIFO"):
        load_toml(fifo)
    assert time.monotonic() - t0 < 1


def test_config_oversized(tmp_path):
    from kbcli.errors import ConfigError
    from kbcli.io.config import MAX_CONFIG_BYTES, load_toml

    big = tmp_path / "c.toml"
    big.write_text("# " + "x" * MAX_CONFIG_BYTES)
    with pytest.raises(ConfigError, match="more than a config file may hold"):
        load_toml(big)


def test_cli_config_folder_one_line(runner, tmp_path):
    r = runner.invoke(app, ["adapt", "--model", MODEL, "--scene", SCENE, "--config",
                            str(tmp_path), "-o", str(tmp_path / "r.h5")])
    assert r.exit_code in (1, 2) and "Traceback" not in r.output
    assert "no such config file" not in r.output
    assert not (tmp_path / "r.h5").exists()


def test_sigterm_handler_restored_after_a_command(runner, tmp_path):
    before = signal.getsignal(signal.SIGTERM)
    r = runner.invoke(app, ["keyboard", "-o", str(tmp_path / "k.h5")])
    assert r.exit_code == 0
    assert signal.getsignal(signal.SIGTERM) is before


def test_terminated_inside_a_command_exits_143(runner, tmp_path, monkeypatch):
    from kbcli.stages import keyboard as keyboard_stage

    def killed(*a, **k):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)

    monkeypatch.setattr(keyboard_stage, "run", killed)
    r = runner.invoke(app, ["keyboard", "-o", str(tmp_path / "k.h5")])
    assert r.exit_code == 143 and r.output.strip() == "kbcli: terminated"
    assert _listing(tmp_path) == []


def test_evaluate_final_write_failing_keeps_the_checkpoint_and_says_how_to_resume(
        tmp_path, monkeypatch):
    """A full disk at the evaluation's last write: one line with the cause and the --resume hint,
    the finished experiments kept, no output; --resume then writes it without running any."""
    from typer.testing import CliRunner

    import kbcli.cli.evaluate as cli_evaluate

    out = tmp_path / "e.h5"
    argv = ["evaluate", "--config", str(ROOT / "pipelines" / "golden.toml"), "--model", MODEL,
            "-o", str(out)]

    def full(*_a, **_k):
        raise ArtifactError(f"{out}: cannot write: No space left on device")

    monkeypatch.setattr(cli_evaluate, "write_artifact", full)
    r = CliRunner().invoke(app, argv)
    assert r.exit_code == 1
    line = r.output.strip()
    assert "\n" not in line and "No space left on device" in line
    assert "rerun with --resume" in line and not out.exists()
    assert Checkpoint.beside(out).is_dir()
    monkeypatch.undo()
    r = CliRunner().invoke(app, [*argv, "--resume"])
    assert r.exit_code == 0, r.output
    assert out.is_file() and not Checkpoint.beside(out).exists()


def test_quality_full_disk_at_its_first_model_leaves_no_checkpoint(tmp_path, monkeypatch):
    """The sweep's first model cannot be written: one line, exit 1, and no empty checkpoint."""
    from typer.testing import CliRunner

    import kbcli.cli.quality as cli_quality

    out = tmp_path / "q.h5"

    def full(art, path, *a, **k):
        raise ArtifactError(f"{path}: cannot write: No space left on device")

    monkeypatch.setattr(cli_quality, "write_artifact", full)
    r = CliRunner().invoke(app, ["quality", "--config", str(ROOT / "pipelines" / "golden.toml"),
                                 "--keyboard", str(GOLDEN / "keyboard.h5"), "-o", str(out)])
    assert r.exit_code == 1, r.output
    assert "No space left on device" in r.output and "Traceback" not in r.output
    assert not out.exists() and not Checkpoint.beside(out).exists()


@pytest.mark.parametrize("head", [
    "1 tasks have been successfully executed  but not used.",
    "4 tasks which were still being processed by the workers have been cancelled.",
    "2 tasks have been successfully executed  but not used. Additionally, 3 tasks which were "
    "still being processed by the workers have been cancelled.",
])
def test_joblibs_cancel_warning_is_silenced_in_every_wording(head):
    import warnings

    from kbcli.io.runner import quiet_joblib_cancel

    msg = head + " You could benefit from adjusting the input task iterator to limit unnecessary " \
        "computation time."
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        quiet_joblib_cancel()
        warnings.warn(msg, stacklevel=2)
        warnings.warn("an unrelated warning", stacklevel=2)
    assert [str(w.message) for w in seen] == ["an unrelated warning"]


@pytest.fixture(params=["alone", "beside another thread"])
def threads(request):
    """The process alone, or with a second thread alive: the kernel may then hand a
    process-directed SIGTERM to that thread (CI's pytest-xdist worker has one)."""
    import threading

    if request.param == "alone":
        yield request.param
        return
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    yield request.param
    stop.set()
    other.join()


def _write_file(atomic, tmp_path):
    with atomic.atomic_paths([tmp_path / "a.h5"]) as tmps:
        Path(tmps[0]).write_bytes(b"x")


def _write_folder(atomic, tmp_path):
    with atomic.atomic_folder(tmp_path / "report") as tmp:
        (tmp / "README.md").write_text("x")


@pytest.mark.parametrize(("maker", "write"), [("mkstemp", _write_file), ("mkdtemp", _write_folder)],
                         ids=["file", "report folder"])
def test_a_sigterm_right_after_the_temporary_file_is_made_leaves_nothing(tmp_path, monkeypatch,
                                                                         threads, maker, write):
    """The signal lands between mkstemp (mkdtemp: a report's folder) and the cleanup knowing
    the temporary (CI saw .part-000007.h5.kbcli-tmp-*.tmp left in a checkpoint, and later, with
    another thread alive, .a.h5.kbcli-tmp-*.tmp here): it is deferred, then removes it."""
    import tempfile

    from kbcli.io import atomic, signals

    real = getattr(tempfile, maker)

    def make_then_sigterm(*args, **kwargs):
        made = real(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)  # time for another thread to take the signal
        return made

    monkeypatch.setattr(atomic.tempfile, maker, make_then_sigterm)
    old = signals.install()
    try:
        with pytest.raises(signals.Terminated):
            write(atomic, tmp_path)
    finally:
        signals.restore(old)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_stop_that_hangs_after_sigterm_is_cut_short_in_the_cli_process():
    """A clean stop that never ends (a worker pool that will not shut down: CI once saw evaluate
    still alive 30 s after SIGTERM) ends 143 after ``GRACE_S`` in the process the CLI runs in."""
    script = ("import sys, threading, time\nfrom kbcli.io import signals\n"
              "signals.GRACE_S = 1.0\nsignals.bound_the_stop()\nsignals.install()\n"
              "threading.Thread(target=time.sleep, args=(60,)).start()  # exit waits for it\n"
              "print('ready', flush=True)\n"
              "try:\n    time.sleep(60)\nexcept signals.Terminated:\n    sys.exit(143)\n")
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.stdout.readline().strip() == "ready"
    start = time.monotonic()
    p.send_signal(signal.SIGTERM)
    p.communicate(timeout=30)
    assert p.returncode == 143 and time.monotonic() - start < 20


@pytest.mark.parametrize(("sig", "code", "word"), [(signal.SIGTERM, 143, "terminated"),
                                                   (signal.SIGINT, 130, "interrupted")])
def test_a_stop_that_lands_in_a_finaliser_is_not_lost(sig, code, word, sigint_heard):
    """Python drops an exception raised inside a ``__del__`` or a weakref callback: CI saw the
    SIGTERM of evaluate lost so ("Exception ignored in: ... WeakValueDictionary ... Terminated")
    and the run went on. In the CLI's process the stop (SIGTERM or Ctrl-C) is delivered again,
    and caught."""
    script = ("import sys, time\nfrom kbcli.io import signals\n"
              "signals.GRACE_S = 60.0\nsignals.bound_the_stop()\nsignals.install()\n"
              "class Slow:\n    def __del__(self):\n        print('finalising', flush=True)\n"
              "        time.sleep(3)  # the signal lands here\n"
              "x = Slow()\nprint('ready', flush=True)\nsys.stdin.readline()\n"
              "try:\n    del x\n    time.sleep(10)\n    print('went on', flush=True)\n"
              "except KeyboardInterrupt as exc:\n    print(signals.what(exc), flush=True)\n"
              "    sys.exit(signals.exit_code(exc))\n")
    p = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.stdout.readline().strip() == "ready"
    p.stdin.write("\n")
    p.stdin.flush()
    assert p.stdout.readline().strip() == "finalising"
    start = time.monotonic()
    p.send_signal(sig)
    out, err = p.communicate(timeout=30)
    assert p.returncode == code and out.strip() == word, (out, err)
    assert time.monotonic() - start < 5 and "Exception ignored" not in err
