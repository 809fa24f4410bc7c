"""Read and write artifacts as self-describing HDF5 files.

Root attributes: ``kind``, ``schema_version``, ``kbcli_version``, ``config`` (JSON), ``seed``
(-1 when none), ``inputs`` (JSON: the provenance chain), ``input_sha256.<role>`` for each direct
input, and ``attrs`` (JSON metadata). Arrays are datasets (nested dicts are groups), written with
``track_times=False`` and only the standard gzip + shuffle filters, so identical inputs give
identical bytes and ``h5dump`` reads every file. Writes are atomic (:mod:`kbcli.io.atomic`).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from kbcli.errors import ArtifactError, ConfigError
from kbcli.io.atomic import atomic_paths
from kbcli.io.schema import validate as check_schema
from kbcli.io.schema.migrate import upgrade
from kbcli.stages.artifact import SCHEMA_VERSIONS, Artifact

_COMPRESS_ABOVE = 4096  # elements; small datasets stay contiguous
_IMAGES = itertools.count()


def sha256_file(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _json(obj: Any) -> str:
    def default(o: Any) -> Any:
        if isinstance(o, np.integer):
            return int(o)
        if isinstance(o, np.floating):
            return float(o)
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, tuple):
            return list(o)
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")

    return json.dumps(obj, sort_keys=True, default=default)


def _group_plist() -> h5py.h5p.PropGCID:
    gcpl = h5py.h5p.create(h5py.h5p.GROUP_CREATE)
    gcpl.set_obj_track_times(False)
    return gcpl


def _write_group(group: h5py.Group, data: dict[str, Any]) -> None:
    for name in sorted(data):
        value = data[name]
        if isinstance(value, dict):
            gid = h5py.h5g.create(group.id, name.encode(), gcpl=_group_plist())
            _write_group(h5py.Group(gid), value)
            continue
        arr = np.asarray(value)
        if arr.dtype.kind == "U":
            arr = arr.astype(h5py.string_dtype("utf-8"), copy=False).astype(object)
            group.create_dataset(name, data=arr, dtype=h5py.string_dtype("utf-8"), track_times=False)
            continue
        if arr.dtype == np.float64 and arr.dtype.byteorder == ">":
            arr = arr.astype("<f8")
        kwargs: dict[str, Any] = {"track_times": False}
        if arr.size > _COMPRESS_ABOVE and arr.ndim > 0:
            kwargs.update(compression="gzip", compression_opts=4, shuffle=True)
        group.create_dataset(name, data=arr, **kwargs)


def hdf5_image(fill: Callable[[h5py.File], None], *, reproducible: bool = True) -> bytes:
    """An HDF5 file built in memory by ``fill(file)`` (HDF5's core driver, no backing store):
    the bytes HDF5 would write to disk, so a full disk or an I/O error fails in a plain Python
    write (HDF5 failing its own write corrupts its cache and crashes later). ``reproducible``: no
    object times, the earliest file format that holds the data."""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    if reproducible:
        fapl.set_libver_bounds(h5py.h5f.LIBVER_EARLIEST, h5py.h5f.LIBVER_LATEST)
    fapl.set_fapl_core(block_size=1 << 16, backing_store=False)
    fcpl = h5py.h5p.create(h5py.h5p.FILE_CREATE)
    if reproducible:
        fcpl.set_obj_track_times(False)
    name = f"kbcli-image-{os.getpid()}-{next(_IMAGES)}".encode()
    fid = h5py.h5f.create(name, h5py.h5f.ACC_TRUNC, fcpl=fcpl, fapl=fapl)
    f = h5py.File(fid)
    try:
        fill(f)
        f.flush()
        return fid.get_file_image()
    finally:
        f.close()
        del f, fid


def _fill(art: Artifact) -> Callable[[h5py.File], None]:
    def fill(f: h5py.File) -> None:
        f.attrs["kind"] = art.kind
        f.attrs["schema_version"] = int(art.schema_version or SCHEMA_VERSIONS[art.kind])
        f.attrs["kbcli_version"] = art.kbcli_version
        f.attrs["config"] = _json(art.config)
        f.attrs["seed"] = -1 if art.seed is None else int(art.seed)
        f.attrs["inputs"] = _json(art.inputs)
        for role in sorted(art.inputs):
            f.attrs[f"input_sha256.{role}"] = str(art.inputs[role].get("sha256"))
        f.attrs["attrs"] = _json(art.attrs)
        _write_group(f, art.data)

    return fill


def write_artifact(art: Artifact, path: str | os.PathLike,
                   also: Sequence[tuple[str | os.PathLike, bytes]] = ()) -> str:
    """Write ``art`` atomically to ``path`` (mode 0644) and return the file's sha256; ``also``:
    other files (path, bytes) written with it, all or none.

    Raises
    ------
    ArtifactError
        If the destination folder does not exist or is not writable, or the write fails: one line
        naming ``path`` and the cause, and no temporary file is left.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ArtifactError(f"{path}: folder {folder} does not exist")
    data = hdf5_image(_fill(art))
    files = [(path, data), *((Path(p), b) for p, b in also)]
    with atomic_paths([p for p, _ in files]) as tmps:
        for tmp, (_, content) in zip(tmps, files, strict=True):
            try:
                with open(tmp, "wb") as fh:
                    fh.write(content)
            except OSError as exc:  # name the file that failed
                raise OSError(exc.errno, exc.strerror, tmp) from None
    digest = hashlib.sha256(data).hexdigest()
    art.sha256 = digest
    art.path = str(path)
    return digest


def read_group(group: h5py.Group) -> dict[str, Any]:
    """A group's datasets (text as str arrays) and sub-groups, as nested dicts."""
    out: dict[str, Any] = {}
    for name, node in group.items():
        if isinstance(node, h5py.Group):
            out[name] = read_group(node)
        elif node.dtype.kind == "O" or h5py.check_string_dtype(node.dtype) is not None:
            out[name] = np.asarray(node.asstr()[()], dtype=str)
        else:
            out[name] = node[()]
    return out


def _text_attr(f: h5py.File, name: str, path: Path) -> str:
    value = f.attrs[name]
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if not isinstance(value, str):
        raise ArtifactError(f"{path}: attribute {name!r} must be text, got {type(value).__name__}")
    return value


def _int_attr(f: h5py.File, name: str, path: Path) -> int:
    value = f.attrs[name]
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)):
        raise ArtifactError(f"{path}: attribute {name!r} must be a whole number, got {value!r:.40}")
    return int(value)


