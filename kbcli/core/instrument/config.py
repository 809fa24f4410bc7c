"""A keyboard's config: its layout (a part with options of its own), where it lies, and the sounds
of its keys (paper Sect. III-A). Building the config places the keys and checks them: inside the
pad, not overlapping, and every two keys sounding further apart than the matching threshold
(Eq. 2), or the robot could not tell them apart.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from pydantic import PrivateAttr, field_validator

from kbcli.core.config import Config, Name, Number, between
from kbcli.core.instrument.geometry import (
    MAX_COORD,
    Coordinate,
    check_in_pad,
    check_key_areas,
    check_overlaps,
)
from kbcli.core.instrument.layouts import DEFAULT_CENTRE, LAYOUTS, LayoutGeometry
from kbcli.core.instrument.notes import DEFAULT_SCALE, SCALES, midi_to_name, name_to_midi
from kbcli.core.options import declared, flat_view, part_field, route
from kbcli.errors import ConfigError

FEATURE_NAMES = ("pitch", "tempo")

#: Bounds of the physical parameters of a keyboard config (a value beyond them is refused, naming
#: the bound): lengths in pad px; the tempo of key 0 and its steps per column and row in bpm; the
#: perception noise and the match threshold in feature units (semitones of pitch, bpm of tempo).
MAX_TEMPO = 10_000.0
MAX_TEMPO_STEP = 1_000.0
MAX_NOISE_STD = 100.0
MAX_MATCH_THRESHOLD = 100.0

class KeyboardConfig(Config):
    """Layout, geometry and sounds of a keyboard. All lengths in pad pixels.

    The layout is a part with options of its own (:mod:`kbcli.core.instrument.layouts`): a name,
    a table ``{name, options...}`` or the layout's options given flat beside its name
    (``KeyboardConfig(layout="pads", pad_radius=15)``) are read; ``to_dict`` writes the flat form.

    Parameters
    ----------
    layout : Options
        A layout of :data:`~kbcli.core.instrument.layouts.LAYOUTS` with its options.
    origin : tuple of float
        Lower-left corner of the keyboard at its reference pose (default: the keyboard centred on
        (400, 350); polygons: (0, 0), so their vertices are pad coordinates).
    margin : float
        Width of the band around the keyboard that belongs to the robot's working area.
    base_note : str
        Note of key 0 (bottom-left); the next keys climb ``scale`` (grid, pads, polygons), the
        Wicki-Hayden lattice (hex) or the chromatic scale (piano).
    scale : str
        One of ``SCALES`` (grid, pads, polygons; default diatonic).
    tempo_base, tempo_col_step, tempo_row_step : float
        Tempo of key (r, c) is ``tempo_base + c * tempo_col_step + r * tempo_row_step`` bpm (grid,
        hex, pads).
    noise_std : float
        Standard deviation of the Gaussian noise added to perceived features.
    match_threshold : float
        Manhattan distance below which a perceived sound matches a known one (Eq. 2).

    Every value is bounded by this module's ``MAX_*`` constants (lengths by
    :data:`~kbcli.core.instrument.geometry.MAX_COORD`).
    """

    what: ClassVar[str] = "keyboard"
    layout: part_field(LAYOUTS, "grid") = "grid"
    origin: tuple[Coordinate, Coordinate] | None = None
    margin: between(Number, 0, MAX_COORD) = 50.0
    base_note: Name = "C3"
    scale: Name | None = None
    tempo_base: between(Number, 0, MAX_TEMPO, low_open=True) = 60.0
    tempo_col_step: between(Number, 0, MAX_TEMPO_STEP) = 4.0
    tempo_row_step: between(Number, 0, MAX_TEMPO_STEP) = 30.0
    noise_std: between(Number, 0, MAX_NOISE_STD) = 0.0
    match_threshold: between(Number, 0, MAX_MATCH_THRESHOLD, low_open=True) = 1.5
    _geometry: LayoutGeometry = PrivateAttr()

    def __init__(self, /, **data: Any) -> None:
        super().__init__(**_with_layout_defaults(data))
        lay = LAYOUTS.get(self.layout.name)
        local = lay.build(self)  # the keys in the keyboard's frame; raises on bad geometry
        if self.origin is None:  # the default origin is filled in once, at construction
            self.__dict__["origin"] = _default_origin(lay.default_origin, local.bounds)
        self._geometry = _placed(local, self.origin, self.match_threshold)

    @field_validator("base_note")
    @classmethod
    def _note(cls, v: str) -> str:
        name_to_midi(v)
        return v

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and self.__dict__ == other.__dict__

    def __hash__(self) -> int:
        return hash(tuple(self.__dict__.items()))

    @property
    def geometry(self) -> LayoutGeometry:
        """The keys on the pad at the reference pose (built and checked by the config)."""
        return self._geometry

    def pitches(self) -> np.ndarray:
        """MIDI pitch of every key, (K,) int."""
        return self.geometry.pitches.copy()

    def to_dict(self) -> dict[str, Any]:
        """The config as a plain mapping in the flat form: the layout's name and its own options,
        and the keyboard's (``scale`` only where the layout uses it)."""
        d = {k: getattr(self, k) for k in type(self).model_fields if k != "layout"}
        if d["scale"] is None:
            del d["scale"]
        d = {**flat_view({"layout": self.layout.to_dict()}, ("layout",)), **d}
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> KeyboardConfig:
        """Build from a mapping (a TOML table, an artifact's config); unknown keys are rejected.

        A mapping without ``layout`` (schema 1 keyboard artifacts) is a grid.
        """
        return super().from_dict(d)  # type: ignore[return-value]


