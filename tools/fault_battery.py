"""The fault battery of issue 29: the real ``kbcli`` CLI, as a user runs it, against a misbehaving
machine, input and robot. Prints one row per case: exit code, stderr line count, what was left on
disk, and the verdict (``clean`` or what was not).

    python tools/fault_battery.py                 # every case (a few minutes on 2 cores)
    python tools/fault_battery.py -k disk -j 2    # only the cases whose name holds "disk"
    python tools/fault_battery.py --json out.json # also the rows as JSON

Classes: ``disk`` (a real full disk: a small tmpfs filled to 0 bytes, or to a few kB, free, on every
command that writes), ``ro`` (a read-only file system), ``signal`` (SIGINT to the process group as
Ctrl-C sends it, SIGTERM and SIGKILL to kbcli, mid-run; after SIGKILL the command is run again and
must remove the killed run's temporary files), ``writers`` (two kbcli on one output), ``bounds``
(oversized counts: refused in one line naming the bound, within 5 s of the interpreter's start-up,
under 1 GB), ``serve`` (hostile robot clients), ``config`` (a folder, FIFO, device... as --config),
``notes`` (dropped or capped options say so).

A case is clean when: the exit code is the expected one; stderr holds the expected number of
lines (one ``kbcli: error: ...`` line for a refusal), no traceback; nothing is left in its folder
but what it should keep; no input file changed; no process it started outlives it (found by an
environment tag every child inherits); it ended before its timeout; its peak memory stayed under
1 GB. The tmpfs and read-only cases need root (``mount``); without it they are skipped.

Runs with the kbcli of this checkout (``PYTHONPATH`` is set to it).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import contextlib
import fnmatch
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "data" / "golden"
PIPELINES = ROOT / "pipelines"
TAG = "KBCLI_FAULT_BATTERY"
GB = 1 << 30
REFUSAL_SECONDS = 5.0
TMP = "*.kbcli-tmp-*"
LOCK = ".*.kbcli-lock"


@dataclass
class Case:
    """One fault: run ``argv`` (placeholders ``{d}`` the case folder, ``{in}`` the inputs folder,
    ``{g}`` data/golden, ``{p}`` pipelines) and judge what happened."""

    name: str
    cls: str
    argv: list[str]
    expect: tuple[int, ...] = (1,)
    lines: int | None = 1                 # non-empty stderr lines (None: any)
    words: tuple[str, ...] = ()           # fragments stderr must hold
    keep: tuple[str, ...] = ()            # globs (relative to the case folder) allowed to remain
    disk: str | None = None               # "full", "free:KB", "ro"
    stdin: str | None = None
    sig: int | None = None                # signal sent mid-run
    to_group: bool = False                # sent to the process group (Ctrl-C) or kbcli alone
    trigger: str | None = None            # glob in the case folder that starts the signal
    delay: float = 0.0                    # seconds after the start-up (or the trigger)
    timeout: float = 180.0
    quick: bool = False                   # a refusal: within REFUSAL_SECONDS of the start-up
    setup: Callable[[Path], None] | None = None
    check: Callable[[Path, Result], str | None] | None = None
    rerun: list[str] | None = None        # after SIGKILL: run again, then judge the folder
    holder: list[str] | None = None       # another kbcli started first, holding the output
    stdout_check: Callable[[str], str | None] | None = None


@dataclass
class Result:
    name: str
    cls: str
    code: int | None = None
    err_lines: int = 0
    leftovers: list[str] = field(default_factory=list)
    seconds: float = 0.0
    rss_mb: float = 0.0
    problems: list[str] = field(default_factory=list)
    stderr: str = ""
    stdout: str = ""

    @property
    def verdict(self) -> str:
        if self.problems and self.problems[0].startswith("skipped"):
            return self.problems[0]
        return "clean" if not self.problems else "; ".join(self.problems)


# -- the machine: tmpfs mounts, processes ------------------------------------------------------------
def _mount(folder: Path, size_kb: int, ro: bool = False) -> bool:
    opts = f"size={size_kb}k" + (",ro" if ro else "")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(folder)],
                       capture_output=True)
    return r.returncode == 0


def _umount(folder: Path) -> None:
    subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def _fill(folder: Path, free_kb: int) -> None:
    """Fill the tmpfs at ``folder`` to ENOSPC, then free ``free_kb`` kB."""
    filler = folder / ".filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        with contextlib.suppress(OSError):
            while True:
                os.write(fd, b"\0" * 4096)
    finally:
        os.close(fd)
    size = filler.stat().st_size
    os.truncate(filler, max(0, size - free_kb * 1024))


def _tagged(tag: str) -> list[int]:
    """Processes whose environment holds ``TAG=tag`` (every process a case started)."""
    needle = f"{TAG}={tag}".encode()
    pids = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as fh:
                if needle in fh.read().split(b"\0"):
                    pids.append(int(entry))
        except OSError:
            continue
    return pids


def _wait(p: subprocess.Popen, timeout: float) -> tuple[int | None, float]:
    """Wait for ``p`` (at most ``timeout`` s); its exit code (negative: the signal) and peak RSS."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
        except ChildProcessError:  # already reaped by a p.poll() (the signal cases' trigger loop)
            return p.returncode, 0.0
        if pid:
            p.returncode = os.waitstatus_to_exitcode(status)
            return p.returncode, usage.ru_maxrss / 1024
        time.sleep(0.05)
    return None, 0.0