def _json_attr(f: h5py.File, name: str, path: Path, required: bool = False) -> dict:
    """A JSON-object attribute (config, attrs, inputs); {} when absent and not required."""
    if name not in f.attrs:
        if required:
            raise ArtifactError(f"{path}: attribute {name!r} is missing")
        return {}
    text = _text_attr(f, name, path)
    try:
        value = json.loads(text)
    except ValueError:
        raise ArtifactError(f"{path}: attribute {name!r} is not valid JSON (truncated?)") from None
    if not isinstance(value, dict):
        raise ArtifactError(f"{path}: attribute {name!r} must hold a JSON object, got "
                            f"{type(value).__name__}")
    return value


def _kinds(kind: str | tuple[str, ...] | None) -> tuple[str, ...] | None:
    return (kind,) if isinstance(kind, str) else kind


def _check_file(path: Path) -> None:
    """An existing file that starts with the HDF5 signature."""
    if not path.exists():
        raise ArtifactError(f"{path}: no such file")
    if path.is_dir():
        raise ArtifactError(f"{path}: is a folder, expected a kbcli artifact (.h5 file)")
    if not path.is_file():  # a FIFO would block the read forever, a device never end
        kind = "a FIFO" if path.is_fifo() else "a device" if path.is_char_device() or \
            path.is_block_device() else "not a regular file"
        raise ArtifactError(f"{path}: is {kind}, expected a kbcli artifact (.h5 file)")
    with open(path, "rb") as fh:
        head = fh.read(8)
    if head != b"\x89HDF\r\n\x1a\n":
        raise ArtifactError(f"{path}: not an HDF5 file (expected a kbcli artifact)")


