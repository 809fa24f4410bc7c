"""Where a result came from: the code's git commit and whether its tree was clean, and the
sha256 of every input artifact a command read.

:func:`git_state` reads the checkout kbcli runs from (None outside one, or without git);
:func:`inputs` hashes the files a command line names and, for an artifact, lists the inputs it
records, so the model a result file's verdict rests on is named by its sha256.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import kbcli

#: The checkout kbcli is imported from (its ``.git`` beside the package, when there is one).
ROOT = Path(kbcli.__file__).resolve().parents[1]


def _git(*args: str, cwd: Path) -> str | None:
    try:
        res = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True,
                             timeout=20, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout if res.returncode == 0 else None


#: The result files themselves (``make results`` writes them one after another: one made before
#: another is not a change to the code that makes the next).
RESULT_FILES = "benchmarks/results/"


def git_state(root: Path = ROOT) -> dict | None:
    """``{"commit": sha, "clean": bool, "changed": [paths]}`` of the checkout at ``root``: the
    files that differ from the commit (untracked ones included, git-ignored ones not), and
    whether the code is the commit's (clean: no change outside :data:`RESULT_FILES`); None when
    ``root`` is not a git checkout."""
    if not (root / ".git").exists():
        return None
    commit = _git("rev-parse", "HEAD", cwd=root)
    status = _git("status", "--porcelain", "--untracked-files=all", cwd=root)
    if commit is None or status is None:
        return None
    changed = sorted(line[3:] for line in status.splitlines() if line.strip())
    code = [p for p in changed if not p.startswith(RESULT_FILES)]
    return {"commit": commit.strip(), "clean": not code, "changed": changed[:50]}


#: Options whose value is a file the command writes, not one it reads.
OUTPUT_FLAGS = ("--json", "-o", "--output", "--plot", "--model-out")


def inputs(argv: list[str]) -> dict[str, dict]:
    """The files named on a command line (its arguments that are existing files, but the values
    of :data:`OUTPUT_FLAGS`), each with its
    sha256 and, for an HDF5 artifact, the kind and the inputs it records (role -> file and
    sha256)."""
    from kbcli.io.artifact import read_artifact, sha256_file

    out: dict[str, dict] = {}
    outputs = {b for a, b in zip(argv, argv[1:], strict=False) if a in OUTPUT_FLAGS}
    for a in argv:
        p = Path(a)
        if a.startswith("-") or a in outputs or not p.is_file():
            continue
        entry: dict = {"sha256": sha256_file(p)}
        if p.suffix in (".h5", ".hdf5"):
            try:
                art = read_artifact(p, validate=False)
            except Exception:  # a file kbcli cannot read: its hash alone
                art = None
            if art is not None:
                entry["kind"] = art.kind
                entry["inputs"] = {role: {k: ref.get(k) for k in ("file", "sha256")}
                                   for role, ref in art.inputs.items()}
        out[a] = entry
    return out
