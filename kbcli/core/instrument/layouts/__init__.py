"""Layouts of the instrument: a registry of how keys are shaped, placed and tuned (Sect. III-A).

A layout turns the layout-specific part of a
:class:`~kbcli.core.instrument.keyboard.KeyboardConfig` into the keys' shapes (:class:`KeyShapes`,
in the keyboard's own frame, lower-left at (0, 0)), their pitches (MIDI) and tempi (bpm).
Registered in :data:`LAYOUTS` (``kbcli keyboard --layout NAME``), one module each: ``grid`` (the
paper's Fig. 2), ``hex``, ``piano``, ``pads`` and ``polygons``. A layout declares the config fields
it uses and their defaults (the others must be left out); its builder raises
:class:`~kbcli.errors.ConfigError` naming the key or option at fault. Adding a layout is one module
calling :func:`layout` (imported below).
"""

from __future__ import annotations

from typing import Any

# registration order is the order users see (grid first, the default)
# isort: off
from kbcli.core.instrument.layouts import grid  # noqa: F401
from kbcli.core.instrument.layouts import hexagonal  # noqa: F401
from kbcli.core.instrument.layouts import piano  # noqa: F401
from kbcli.core.instrument.layouts import pads  # noqa: F401
from kbcli.core.instrument.layouts import polygons  # noqa: F401
# isort: on
from kbcli.core.instrument.layouts.base import (
    DEFAULT_CENTRE,
    LAYOUTS,
    MAX_KEYS,
    Layout,
    LayoutGeometry,
    layout,
)
from kbcli.core.instrument.layouts.grid import GridShapes
from kbcli.core.instrument.layouts.polygons import PolygonKey, example_polygon_keys, polygon_keys

__all__ = ["DEFAULT_CENTRE", "LAYOUTS", "MAX_KEYS", "GridShapes", "Layout",
           "LayoutGeometry", "PolygonKey", "example_config_fields", "example_polygon_keys",
           "layout", "polygon_keys"]


def example_config_fields(name: str) -> dict[str, Any]:
    """Config fields of the example keyboard of layout ``name`` (the polygons' keys; nothing for
    the others)."""
    return LAYOUTS.get(name).example_fields()