def _env(tag: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("CI",)}
    env["PYTHONPATH"] = str(ROOT)
    env[TAG] = tag
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def _start(argv: list[str], tag: str, folder: Path, stdin: str | None) -> subprocess.Popen:
    out = open(folder.parent / f"{folder.name}.out", "w")  # noqa: SIM115
    err = open(folder.parent / f"{folder.name}.err", "w")  # noqa: SIM115
    return subprocess.Popen([sys.executable, "-m", "kbcli", *argv], cwd=folder.parent,
                            env=_env(tag), stdin=subprocess.PIPE if stdin is not None else
                            subprocess.DEVNULL, stdout=out, stderr=err, start_new_session=True)


def _listing(folder: Path) -> list[str]:
    if not folder.exists():
        return []
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.name != ".filler")


def _digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(p.name.encode())
            h.update(p.read_bytes())
    return h.hexdigest()


# -- running a case ----------------------------------------------------------------------------------
class Battery:
    def __init__(self, base: Path, startup: float) -> None:
        self.base = base
        self.inputs = base / "inputs"
        self.startup = startup
        self.can_mount = os.geteuid() == 0
        self.running: set[subprocess.Popen] = set()
        self.mounts: set[Path] = set()
        self.stopping = False

    def stop(self) -> None:
        """Kill the processes of the running cases (by their process groups) and unmount."""
        self.stopping = True
        for p in list(self.running):
            with contextlib.suppress(OSError):
                os.killpg(p.pid, signal.SIGKILL)
        time.sleep(1.0)
        for m in list(self.mounts):
            _umount(m)

    def start(self, argv: list[str], tag: str, folder: Path, stdin: str | None
              ) -> subprocess.Popen:
        if self.stopping:
            raise RuntimeError("stopping")
        p = _start(argv, tag, folder, stdin)
        self.running.add(p)
        return p

    def fmt(self, args: list[str], d: Path) -> list[str]:
        return [a.format(d=d, g=GOLDEN, p=PIPELINES, i=self.inputs) for a in args]

    def run(self, case: Case) -> Result:
        res = Result(case.name, case.cls)
        d = self.base / case.name
        d.mkdir(parents=True)
        mounted = False
        if case.disk:
            if not self.can_mount:
                res.problems.append("skipped (needs root to mount a tmpfs)")
                return res
            mounted = _mount(d, 8192)
            if mounted:
                self.mounts.add(d)
            else:
                res.problems.append("skipped (mount failed)")
                return res
        try:
            self._run(case, d, res)
        except Exception as exc:  # the battery's own failure: shown, never hidden
            res.problems.append(f"battery error: {type(exc).__name__}: {exc}")
        finally:
            if mounted:
                _umount(d)
                self.mounts.discard(d)
        return res

    def _prepare(self, case: Case, d: Path) -> None:
        if case.setup is not None:
            case.setup(d)
        if case.disk == "ro":
            subprocess.run(["mount", "-o", "remount,ro", str(d)], check=True)
        elif case.disk == "full":
            _fill(d, 0)
        elif case.disk and case.disk.startswith("free:"):
            _fill(d, int(case.disk[5:]))

    def _run(self, case: Case, d: Path, res: Result) -> None:
        self._prepare(case, d)
        before = set(_listing(d))
        digest = _digest(self.inputs)
        tag = uuid.uuid4().hex
        holder = self._hold(case, d, tag + "h") if case.holder else None
        t0 = time.monotonic()
        p = self.start(self.fmt(case.argv, d), tag, d, case.stdin)
        if case.stdin is not None:
            with contextlib.suppress(BrokenPipeError, OSError):
                p.stdin.write(case.stdin.encode("utf-8", "surrogateescape"))
                p.stdin.close()
        if case.sig is not None:
            self._signal(case, d, p)
        res.code, res.rss_mb = _wait(p, case.timeout)
        res.seconds = time.monotonic() - t0
        if res.code is None:
            res.problems.append(f"hang (> {case.timeout:g} s)")
            with contextlib.suppress(OSError):
                os.killpg(p.pid, signal.SIGKILL)
            _wait(p, 10)
        if holder is not None:
            self._release(holder)
        res.stderr = (d.parent / f"{d.name}.err").read_text(errors="replace")
        res.stdout = (d.parent / f"{d.name}.out").read_text(errors="replace")
        self._orphans(tag, res)
        if case.rerun is not None and res.code is not None:
            self._rerun(case, d, tag, res)
        self._judge(case, d, before, res)
        if _digest(self.inputs) != digest:
            res.problems.append("an input changed")

    def _signal(self, case: Case, d: Path, p: subprocess.Popen) -> None:
        end = time.monotonic() + case.timeout
        if case.trigger is not None:
            while time.monotonic() < end and p.poll() is None:
                if any(fnmatch.fnmatch(x, case.trigger) for x in _listing(d)):
                    break
                time.sleep(0.02)
        else:
            time.sleep(self.startup)
        time.sleep(case.delay)
        if p.poll() is None:
            with contextlib.suppress(OSError):
                if case.to_group:
                    os.killpg(p.pid, case.sig)
                else:
                    os.kill(p.pid, case.sig)

    def _hold(self, case: Case, d: Path, tag: str) -> subprocess.Popen:
        h = subprocess.Popen([sys.executable, "-m", "kbcli", *self.fmt(case.holder, d)],
                             cwd=d.parent, env=_env(tag), stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
        end = time.monotonic() + 60
        while time.monotonic() < end and not any(fnmatch.fnmatch(x, LOCK) for x in _listing(d)):
            time.sleep(0.05)
        time.sleep(0.3)
        return h

    def _release(self, h: subprocess.Popen) -> None:
        with contextlib.suppress(OSError):
            os.killpg(h.pid, signal.SIGINT)
        if _wait(h, 30)[0] is None:
            with contextlib.suppress(OSError):
                os.killpg(h.pid, signal.SIGKILL)
            _wait(h, 10)

    def _orphans(self, tag: str, res: Result) -> None:
        end = time.monotonic() + 6.0  # a worker notices its parent's death within ~1 s
        left = _tagged(tag)
        while left and time.monotonic() < end:
            time.sleep(0.2)
            left = _tagged(tag)
        if left:
            res.problems.append(f"{len(left)} orphan process(es)")
            for pid in left:
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)

    def _rerun(self, case: Case, d: Path, tag: str, res: Result) -> None:
        half = [x for x in _listing(d) if not fnmatch.fnmatch(Path(x).name, TMP)
                and not fnmatch.fnmatch(Path(x).name, LOCK) and "ckpt" not in x]
        for x in half:
            if (d / x).is_file() and x.endswith(".h5"):
                r = subprocess.run([sys.executable, "-m", "kbcli", "inspect", str(d / x)],
                                   env=_env(tag + "i"), capture_output=True, cwd=d.parent)
                if r.returncode != 0:
                    res.problems.append(f"half-written {x} after SIGKILL")
        p = self.start(self.fmt(case.rerun, d), tag + "r", d, None)
        code, _ = _wait(p, case.timeout)
        if code != 0:
            err = (d.parent / f"{d.name}.err").read_text(errors="replace").strip()
            res.problems.append(f"rerun exit {code}: {err[-200:]}")
        self._orphans(tag + "r", res)

    def _judge(self, case: Case, d: Path, before: set[str], res: Result) -> None:
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        res.err_lines = len(lines)
        if res.code is not None and res.code not in case.expect:
            res.problems.append(f"exit {res.code}, expected {'/'.join(map(str, case.expect))}")
        if "Traceback" in res.stderr or "Segmentation" in res.stderr:
            res.problems.append("traceback")
        if case.lines is not None and len(lines) != case.lines:
            res.problems.append(f"{len(lines)} stderr lines, expected {case.lines}")
        if case.expect == (1,) and lines and not lines[-1].startswith("kbcli: error:"):
            res.problems.append("no 'kbcli: error:' line")
        for w in case.words:
            if w not in res.stderr:
                res.problems.append(f"stderr lacks {w!r}")
        keep = case.keep
        res.leftovers = [x for x in _listing(d) if x not in before and not any(
            fnmatch.fnmatch(x, k) or fnmatch.fnmatch(x.split("/")[0], k) for k in keep)]
        if res.leftovers:
            res.problems.append("leftovers")
        if case.quick and res.seconds - self.startup > REFUSAL_SECONDS:
            res.problems.append(f"slow refusal ({res.seconds - self.startup:.1f} s after start-up)")
        if res.rss_mb > 1024:
            res.problems.append(f"{res.rss_mb:.0f} MB")
        if case.check is not None and (msg := case.check(d, res)):
            res.problems.append(msg)
        if case.stdout_check is not None and (msg := case.stdout_check(res.stdout)):
            res.problems.append(msg)