def _kind_and_version(f: h5py.File, path: Path, wanted: tuple[str, ...] | None) -> tuple[str, int]:
    """The artifact's kind (one of ``wanted``) and schema version (one this kbcli reads)."""
    if "kind" not in f.attrs or "schema_version" not in f.attrs:
        raise ArtifactError(f"{path}: an HDF5 file but not a kbcli artifact (no kind attribute)")
    got = _text_attr(f, "kind", path)
    version = _int_attr(f, "schema_version", path)
    if wanted is not None and got not in wanted:
        raise ArtifactError(f"{path}: is a {got} artifact, expected {' or '.join(wanted)}")
    known = SCHEMA_VERSIONS.get(got)
    if known is None:
        raise ArtifactError(f"{path}: unknown artifact kind {got!r}; you may need to update kbcli")
    if version > known:
        raise ArtifactError(
            f"{path}: {got} artifact of schema {version}, newer than this kbcli reads "
            f"({known}); you may need to update kbcli"
        )
    if version < 1:
        raise ArtifactError(f"{path}: attribute 'schema_version' must be >= 1, got {version}")
    return got, version


def read_artifact(path: str | os.PathLike, kind: str | tuple[str, ...] | None = None, *,
                  validate: bool = True) -> Artifact:
    """Read an artifact, checking that it is one, of the expected kind and of a known schema, and
    (``validate``) that it holds what its kind's schema requires (:mod:`kbcli.io.schema`).

    Parameters
    ----------
    kind : str or tuple of str, optional
        The kind(s) accepted.
    validate : bool
        Check the datasets, summary attributes and config entries against the schema (False:
        only the root attributes, e.g. to show a damaged file with ``kbcli inspect``).

    Raises
    ------
    ArtifactError
        Missing file, not HDF5, truncated or corrupt, not a kbcli artifact, wrong kind, newer
        schema, or (``validate``) a missing or malformed dataset, attribute or config entry.
    """
    path = Path(path)
    _check_file(path)
    try:
        with h5py.File(path, "r") as f:
            got, version = _kind_and_version(f, path, _kinds(kind))
            seed = _int_attr(f, "seed", path) if "seed" in f.attrs else -1
            art = Artifact(
                kind=got,
                config=_json_attr(f, "config", path, required=True),
                seed=None if seed < 0 else seed,
                data=read_group(f),
                attrs=_json_attr(f, "attrs", path),
                inputs=_json_attr(f, "inputs", path),
                schema_version=version,
                kbcli_version=str(f.attrs.get("kbcli_version", "?")),
            )
    except ArtifactError:
        raise
    except (OSError, KeyError, ValueError, RuntimeError, TypeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ArtifactError(f"{path}: truncated or corrupt HDF5 file ({first})") from None
    if not all(isinstance(v, dict) for v in art.inputs.values()):
        raise ArtifactError(f"{path}: attribute 'inputs' must map each input to a table")
    if validate:
        check_schema(art, str(path))
    try:
        art = upgrade(art)
    except ConfigError as exc:
        if validate:
            raise ArtifactError(f"{path}: its robot options cannot be read: {exc}") from None

    art.sha256 = sha256_file(path)
    art.path = str(path)
    return art


def describe(path: str | os.PathLike) -> dict[str, Any]:
    """What ``kbcli inspect`` shows: kind, schema, versions, config, provenance and dataset shapes,
    and ``problem``: what does not match the kind's schema (None when all is well)."""
    art = read_artifact(path, validate=False)
    try:
        check_schema(art, "")
        problem = None
    except ArtifactError as exc:
        problem = str(exc)
    shapes: dict[str, dict[str, Any]] = {}
    with h5py.File(path, "r") as f:

        def visit(name: str, node: Any) -> None:
            if isinstance(node, h5py.Dataset):
                shapes[name] = {"shape": list(node.shape), "dtype": str(node.dtype)}

        f.visititems(visit)
    return {
        "file": str(path),
        "kind": art.kind,
        "schema_version": art.schema_version,
        "kbcli_version": art.kbcli_version,
        "sha256": art.sha256,
        "seed": art.seed,
        "config": art.config,
        "attrs": art.attrs,
        "inputs": art.inputs,
        "datasets": shapes,
        "problem": problem,
    }


def provenance_chain(inputs: dict[str, dict], depth: int = 0) -> Iterator[tuple[int, str, dict]]:
    """Walk the provenance chain depth first: (depth, role, reference)."""
    for role in sorted(inputs):
        r = inputs[role]
        yield depth, role, r
        yield from provenance_chain(r.get("inputs") or {}, depth + 1)
