"""Check an artifact against its kind's schema: config entries and summary attributes by type,
datasets by presence, dtype and shape, then their values (finite, index bounds), then the rules
across entries. Each check is a small function in a table; the first message found is raised."""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

import kbcli.io.schema.rules as rules
from kbcli.errors import ArtifactError
from kbcli.io.schema.kinds import schema_for
from kbcli.io.schema.spec import KIND_WORDS, WORDS, Dataset, Schema, typed

_PLACEHOLDER = re.compile(r"\{(\w+)\}")


@dataclass
class _Found:
    """A dataset of the artifact found at ``path`` for the schema entry ``ds``."""

    ds: Dataset
    path: str
    arr: np.ndarray


# -- paths -----------------------------------------------------------------------------------------

def lookup(tree: dict, dotted: str, sep: str = ".") -> tuple[bool, Any]:
    """(found, value) of a ``sep``-separated path in nested dicts."""
    node: Any = tree
    for part in dotted.split(sep):
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _placeholder_values(name: str, attrs: dict) -> list[str]:
    if name == "others":
        vals = [s for s in attrs.get("strategies", []) if s != attrs.get("baseline")]
    else:
        vals = attrs.get(name, [])
    return [str(v) for v in vals] if isinstance(vals, list) else []


def _expand_method(path: str, art) -> list[str]:
    out = []
    for m in rules.methods(art):
        own = (art.attrs.get("methods") or {}).get(m)
        sub = dict(art.attrs, **(own if isinstance(own, dict) else {}))
        view = type("View", (), {"attrs": sub})()
        out += expand(path.replace("{method}", m), view)
    return out


def expand(path: str, art) -> list[str]:
    """Every path a ``{placeholder}`` path stands for. ``{method}`` runs over the evaluation's
    methods, and the lists after it (modes, categories, strategies) are that method's own."""
    if "{method}" in path:
        return _expand_method(path, art)
    names = _PLACEHOLDER.findall(path)
    if not names:
        return [path]
    out = []
    for combo in itertools.product(*(_placeholder_values(n, art.attrs) for n in names)):
        p = path
        for n, v in zip(names, combo, strict=True):
            p = p.replace("{" + n + "}", v, 1)
        out.append(p)
    return out


# -- config entries and summary attributes ---------------------------------------------------------

def _entries(table: dict, specs: dict[str, str], what: str, get, say_null: bool) -> str | None:
    """The first config entry or summary attribute (``what``) missing or of the wrong type
    (``say_null``: the message says when null is allowed too)."""
    for key, spec in specs.items():
        optional = key.endswith("?")
        key = key.rstrip("?")
        ok, value = get(table, key)
        if not ok:
            if optional:
                continue
            return f"{what} {key!r} is missing"
        if not typed(value, spec):
            null = " or null" if say_null and spec.endswith("?") else ""
            return f"{what} {key!r} must be {WORDS[spec.rstrip('?')]}{null}, got {value!r:.60}"
    return None


def _flat(table: dict, key: str) -> tuple[bool, Any]:
    return (key in table), table.get(key)


def _config(art, schema: Schema, dims: dict) -> str | None:
    return _entries(art.config, schema.config, "config entry", lookup, False)


def _attrs(art, schema: Schema, dims: dict) -> str | None:
    return _entries(art.attrs, schema.attrs, "summary attribute", _flat, True)


# -- datasets: presence, dtype, shape --------------------------------------------------------------

def _kind_of(arr: np.ndarray) -> str:
    k = arr.dtype.kind
    return "U" if k in "USO" else k


def _dtype(f: _Found, dims: dict) -> str | None:
    if _kind_of(f.arr) not in f.ds.kinds:
        return (f"dataset {f.path!r} holds {f.arr.dtype}, expected "
                f"{KIND_WORDS.get(f.ds.kinds, f.ds.kinds)}")
    return None


def _ndim(f: _Found, dims: dict) -> str | None:
    if f.arr.ndim != len(f.ds.shape):
        return f"dataset {f.path!r} has {f.arr.ndim} dimension(s), expected {len(f.ds.shape)}"
    return None


def _axes(f: _Found, dims: dict) -> str | None:
    """Fixed lengths match; a symbol's length is that of its first dataset (recorded in dims)."""
    for axis, (n, want) in enumerate(zip(f.arr.shape, f.ds.shape, strict=True)):
        if want == "*":
            continue
        if isinstance(want, int):
            expected, was = want, ""
        else:
            expected, first = dims.setdefault(want, (n, f.path))
            was = f" (as {first!r})"
        if n != expected:
            return f"dataset {f.path!r} has length {n} along axis {axis}, expected {expected}{was}"
    return None


