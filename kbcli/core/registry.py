"""One registry helper for every interchangeable part of kbcli.

Posteriors, estimators, transform families, sim modes, model classes, strategies (adaptation and
exploration), detectors, layouts and arm presets are each a :class:`Registry`: filled one way
(:meth:`Registry.register`, a decorator or a call), read one way (:meth:`Registry.get`), and an
unknown name is answered with the list of known ones. Code never branches on a part's name: it asks
the registered object.

Examples
--------
>>> from kbcli.core.registry import Registry
>>> SHAPES = Registry("shape")
>>> @SHAPES.register("square", summary="four equal sides")
... def square(side):
...     return side * side
>>> SHAPES.get("square")(3)
9
>>> SHAPES.names()
('square',)
>>> SHAPES.get("circle")
Traceback (most recent call last):
...
kbcli.errors.ConfigError: unknown shape 'circle'; valid: square
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any, Generic, TypeVar, overload

from kbcli.errors import ConfigError

T = TypeVar("T")


class Registry(Generic[T]):
    """Named entries of one kind of part, in registration order.

    Parameters
    ----------
    kind : str
        What an entry is, for messages ("posterior", "model class", ...).
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._entries: dict[str, T] = {}
        self._summaries: dict[str, str] = {}
        self._traits: dict[str, dict[str, Any]] = {}

    @overload
    def register(self, name: str, obj: None = None, *, summary: str = "",
                 replace: bool = False,
                 traits: dict[str, Any] | None = None) -> Callable[[T], T]: ...

    @overload
    def register(self, name: str, obj: T, *, summary: str = "", replace: bool = False,
                 traits: dict[str, Any] | None = None) -> T: ...

    def register(self, name: str, obj: T | None = None, *, summary: str = "",
                 replace: bool = False, traits: dict[str, Any] | None = None) -> Any:
        """Register ``obj`` as ``name``; without ``obj``, a decorator that registers what it wraps.

        Parameters
        ----------
        summary : str
            One line on what the entry does (``--help``, :meth:`describe`); default: the first
            line of the entry's docstring.
        replace : bool
            Allow replacing an entry of the same name (otherwise a ``ValueError``).
        traits : dict, optional
            What the part declares of itself (``{"simulates": True}``, ``{"options":
            KdeOptions}``), read with :meth:`trait`.
        """
        if not isinstance(name, str) or not name:
            raise ValueError(f"a {self.kind} needs a non-empty name, got {name!r}")

        def add(entry: T) -> T:
            if name in self._entries and not replace:
                raise ValueError(f"{self.kind} {name!r} is registered twice")
            self._entries[name] = entry
            doc = (getattr(entry, "__doc__", None) or "").strip().splitlines()
            self._summaries[name] = summary or (doc[0] if doc else "")
            self._traits[name] = dict(traits or {})
            return entry

        return add if obj is None else add(obj)

    def unregister(self, name: str) -> None:
        """Remove ``name`` (a plug-in's tests clean up after themselves)."""
        self._entries.pop(name, None)
        self._summaries.pop(name, None)
        self._traits.pop(name, None)

    @contextlib.contextmanager
    def temporarily(self, name: str, obj: T, *, summary: str = "",
                    traits: dict[str, Any] | None = None) -> Iterator[T]:
        """Register ``obj`` as ``name`` for the duration of a ``with`` block."""
        self.register(name, obj, summary=summary, traits=traits)
        try:
            yield obj
        finally:
            self.unregister(name)

    def get(self, name: str) -> T:
        """The entry registered as ``name``.

        Raises
        ------
        ConfigError
            For an unknown name, listing the valid ones.
        """
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise ConfigError(
                f"unknown {self.kind} {name!r}; valid: {', '.join(self._entries)}") from None

    def check(self, name: str) -> str:
        """``name`` itself when it is registered (for config validators); ConfigError otherwise."""
        self.get(name)
        return name

    def trait(self, name: str, key: str, default: Any = None) -> Any:
        """What ``name`` declared as ``key`` when registered (``traits=``), else ``default``."""
        self.get(name)
        return self._traits[name].get(key, default)

    def having(self, key: str, value: Any = True) -> tuple[str, ...]:
        """The names whose trait ``key`` is ``value``, in registration order."""
        return tuple(n for n in self._entries if self._traits[n].get(key) == value)

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self._entries)

    def summary(self, name: str) -> str:
        """The one-line summary of ``name``."""
        self.get(name)
        return self._summaries[name]

    def describe(self, sep: str = "; ") -> str:
        """``name (summary)`` of every entry, for help texts."""
        return sep.join(f"{n} ({s})" if s else n for n, s in self._summaries.items())

    def items(self) -> Iterator[tuple[str, T]]:
        return iter(self._entries.items())

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._entries)})"