def measure_startup() -> float:
    """Seconds for ``kbcli --version`` (the interpreter and kbcli's imports): refusals are timed
    from there (median of 3)."""
    times = []
    for _ in range(3):
        t0 = time.monotonic()
        subprocess.run([sys.executable, "-m", "kbcli", "--version"], env=_env("startup"),
                       capture_output=True)
        times.append(time.monotonic() - t0)
    return sorted(times)[1]


# -- report ------------------------------------------------------------------------------------------
def table(results: list[Result]) -> str:
    rows = [("case", "exit", "err", "left", "s", "MB", "verdict")]
    for r in results:
        left = ",".join(r.leftovers)
        rows.append((r.name, "-" if r.code is None else str(r.code), str(r.err_lines),
                     (left[:40] + "...") if len(left) > 40 else (left or "-"),
                     f"{r.seconds:.1f}", f"{r.rss_mb:.0f}", r.verdict))
    widths = [max(len(row[i]) for row in rows) for i in range(6)]
    out = []
    for row in rows:
        out.append("  ".join(c.ljust(w) for c, w in zip(row[:6], widths, strict=True))
                   + "  " + row[6])
    return "\n".join(out)


def summary(results: list[Result]) -> str:
    ran = [r for r in results if not r.verdict.startswith("skipped")]
    clean = sum(r.verdict == "clean" for r in ran)
    by: dict[str, list[int]] = {}
    for r in ran:
        by.setdefault(r.cls, [0, 0])
        by[r.cls][0] += 1
        by[r.cls][1] += r.verdict == "clean"
    per = ", ".join(f"{c} {k}/{n}" for c, (n, k) in sorted(by.items()))
    skipped = len(results) - len(ran)
    return (f"{clean} of {len(ran)} cases clean ({per})"
            + (f"; {skipped} skipped" if skipped else ""))