#: Checks of one dataset's dtype and shape, in order.
_SHAPE_CHECKS: tuple[Callable[[_Found, dict], str | None], ...] = (_dtype, _ndim, _axes)


def _node(art, ds: Dataset, path: str) -> tuple[_Found | None, str | None]:
    found, node = lookup(art.data, path, "/")
    if not found:
        return None, (None if ds.optional else f"dataset {path!r} is missing")
    if isinstance(node, dict):
        return None, f"{path!r} is a group, expected a dataset"
    return _Found(ds, path, np.asarray(node)), None


def _datasets(art, schema: Schema, dims: dict, found: list[_Found]) -> str | None:
    """Find every dataset the artifact must hold and check its dtype and shape."""
    for ds in schema.datasets:
        if ds.when is not None and not ds.when(art):
            continue
        for path in expand(ds.path, art):
            f, msg = _node(art, ds, path)
            for check in _SHAPE_CHECKS if f is not None else ():
                msg = msg or check(f, dims)
            if msg:
                return msg
            if f is not None:
                found.append(f)
    return None


# -- dataset values --------------------------------------------------------------------------------

def _finite(f: _Found, art, dims: dict) -> str | None:
    """Float values are finite, or NaN where the dataset says NaN marks a missing value."""
    if not (f.ds.finite and f.arr.size and f.arr.dtype.kind == "f"):
        return None
    if f.ds.nan:
        if np.any(np.isinf(f.arr)):
            return f"dataset {f.path!r} holds infinite values"
    elif not np.all(np.isfinite(f.arr)):
        return f"dataset {f.path!r} holds NaN or infinite values"
    return None


def _axis_length(sym: str, art, dims: dict) -> int | None:
    """The length of axis ``sym``: from the datasets, or for keys (``K``) from the keyboard."""
    n = dims.get(sym, (None,))[0]
    if n is None and sym == "K":
        n = rules.n_keys(art)
    return n


def bound_error(arr: np.ndarray, n: int, inclusive: bool) -> int | None:
    """The largest value allowed in ``arr`` if any value of it is outside it, else None.

    Indices into an axis of length ``n`` lie in ``[0, n - 1]``; steps (``inclusive``) in
    ``[0, n]``.
    """
    hi = n if inclusive else n - 1
    if arr.size and (arr.min() < 0 or arr.max() > hi):
        return hi
    return None


def _bounds(f: _Found, art, dims: dict) -> str | None:
    if not f.arr.size:
        return None
    for sym, inclusive in ((f.ds.index, False), (f.ds.upto, True)):
        n = None if sym is None else _axis_length(sym, art, dims)
        hi = None if n is None else bound_error(f.arr, n, inclusive)
        if hi is not None:
            return f"dataset {f.path!r} holds values outside [0, {hi}]"
    return None


#: Checks of one dataset's values, once every dataset's shape is known.
_VALUE_CHECKS = (_finite, _bounds)


def _values(art, found: list[_Found], dims: dict) -> str | None:
    for f in found:
        for check in _VALUE_CHECKS:
            msg = check(f, art, dims)
            if msg:
                return msg
    return None


def _rules(art, schema: Schema) -> str | None:
    for check in schema.checks:
        try:
            msg = check(art)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            msg = f"inconsistent entries ({type(exc).__name__}: {exc})"
        if msg:
            return msg
    return None


def problem(art) -> str | None:
    """What in ``art`` does not match its kind's schema (the first thing found), or None."""
    schema = schema_for(art.kind, int(art.schema_version or 1))
    if schema is None:
        return None
    dims: dict[str, tuple[int, str]] = {}
    found: list[_Found] = []
    return (_config(art, schema, dims) or _attrs(art, schema, dims)
            or _datasets(art, schema, dims, found) or _values(art, found, dims)
            or _rules(art, schema))


def validate(art, where: str = "") -> None:
    """Check an artifact read from disk against its kind's schema.

    Parameters
    ----------
    art : Artifact
    where : str
        The file name, for the message.

    Raises
    ------
    ArtifactError
        Naming the first missing or malformed entry.
    """
    msg = problem(art)
    if msg:
        pre = f"{where}: " if where else ""
        raise ArtifactError(f"{pre}{art.kind} artifact: {msg}")