def _with_layout_defaults(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with the layout's options given flat moved into the layout (which refuses one it
    does not take, naming it; :func:`kbcli.core.options.route`) and its scale set."""
    out = route({k: v for k, v in data.items() if v is not None or k == "scale"},
                {"layout": (LAYOUTS, "grid")}, KeyboardConfig.model_fields)
    lay = LAYOUTS.get(out["layout"]["name"])
    unknown = [k for k in out if k not in KeyboardConfig.model_fields]
    if unknown:  # the valid keys a user may type: the keyboard's and its layout's own
        valid = ["layout", *declared(LAYOUTS, lay.name),
                 *(k for k in KeyboardConfig.model_fields
                   if k != "layout" and (k != "scale" or lay.uses_scale))]
        raise ConfigError(f"unknown keyboard option {unknown[0]!r}; valid: {', '.join(valid)}")
    if not lay.uses_scale and out.get("scale") is not None:
        raise ConfigError(f"scale does not apply to the {lay.name} layout (its notes follow "
                          f"its own lattice)")
    if lay.uses_scale:
        out["scale"] = SCALES.check(out.get("scale") or DEFAULT_SCALE)
    return out


def _default_origin(default: tuple[float, float] | None,
                    bounds: tuple[float, float, float, float]) -> tuple[float, float]:
    """The layout's default origin, or the one centring keys of ``bounds`` on DEFAULT_CENTRE."""
    if default is None:
        x0, y0, x1, y1 = bounds
        default = (DEFAULT_CENTRE[0] - (x0 + x1) / 2, DEFAULT_CENTRE[1] - (y0 + y1) / 2)
    return (float(default[0]), float(default[1]))


def _placed(local: LayoutGeometry, origin: tuple[float, float],
            threshold: float) -> LayoutGeometry:
    """The keys moved to ``origin`` and checked: MIDI range, inside the pad, no overlap, sounds
    apart (Eq. 2)."""
    geom = local.moved(origin)
    names = tuple(midi_to_name(p) for p in geom.pitches)
    top = int(np.max(geom.pitches))
    if top > 127:
        raise ConfigError(f"the highest key would be MIDI {top}, above 127: lower base_note")
    check_in_pad(geom.shapes)
    check_key_areas(geom.shapes, names)
    check_overlaps(geom.shapes, names)
    _check_distinct(key_features(geom), names, threshold)
    return geom


def _check_distinct(features: np.ndarray, names: tuple[str, ...], threshold: float) -> None:
    """ConfigError naming two keys whose sounds are within the matching threshold (Eq. 2)."""
    d = np.abs(features[:, None, :] - features[None, :, :]).sum(axis=-1)
    d[np.diag_indices(len(d))] = np.inf
    i, j = np.unravel_index(np.argmin(d), d.shape)
    if d[i, j] <= threshold:
        i, j = min(i, j), max(i, j)
        raise ConfigError(
            f"keys {i} ({names[i]}, {features[i, 1]:g} bpm) and {j} ({names[j]}, "
            f"{features[j, 1]:g} bpm) sound alike: their Manhattan distance {d[i, j]:g} is not "
            f"above match_threshold {threshold:g} (Eq. 2); change their notes or tempi")


def key_features(geom: LayoutGeometry) -> np.ndarray:
    """(K, 2) the sound of every key: pitch (MIDI) and tempo (bpm)."""
    return np.column_stack([geom.pitches.astype(float), geom.tempos.astype(float)])
