"""A run's checkpoint: finished experiments kept beside the output, so a killed run resumes.

:class:`Checkpoint` keeps them in ``OUTPUT.ckpt/``: a ``meta.json`` with the fingerprint of what is
being run, and ``part-NNNNNN.h5`` files written atomically every few experiments. ``resume=True``
loads them and refuses a checkpoint whose fingerprint differs, naming the fields that differ; the
fingerprint holds :func:`source_digest`, so results of two code versions are never mixed.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import shutil
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from kbcli.errors import KbcliError
from kbcli.io.artifact import hdf5_image, read_group
from kbcli.io.atomic import describe_os_error, write_bytes

CHECKPOINT_FORMAT = 1

#: Sources that only present, judge or record numbers, never make them: a change to these
#: does not refuse a checkpoint (the benchmarks' tables, the report, provenance, the schema's
#: read checks). Paths relative to the package, a trailing ``/`` for a folder.
PRESENTATION_ONLY = ("bench/", "stages/report/", "cli/report.py", "io/provenance.py",
                     "io/schema/rules.py")


def source_digest(package: str = "kbcli", skip: tuple[str, ...] = PRESENTATION_ONLY) -> str:
    """sha256 of the package's Python sources that make numbers (every module but ``skip``), so
    a checkpoint is never resumed by other code (results made by two versions would otherwise
    be mixed in one artifact), while a change to a table's wording does not stale a sweep."""
    import hashlib

    root = Path(importlib.import_module(package).__file__).parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if any(rel == s or (s.endswith("/") and rel.startswith(s)) for s in skip):
            continue
        h.update(rel.encode())
        h.update(b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def _write_tree(group: h5py.Group, data: dict[str, Any]) -> None:
    for name, value in data.items():
        if isinstance(value, dict):
            _write_tree(group.create_group(name), value)
            continue
        arr = np.asarray(value)
        if arr.dtype.kind == "U":
            group.create_dataset(name, data=arr.astype(object), dtype=h5py.string_dtype("utf-8"))
        else:
            group.create_dataset(name, data=arr)


def _diff(old: dict, new: dict, prefix: str = "") -> list[str]:
    keys = sorted(set(old) | set(new))
    out: list[str] = []
    for k in keys:
        a, b = old.get(k), new.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _diff(a, b, f"{prefix}{k}.")
        elif a != b:
            out.append(f"{prefix}{k}")
    return out


def _canonical(obj: Any) -> Any:
    """JSON round trip, so tuples and lists compare equal."""
    return json.loads(json.dumps(obj, sort_keys=True))


class Checkpoint:
    """Finished experiments of a run, kept in ``folder`` (conventionally ``OUTPUT.ckpt``).

    Parameters
    ----------
    folder : Path
    fingerprint : dict
        JSON-able description of what is being run (config, inputs, experiment count); a checkpoint
        is only resumed by a run with the same fingerprint.
    every : int
        Write a part after this many new experiments ...
    seconds : float
        ... or when the oldest unwritten one is this old, whichever comes first.
    """

    def __init__(self, folder: str | os.PathLike, fingerprint: dict, *, every: int = 10,
                 seconds: float = 30.0) -> None:
        self.folder = Path(folder)
        self.fingerprint = _canonical(fingerprint)
        self.every = max(1, int(every))
        self.seconds = float(seconds)
        self._pending: dict[int, dict] = {}
        self._since = time.monotonic()
        self._parts = 0
        #: results written to parts by this object (what a resumed run gets back, beside the
        #: results it loaded)
        self.written = 0

    @staticmethod
    def beside(output: str | os.PathLike) -> Path:
        """The checkpoint folder of an output file: ``OUTPUT.ckpt``."""
        output = Path(output)
        return output.with_name(output.name + ".ckpt")

    def exists(self) -> bool:
        return (self.folder / "meta.json").is_file()

    @property
    def pending(self) -> int:
        """Results added but not written yet."""
        return len(self._pending)

    def load(self, resume: bool) -> dict[int, dict]:
        """Finished experiments to keep (empty when starting afresh).

        Raises
        ------
        KbcliError
            A checkpoint exists but ``resume`` is False; or it was made by a different config
            (the message names the differing fields); or it is unreadable.
        """
        if not self.exists():
            if self.folder.exists() and not self.folder.is_dir():
                raise KbcliError(f"{self.folder}: exists and is not a checkpoint folder")
            return {}
        self._check_meta(resume)
        done: dict[int, dict] = {}
        for part in sorted(self.folder.glob("part-*.h5")):
            try:
                with h5py.File(part, "r") as f:
                    done.update((int(name), read_group(node)) for name, node in f.items())
            except (OSError, ValueError, KeyError) as exc:
                raise KbcliError(f"{part}: unreadable checkpoint part ({exc}); delete it") from None
            self._parts = max(self._parts, int(part.stem.split("-")[1]))
        for stale in self.folder.glob(".*.tmp"):
            with contextlib.suppress(OSError):
                stale.unlink()
        return done

    def _check_meta(self, resume: bool) -> None:
        """KbcliError unless ``meta.json`` is readable, ``resume`` is asked and the checkpoint was
        made with this fingerprint (see :meth:`load`)."""
        try:
            meta = json.loads((self.folder / "meta.json").read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise KbcliError(f"{self.folder}: unreadable checkpoint ({exc}); delete it") from None
        if not resume:
            raise KbcliError(
                f"{self.folder} holds an interrupted run: pass --resume to continue it, or delete it"
            )
        if meta.get("format") != CHECKPOINT_FORMAT or "fingerprint" not in meta:
            raise KbcliError(f"{self.folder}: not a kbcli checkpoint of format {CHECKPOINT_FORMAT}")
        if meta["fingerprint"] != self.fingerprint:
            fields = _diff(meta["fingerprint"], self.fingerprint)
            raise KbcliError(
                f"{self.folder} was made with a different config ({', '.join(fields)} differ): "
                "refusing to resume; rerun with the same config or delete the checkpoint"
            )

    def start(self) -> None:
        """Create the folder and its ``meta.json`` (atomically) if they do not exist yet."""
        made = not self.folder.exists()
        try:
            self.folder.mkdir(exist_ok=True)
        except OSError as exc:
            raise KbcliError(f"{self.folder}: cannot create the checkpoint folder "
                             f"({describe_os_error(exc)})") from None
        if not self.exists():
            meta = json.dumps({"format": CHECKPOINT_FORMAT, "fingerprint": self.fingerprint},
                              sort_keys=True, indent=1)
            try:
                write_bytes(self.folder / "meta.json", meta.encode())
            except BaseException:  # (a full disk): no folder left that nothing could resume
                with contextlib.suppress(OSError):
                    _ = made and self.folder.rmdir()
                raise

    def add(self, index: int, result: dict) -> None:
        """Record one finished experiment; writes a part when enough are pending."""
        if not self._pending:
            self._since = time.monotonic()
        self._pending[int(index)] = result
        if len(self._pending) >= self.every or time.monotonic() - self._since >= self.seconds:
            self.flush()

    def flush(self) -> None:
        """Write pending experiments as a new part (atomically)."""
        if not self._pending:
            return
        self.start()
        self._parts += 1

        def fill(f: h5py.File) -> None:
            for i in sorted(self._pending):
                _write_tree(f.create_group(str(i)), self._pending[i])

        image = hdf5_image(fill, reproducible=False)  # in memory: a full disk fails cleanly
        write_bytes(self.folder / f"part-{self._parts:06d}.h5", image)
        self.written += len(self._pending)
        self._pending = {}

    def remove(self) -> None:
        """Delete the checkpoint (after the final output is safely written)."""
        self._pending = {}
        if self.folder.is_dir():
            shutil.rmtree(self.folder)