def main(argv: list[str] | None = None) -> int:
    from fault_cases import all_cases  # noqa: PLC0415 (tools/ is the script's folder)

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-k", default=None, help="only cases whose name or class holds this")
    ap.add_argument("-j", "--jobs", type=int, default=1, help="cases run at once")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    ap.add_argument("--show", action="store_true", help="print each unclean case's stderr")
    args = ap.parse_args(argv)
    # A shell starts a background job with SIGINT ignored, and every kbcli would inherit that
    # (Python keeps an inherited SIG_IGN): the Ctrl-C cases would test nothing. Handled here, it
    # is the default again in the children (an exec resets handled signals).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    cases = [c for c in all_cases() if args.k is None or args.k in c.name or args.k == c.cls]
    base = Path(tempfile.mkdtemp(prefix="kbcli-faults-"))
    inputs = base / "inputs"
    shutil.copytree(GOLDEN, inputs)
    shutil.copy(PIPELINES / "golden.toml", inputs)
    startup = measure_startup()
    print(f"{len(cases)} cases in {base}; kbcli start-up {startup:.1f} s", file=sys.stderr)
    battery = Battery(base, startup)
    pool = cf.ThreadPoolExecutor(max(1, args.jobs))
    try:
        results = list(pool.map(battery.run, cases))
    except KeyboardInterrupt:  # stop every case's processes, unmount, remove the work folder
        pool.shutdown(wait=False, cancel_futures=True)
        battery.stop()
        pool.shutdown(wait=True)
        shutil.rmtree(base, ignore_errors=True)
        return 130
    pool.shutdown()
    print(table(results))
    print(summary(results))
    if args.show:
        for r in results:
            if r.verdict != "clean" and not r.verdict.startswith("skipped"):
                print(f"--- {r.name}\n{r.stderr.strip()[-2000:]}")
    if args.json:
        Path(args.json).write_text(json.dumps([{
            "case": r.name, "class": r.cls, "exit": r.code, "stderr_lines": r.err_lines,
            "leftovers": r.leftovers, "seconds": round(r.seconds, 2), "rss_mb": round(r.rss_mb),
            "verdict": r.verdict, "stderr": r.stderr[-1000:]} for r in results], indent=1))
    if not args.keep:
        shutil.rmtree(base, ignore_errors=True)
    return 0 if all(r.verdict == "clean" or r.verdict.startswith("skipped") for r in results) \
        else 1


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
