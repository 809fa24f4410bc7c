"""The cases of tools/fault_battery.py (issue 29), by class. Paths: ``{d}`` the case's own folder
(a fresh tmpfs for the disk cases), ``{i}`` a copy of data/golden/ plus pipelines/golden.toml (the
inputs, checked unchanged after every case)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from fault_battery import LOCK, ROOT, TMP, Case, Result, _env

M, S, KB = "{i}/model.h5", "{i}/scene.h5", "{i}/keyboard.h5"
SMALL = ["--resolution", "2", "--prior-halfwidth", "15"]
TOUCH = json.dumps({"op": "observe", "heard": None, "felt": [400, 350]})
END = json.dumps({"op": "end"})

#: Every command that writes, with small settings: name -> (argv, what it writes).
WRITERS: dict[str, tuple[list[str], str]] = {
    "keyboard": (["keyboard", "-o", "{d}/k.h5"], "k.h5"),
    "learn": (["learn", "--keyboard", KB, "--budget", "40", "-o", "{d}/m.h5"], "m.h5"),
    "perturb": (["perturb", "--keyboard", KB, "--dx", "5", "--dy", "3", "-o", "{d}/s.h5"],
                "s.h5"),
    "play": (["play", "--model", M, "--steps", "50", "-o", "{d}/h.h5"], "h.h5"),
    "play-wav": (["play", "--model", M, "--steps", "50", "--wav", "{d}/h.wav", "-o", "{d}/h.h5"],
                 "h.h5"),
    "detect": (["detect", "{i}/history.h5", "-o", "{d}/det.h5"], "det.h5"),
    "adapt": (["adapt", "--model", M, "--scene", S, "-T", "3", *SMALL, "--snapshots", "0,1,3",
               "-o", "{d}/r.h5"], "r.h5"),
    "run": (["run", "--model", M, "--scene", S, "--steps", "150", "--perturb-at", "110",
             "--max-adapt-steps", "5", "-o", "{d}/cl.h5"], "cl.h5"),
    "evaluate": (["evaluate", "--config", "{i}/golden.toml", "--model", M, "-o", "{d}/ev.h5"],
                 "ev.h5"),
    "report": (["report", "{i}/evaluation.h5", "-o", "{d}/rep"], "rep"),
    "report-quality": (["report", "{i}/model_quality.h5", "-o", "{d}/rep"], "rep"),
    "quality": (["quality", "--config", "{i}/golden.toml", "--keyboard", KB, "-o", "{d}/q.h5"],
                "q.h5"),
    "quality-models": (["quality", "--config", "{i}/golden.toml", "--keyboard", KB, "--models",
                        "{d}/models", "-o", "{d}/q.h5"], "q.h5"),
    "animate": (["animate", "{i}/run.h5", "--max-frames", "8", "-o", "{d}/a.gif"], "a.gif"),
    "plot-keyboard": (["plot", "keyboard", KB, "-o", "{d}/k.png"], "k.png"),
    "plot-model": (["plot", "model", M, "-o", "{d}/m.pdf"], "m.pdf"),
    "plot-play": (["plot", "play", "{i}/history.h5", "-o", "{d}/p.svg"], "p.svg"),
    "plot-adapt": (["plot", "adapt", "{i}/run.h5", "-o", "{d}/a.png"], "a.png"),
    "plot-run": (["plot", "run", "{i}/closed_loop.h5", "-o", "{d}/r.png"], "r.png"),
    "serve": (["serve", "--model", M, "-o", "{d}/s.h5", *SMALL], "s.h5"),
    "bench-json": (["bench", "--json", "{d}/b.json", "arm", "--reaches", "5"], "b.json"),
}


def _stdin(name: str) -> str | None:
    return f"{TOUCH}\n{END}\n" if name == "serve" else None


def _resume_or_nothing(d: Path, r: Result) -> str | None:
    """A checkpoint may stay only when the message says how to resume."""
    kept = [p.name for p in d.iterdir() if p.name.endswith(".ckpt")]
    if kept and "--resume" not in r.stderr:
        return f"kept {kept[0]} without saying --resume"
    return None


#: Writers whose whole output fits in 12 kB (bench --json: about 2 kB): on a disk with 12 kB free
#: they must succeed (a refusal there would be the wrong answer), not fail with ENOSPC.
FITS_12K = {"bench-json"}


def disk_cases() -> list[Case]:
    out = []
    for name, (argv, product) in WRITERS.items():
        ckpt = name.startswith(("evaluate", "quality"))
        for disk, label in (("full", "full"), ("free:12", "12k-free")):
            if disk == "free:12" and name in FITS_12K:
                out.append(Case(f"disk-{label}-{name}", "disk", argv, disk=disk, expect=(0,),
                                lines=None, keep=(product,)))
                continue
            out.append(Case(f"disk-{label}-{name}", "disk", argv, disk=disk,
                            words=("No space left on device",), stdin=_stdin(name),
                            keep=("*.ckpt",) if ckpt else (),
                            check=_resume_or_nothing if ckpt else None))
    out.append(Case("disk-200k-free-play-wav", "disk", WRITERS["play-wav"][0], disk="free:200",
                    words=("No space left on device",)))
    return out


def ro_cases() -> list[Case]:
    return [Case(f"ro-{name}", "ro", argv, disk="ro", words=("Read-only file system",),
                 stdin=_stdin(name), quick=True) for name, (argv, _) in WRITERS.items()]


# -- signals -----------------------------------------------------------------------------------------
_LONG = {
    "learn": (["learn", "--keyboard", KB, "--budget", "20000", "-o", "{d}/m.h5"], None, 3.0,
              ["learn", "--keyboard", KB, "--budget", "20", "-o", "{d}/m.h5"], "m.h5"),
    "evaluate": (["evaluate", "--config", "{i}/golden.toml", "--model", M, "--experiments", "40",
                  "-j", "2", "--checkpoint-every", "3", "-o", "{d}/ev.h5"], "ev.h5.ckpt/*", 1.0,
                 ["evaluate", "--config", "{i}/golden.toml", "--model", M, "--experiments", "40",
                  "-j", "2", "--checkpoint-every", "3", "--resume", "-o", "{d}/ev.h5"], "ev.h5"),
    "report": (["report", "{i}/evaluation.h5", "-o", "{d}/rep"], ".rep" + TMP, 0.5,
               ["report", "{i}/evaluation.h5", "-o", "{d}/rep"], "rep"),
    "animate": (["animate", "{i}/run.h5", "-o", "{d}/a.gif"], ".a.gif" + TMP, 0.5,
                ["animate", "{i}/run.h5", "--max-frames", "4", "-o", "{d}/a.gif"], "a.gif"),
    "quality": (["quality", "--config", "{i}/golden.toml", "--keyboard", KB, "--experiments",
                 "20", "-j", "2", "-o", "{d}/q.h5"], "q.h5.ckpt/*", 1.0,
                ["quality", "--config", "{i}/golden.toml", "--keyboard", KB, "--experiments",
                 "20", "-j", "2", "--resume", "-o", "{d}/q.h5"], "q.h5"),
}


def _old_report(d: Path) -> None:
    (d / "rep").mkdir()
    (d / "rep" / "README.md").write_text("old report\n")
    (d / "rep" / "mine.txt").write_text("the user's own file\n")


def _old_report_kept(d: Path, r: Result) -> str | None:
    if (d / "rep" / "README.md").read_text() != "old report\n":
        return "the old report changed"
    if sorted(p.name for p in (d / "rep").iterdir()) != ["README.md", "mine.txt"]:
        return "the old report's folder changed"
    return None


def signal_cases() -> list[Case]:
    out = []
    for name, (argv, trigger, delay, rerun, product) in _LONG.items():
        ckpt = name in ("evaluate", "quality")
        keep = (product + ".ckpt",) if ckpt else ()
        words = ("--resume",) if ckpt else ()
        out.append(Case(f"sigint-{name}", "signal", argv, expect=(130,), sig=signal.SIGINT,
                        to_group=True, trigger=trigger, delay=delay, keep=keep,
                        words=("kbcli: interrupted", *words)))
        out.append(Case(f"sigterm-{name}", "signal", argv, expect=(143,), sig=signal.SIGTERM,
                        trigger=trigger, delay=delay, keep=keep,
                        words=("kbcli: terminated", *words),
                        setup=_old_report if name == "report" else None,
                        check=_old_report_kept if name == "report" else None))
        out.append(Case(f"sigkill-{name}-then-rerun", "signal", argv, expect=(-9,), lines=0,
                        sig=signal.SIGKILL, trigger=trigger, delay=delay, rerun=rerun,
                        keep=(product,)))
    out += [
        Case("sigterm-run", "signal", ["run", "--model", M, "--scene", S, "--steps", "90000",
                                       "-o", "{d}/cl.h5"], expect=(143,), sig=signal.SIGTERM,
             delay=2.0, words=("kbcli: terminated",)),
        # (1000 steps: the most the WAV's 1200 s bound lets this melody have; 90000 was refused)
        Case("sigint-play-wav", "signal", ["play", "--model", M, "--steps", "1000", "--wav",
                                           "{d}/h.wav", "-o", "{d}/h.h5"], expect=(130,),
             sig=signal.SIGINT, to_group=True, delay=2.0, words=("kbcli: interrupted",)),
        Case("sigterm-serve-socket", "signal", ["serve", "--model", M, "-o", "{d}/s.h5",
                                                "--socket", "{d}/s.sock", *SMALL],
             expect=(143,), sig=signal.SIGTERM, trigger="s.sock", delay=0.5, lines=None,
             words=("terminated",), keep=("s.h5",)),
        Case("sigint-evaluate-j2-no-checkpoint-yet", "signal",
             ["evaluate", "--config", "{i}/golden.toml", "--model", M, "--experiments", "40",
              "-j", "2", "-o", "{d}/ev.h5"], expect=(130,), sig=signal.SIGINT, to_group=True,
             delay=1.0, lines=1, keep=("ev.h5.ckpt",), check=_resume_or_nothing),
    ]
    return out


# -- two writers, locks, outputs that are inputs -----------------------------------------------------
def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def _stale_lock(content: str):
    def setup(d: Path) -> None:
        lock = d / ".m.h5.kbcli-lock"
        lock.write_text(content.format(pid=_dead_pid()))
        os.utime(lock, (1e9, 1e9))
    return setup


def _copy_evaluation(d: Path) -> None:
    (d / "evaluation.h5").write_bytes((ROOT / "data" / "golden" / "evaluation.h5").read_bytes())


def _evaluation_unchanged(d: Path, r: Result) -> str | None:
    same = (d / "evaluation.h5").read_bytes() == (ROOT / "data" / "golden" /
                                                   "evaluation.h5").read_bytes()
    return None if same else "the report changed its input"


def writer_cases() -> list[Case]:
    learn_long = ["learn", "--keyboard", KB, "--budget", "20000", "-o", "{d}/m.h5"]
    learn = WRITERS["learn"][0]
    rep_long = ["report", "{i}/evaluation.h5", "-o", "{d}/rep"]
    ev_long = _LONG["evaluate"][0]
    anim = ["animate", "{i}/run.h5", "-o", "{d}/a.gif"]
    words = ("another kbcli",)
    return [
        Case("two-writers-learn", "writers", learn, holder=learn_long, words=words, quick=True),
        Case("two-writers-learn-other-folder-spelling", "writers",
             ["learn", "--keyboard", KB, "--budget", "40", "-o", "{d}/./m.h5"],
             holder=learn_long, words=words, quick=True),
        # (the first writer may finish before it is released: its whole report may stay)
        Case("two-writers-report", "writers", rep_long, holder=rep_long, words=words, quick=True,
             keep=("rep",)),
        Case("two-writers-evaluate", "writers", WRITERS["evaluate"][0], holder=ev_long,
             words=words, quick=True, keep=("ev.h5.ckpt",)),
        Case("two-writers-evaluate-resume", "writers", [*WRITERS["evaluate"][0], "--resume"],
             holder=ev_long, words=words, quick=True, keep=("ev.h5.ckpt",)),
        # (the holder animates the closed loop, 150 frames: run.h5's 9 were done before the
        # second kbcli had loaded, which then rightly wrote a.gif)
        Case("two-writers-animate", "writers", anim, words=words, quick=True, keep=("a.gif",),
             holder=["animate", "{i}/closed_loop.h5", "-o", "{d}/a.gif"]),
        Case("stale-lock-dead-pid", "writers", learn, expect=(0,), lines=None,
             setup=_stale_lock("{pid}\n"), keep=("m.h5",)),
        Case("stale-lock-empty-old", "writers", learn, expect=(0,), lines=None,
             setup=_stale_lock(""), keep=("m.h5",)),
        Case("stale-lock-garbage-old", "writers", learn, expect=(0,), lines=None,
             setup=_stale_lock("not a pid\n"), keep=("m.h5",)),
        Case("output-is-input", "writers", ["perturb", "--keyboard", KB, "--dx", "1", "-o", KB],
             quick=True),
        # A report into the folder that holds its input is allowed (kbcli.io.atomic.atomic_folder:
        # the folder may hold the user's files, even the input): the input must stay as it was.
        # (It wrote into {i}, the shared inputs: every file it added read as "an input changed".)
        Case("report-into-input-folder", "writers", ["report", "{d}/evaluation.h5", "-o", "{d}"],
             expect=(0,), lines=None, setup=_copy_evaluation, check=_evaluation_unchanged,
             keep=("*",)),
        Case("wav-is-history", "writers", ["play", "--model", M, "--wav", "{d}/h.h5", "-o",
                                           "{d}/h.h5"], quick=True),
    ]


# -- oversized requests ------------------------------------------------------------------------------
def _toml(name: str, text: str):
    def setup(d: Path) -> None:
        (d / name).write_text(text)
    return setup


_GOLDEN_EVAL = (ROOT / "pipelines" / "golden.toml").read_text()


def _bound(name: str, argv: list[str], *words: str, setup=None, expect=(1,)) -> Case:
    return Case(f"bound-{name}", "bounds", argv, expect=expect, quick=True, words=words,
                setup=setup, timeout=40)


def _polygon(x: float, n: int = 4) -> str:
    pts = ", ".join(f"[{x + i}, {i * i % 7}]" for i in range(n))
    return ('[keyboard]\nlayout = "polygons"\n[[keyboard.keys]]\n'
            f'note = "C4"\nvertices = [{pts}]\n')


def bound_cases() -> list[Case]:
    big = "1000000000"
    ad = ["adapt", "--model", M, "--scene", S, "-o", "{d}/r.h5"]
    ev = ["evaluate", "--config", "{i}/golden.toml", "--model", M, "-o", "{d}/ev.h5"]
    qu = ["quality", "--config", "{i}/golden.toml", "--keyboard", KB, "-o", "{d}/q.h5"]
    le = ["learn", "--keyboard", KB, "-o", "{d}/m.h5"]
    pl = ["play", "--model", M, "-o", "{d}/h.h5"]
    ru = ["run", "--model", M, "--scene", S, "-o", "{d}/cl.h5"]
    se = ["serve", "--model", M, "-o", "{d}/s.h5"]
    kb = ["keyboard", "-o", "{d}/k.h5"]
    return [
        _bound("learn-budget-1e9", [*le, "--budget", big], "20000"),
        _bound("learn-budget-20001", [*le, "--budget", "20001"], "20000"),
        _bound("learn-batch-1e9", [*le, "--batch", big]),
        _bound("learn-curve-every-1e9", [*le, "--curve-every", big]),
        _bound("learn-explore-radius-tiny", [*le, "--explore-radius", "1e-6"]),
        _bound("adapt-T-1e9", [*ad, "-T", big], "10000"),
        _bound("adapt-config-max-steps-1e9", [*ad, "--config", "{d}/a.toml"], "10000",
               setup=_toml("a.toml", f"[adapt]\nmax_steps = {big}\n")),
        _bound("adapt-resolution-tiny", [*ad, "--resolution", "1e-5"]),
        _bound("adapt-prior-halfwidth-1e6", [*ad, "--prior-halfwidth", "1e6"]),
        # A run, not a refusal: two lines (the family adapt follows, the snapshots note).
        Case("bound-adapt-snapshots-20000-entries", "bounds",
             [*ad, "-T", "2", *SMALL, "--snapshots", ",".join(map(str, range(20000)))],
             expect=(0,), lines=2, words=("beyond --max-steps 2",), keep=("r.h5",), timeout=60),
        _bound("play-steps-1e9", [*pl, "--steps", big], "100000"),
        _bound("play-melody-5000-notes", [*pl, "--melody", " ".join(["A:1"] * 5000)], "256"),
        _bound("play-melody-beats-1e9", [*pl, "--melody", f"A:{big}"], "16"),
        _bound("play-perturb-at-1e9", [*pl, "--scene", S, "--perturb-at", big]),
        _bound("play-wav-too-long", [*pl, "--steps", "100000", "--wav", "{d}/h.wav"], "1200 s"),
        _bound("run-steps-1e9", [*ru, "--steps", big], "100000"),
        _bound("run-max-adapt-steps-1e9", [*ru, "--max-adapt-steps", big], "10000"),
        _bound("run-perturb-at-1e9", [*ru, "--perturb-at", big]),
        _bound("run-n-lt-1e9", [*ru, "--n-lt", big], "10000"),
        _bound("detect-n-lt-1e9", ["detect", "{i}/history.h5", "-o", "{d}/d.h5", "--n-lt", big],
               "10000"),
        _bound("detect-n-st-1e9", ["detect", "{i}/history.h5", "-o", "{d}/d.h5", "--n-st", big]),
        _bound("evaluate-experiments-1e9", [*ev, "--experiments", big], "10000"),
        _bound("evaluate-config-max-steps-1e9", ["evaluate", "--config", "{d}/e.toml", "--model",
                                                M, "-o", "{d}/ev.h5"], "10000",
               setup=_toml("e.toml", _GOLDEN_EVAL.replace("max_steps = 6", f"max_steps = {big}"))),
        _bound("evaluate-jobs-0", [*ev, "--jobs", "0"]),
        _bound("evaluate-checkpoint-every-0", [*ev, "--checkpoint-every", "0"]),
        _bound("evaluate-paper-total-1e4-experiments", [
            "evaluate", "--model", M, "--experiments", "10000", "-o", "{d}/ev.h5"]),
        _bound("quality-experiments-1e9", [*qu, "--experiments", big], "10000"),
        _bound("quality-budgets-1e9", [*qu, "--budgets", big], "20000"),
        # (5000 distinct budgets: 5000 copies of one budget are one model, a real sweep)
        _bound("quality-budgets-5000-models", [*qu, "--budgets",
                                               ",".join(map(str, range(10, 5010)))], "100"),
        _bound("keyboard-rows-cols-1e6", [*kb, "--rows", "1000000", "--cols", "1000000"], "256"),
        _bound("keyboard-key-size-1e7", [*kb, "--key-size", "1e7"]),
        _bound("keyboard-origin-1e7", [*kb, "--origin-x", "1e7"]),
        _bound("keyboard-margin-1e7", [*kb, "--margin", "1e7"]),
        _bound("keyboard-polygon-x-1e7", [*kb, "--config", "{d}/p.toml"], "10000",
               setup=_toml("p.toml", _polygon(1e7))),
        _bound("keyboard-polygon-100k-vertices", [*kb, "--config", "{d}/p.toml"],
               setup=_toml("p.toml", _polygon(200, 100_000))),
        _bound("keyboard-pads-radius-tiny", [*kb, "--layout", "pads", "--pad-radius", "1e-9"]),
        _bound("serve-T-1e9", [*se, "-T", big], "10000"),
        _bound("serve-resolution-tiny", [*se, "--resolution", "1e-5"]),
        _bound("bench-arm-reaches-1e9", ["bench", "arm", "--reaches", big]),
        _bound("bench-detect-streams-1e9", ["bench", "detect", "--streams", big]),
        _bound("bench-detect-tune-actions-1e12", ["bench", "detect", "--tune-actions", "1" + "0" * 12]),
        _bound("bench-adapt-experiments-1e9", ["bench", "adapt", "--experiments", big]),
        _bound("bench-adapt-T-1e9", ["bench", "adapt", "-T", big]),
        _bound("bench-learn-seeds-1e9", ["bench", "learn", "--seeds", big]),
        _bound("bench-learn-budgets-1e9", ["bench", "learn", "--budgets", big]),
        _bound("bench-robust-experiments-1e9", ["bench", "robust", "--experiments", big]),
        _bound("bench-reliability-seeds-1e9", ["bench", "reliability", "--seeds", big]),
        _bound("bench-animate-repeats-1e9", ["bench", "animate", "--repeats", big]),
        _bound("bench-animate-touches-1e9", ["bench", "animate", "--touches", big]),
        _bound("bench-evaluate-experiments-1e9", ["bench", "evaluate", "--experiments", big]),
        Case("bound-bench-evaluate-workers-1e4-capped", "bounds",
             ["bench", "evaluate", "--config", "{i}/golden.toml", "--experiments", "1",
              "--workers", "10000"], expect=(0,), lines=None, timeout=300,
             words=("--workers 10000 is more than",)),
        _bound("bench-layouts-seeds-1e9", ["bench", "layouts", "--seeds", big, "-o", "{d}/l"]),
        Case("bound-animate-max-frames-1e9", "bounds", ["animate", "{i}/run.h5", "--max-frames",
                                                        big, "-o", "{d}/a.gif"], expect=(0,),
             lines=0, keep=("a.gif",)),
    ]


# -- hostile serve clients ---------------------------------------------------------------------------
def _replies(stdout: str) -> list[dict]:
    return [json.loads(ln) for ln in stdout.splitlines() if ln.strip()]


def _serve_check(errors: int, steps: int):
    def check(stdout: str) -> str | None:
        try:
            rep = _replies(stdout)
        except ValueError:
            return "a reply is not JSON"
        got = sum(r.get("type") == "error" for r in rep)
        bye = [r for r in rep if r.get("type") == "bye"]
        if got != errors:
            return f"{got} error replies, expected {errors}"
        if not bye or bye[0].get("steps") != steps:
            return f"bye {bye[:1]}, expected {steps} touches"
        return None
    return check


def _serve(name: str, lines: list[str], errors: int = 1, steps: int = 0, extra=()) -> Case:
    return Case(f"serve-{name}", "serve", ["serve", "--model", M, "-o", "{d}/s.h5", *SMALL,
                                           *extra],
                expect=(0,), lines=1, stdin="\n".join([*lines, END]) + "\n", keep=("s.h5",),
                stdout_check=_serve_check(errors, steps), timeout=60)


def serve_cases() -> list[Case]:
    obs = lambda **k: json.dumps({"op": "observe", **k})  # noqa: E731
    return [
        _serve("felt-1e6-off-the-pad", [obs(heard=None, felt=[1e6, 350])]),
        _serve("felt-nan", ['{"op": "observe", "heard": null, "felt": [NaN, 350]}']),
        _serve("felt-infinity", ['{"op": "observe", "heard": null, "felt": [Infinity, 0]}']),
        _serve("felt-1e400", ['{"op": "observe", "heard": null, "felt": [1e400, 0]}']),
        _serve("felt-strings", [obs(heard=None, felt=["a", "b"])]),
        _serve("felt-three-numbers", [obs(heard=None, felt=[1, 2, 3])]),
        _serve("heard-no-such-sound", [obs(heard=[1e9, 1e9], felt=[400, 350])]),
        _serve("heard-nan", ['{"op": "observe", "heard": [NaN, NaN]}']),
        _serve("heard-wrong-length", [obs(heard=[1, 2, 3, 4])]),
        _serve("heard-unknown-insisted", [obs(heard=[1e9, 1e9], felt=[400, 350], insist=True)],
               errors=0, steps=1),
        _serve("action-outside", [obs(heard=None, action=[1e6, 0])]),
        _serve("garbage", ["this is not json"]),
        _serve("invalid-utf8", ["{\"op\": \"\udcff\udcfe\"}"]),
        _serve("huge-line-1mb", ["x" * 1_000_000]),
        _serve("huge-json-8mb", [json.dumps({"op": "observe", "heard": [0.5] * 1_000_000})]),
        _serve("deep-nesting", ["[" * 60_000 + "]" * 60_000]),
        _serve("deep-nesting-object", ['{"op": ' + "[" * 30_000 + "]" * 30_000 + "}"]),
        _serve("top-level-array", ["[1, 2]"]),
        _serve("unknown-op", [json.dumps({"op": "dance"})]),
        _serve("unknown-field", [obs(heard=None, colour="red")]),
        _serve("beyond-max-steps", [TOUCH, TOUCH], errors=1, steps=1, extra=("-T", "1")),
        _serve("thousand-garbage-lines", ["{"] * 1000, errors=1000),
        _serve("empty-lines", ["", "   ", ""], errors=0),
    ]


# -- config files and input paths that are not files -------------------------------------------------
def _fifo(name: str):
    def setup(d: Path) -> None:
        os.mkfifo(d / name)
    return setup


def _folder(name: str):
    def setup(d: Path) -> None:
        (d / name).mkdir()
    return setup


def _bytes(name: str, data: bytes):
    def setup(d: Path) -> None:
        (d / name).write_bytes(data)
    return setup


def config_cases() -> list[Case]:
    kb = ["keyboard", "-o", "{d}/k.h5", "--config"]
    ev = ["evaluate", "--model", M, "-o", "{d}/ev.h5", "--config"]
    ad = ["adapt", "--model", M, "--scene", S, "-o", "{d}/r.h5"]

    def c(name, argv, *words, setup=None):
        return Case(f"config-{name}", "config", argv, words=words, setup=setup, quick=True,
                    timeout=40, keep=("c", "c.toml", "f", "x.h5"))

    return [
        c("folder", [*kb, "{d}/c"], "is a folder", setup=_folder("c")),
        c("fifo", [*kb, "{d}/f"], "FIFO", setup=_fifo("f")),
        c("dev-null", [*kb, "/dev/null"], "device"),
        c("dev-zero-evaluate", [*ev, "/dev/zero"], "device"),
        c("missing", [*kb, "{d}/nope.toml"], "no such config file"),
        c("binary", [*kb, "{d}/c.toml"], "invalid TOML",
          setup=_bytes("c.toml", bytes(range(256)) * 4)),
        c("2mb", [*kb, "{d}/c.toml"], "bytes", setup=_bytes("c.toml", b"# x\n" * 600_000)),
        c("no-table", [*kb, "{d}/c.toml"], "[keyboard]", setup=_bytes("c.toml", b"a = 1\n")),
        c("arm-fifo", [*ad, "--arm", "{d}/f.toml"], "FIFO", setup=_fifo("f.toml")),
        c("model-fifo", ["adapt", "--model", "{d}/f", "--scene", S, "-o", "{d}/r.h5"],
          setup=_fifo("f")),
        c("model-dev-zero", ["adapt", "--model", "/dev/zero", "--scene", S, "-o", "{d}/r.h5"]),
        c("model-folder", ["adapt", "--model", "{d}/c", "--scene", S, "-o", "{d}/r.h5"],
          setup=_folder("c")),
        c("model-garbage", ["adapt", "--model", "{d}/x.h5", "--scene", S, "-o", "{d}/r.h5"],
          setup=_bytes("x.h5", b"\x89HDF\r\n\x1a\n" + b"\0" * 5000)),
        c("inspect-fifo", ["inspect", "{d}/f"], setup=_fifo("f")),
        c("report-of-fifo", ["report", "{d}/f", "-o", "{d}/rep"], setup=_fifo("f")),
        Case("config-output-is-a-fifo-replaced", "config", ["keyboard", "-o", "{d}/f"],
             setup=_fifo("f"), expect=(0,), lines=0, keep=("f",)),
    ]


# -- no silent guesses -------------------------------------------------------------------------------
def _rigid_scene(d: Path) -> None:
    subprocess.run([sys.executable, "-m", "kbcli", "perturb", "--keyboard",
                    str(ROOT / "data" / "golden" / "keyboard.h5"), "--dx", "6", "--dy", "-4",
                    "--angle", "3", "-o", str(d / "rigid.h5")], env=_env("setup"), check=True,
                   capture_output=True)


def _follows_rigid(d: Path, r: Result) -> str | None:
    sys.path.insert(0, str(ROOT))
    from kbcli.io.artifact import read_artifact

    cfg = read_artifact(d / "cl.h5").config
    fam = json.dumps(cfg)
    return None if '"family": "rigid"' in fam else "run did not estimate a rigid move"


def note_cases() -> list[Case]:
    return [
        Case("note-snapshots-beyond-T", "notes",
             ["adapt", "--model", M, "--scene", S, "-T", "2", *SMALL, "--snapshots", "0,1,50",
              "-o", "{d}/r.h5"], expect=(0,), lines=2, words=("--snapshots 50 beyond",),
             keep=("r.h5",)),
        Case("note-jobs-capped", "notes",
             ["evaluate", "--config", "{i}/golden.toml", "--model", M, "-j", "10000", "-o",
              "{d}/ev.h5"], expect=(0,), words=("--jobs 10000 is more than",), keep=("ev.h5",)),
        Case("note-run-follows-rigid-scene", "notes",
             ["run", "--model", M, "--scene", "{d}/rigid.h5", "--steps", "150", "--perturb-at",
              "110", "--max-adapt-steps", "5", "-o", "{d}/cl.h5"], expect=(0,), lines=None,
             setup=_rigid_scene, check=_follows_rigid, keep=("cl.h5", "rigid.h5")),
    ]


def all_cases() -> list[Case]:
    return [*disk_cases(), *ro_cases(), *signal_cases(), *writer_cases(), *bound_cases(),
            *serve_cases(), *config_cases(), *note_cases()]


__all__ = ["LOCK", "all_cases"]
