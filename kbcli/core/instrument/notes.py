"""Notes and scales: MIDI numbers, scientific pitch names and the scales keys climb (Sect. III-A).

Shared by the keyboard (:mod:`kbcli.core.instrument.keyboard`) and its layouts (:mod:`kbcli.core.instrument.layouts`),
so neither imports the other for them. Scales are a :class:`~kbcli.core.registry.Registry`
(:data:`SCALES`): a scale is the tuple of its pitch classes above the tonic.

Examples
--------
>>> name_to_midi("A"), midi_to_name(60)
(69, 'C4')
>>> scale_pitches(48, "pentatonic", 6).tolist()
[48, 50, 52, 55, 57, 60]
"""

from __future__ import annotations

import re

import numpy as np

from kbcli.core.registry import Registry
from kbcli.errors import ConfigError

NOTE_NAMES = ("C", "C#", "D", "D#", "E", "F", "F#", "G", "G#", "A", "A#", "B")
_NOTE_RE = re.compile(r"^([A-Ga-g])([#b]?)(-?\d+)?$")
DEFAULT_OCTAVE = 4
#: Pitch classes of the black keys of a piano.
BLACK = (1, 3, 6, 8, 10)
#: Pitch classes of the white keys of a piano.
NATURAL = (0, 2, 4, 5, 7, 9, 11)

#: Named scales: the pitch classes of one octave above the tonic.
SCALES: Registry[tuple[int, ...]] = Registry("scale")
SCALES.register("diatonic", NATURAL, summary="C major")
SCALES.register("chromatic", tuple(range(12)), summary="every semitone")
SCALES.register("pentatonic", (0, 2, 4, 7, 9), summary="major pentatonic")
DEFAULT_SCALE = "diatonic"


def midi_to_name(midi: int) -> str:
    """MIDI note number -> scientific pitch name (60 -> 'C4')."""
    return f"{NOTE_NAMES[int(midi) % 12]}{int(midi) // 12 - 1}"


def name_to_midi(name: str) -> int:
    """Scientific pitch name -> MIDI number ('C4' -> 60, 'A' -> 69 with the default octave 4).

    Raises
    ------
    ConfigError
        If the name is not a note name such as ``A``, ``F#3`` or ``Bb4``.
    """
    m = _NOTE_RE.match(name.strip())
    if m is None:
        raise ConfigError(f"unknown note {name!r}: expected a name like A, F#3 or Bb4")
    letter, accidental, octave = m.groups()
    pc = NOTE_NAMES.index(letter.upper()) + {"": 0, "#": 1, "b": -1}[accidental]
    octv = DEFAULT_OCTAVE if octave is None else int(octave)
    return (octv + 1) * 12 + pc


def sound_name(features) -> str:
    """A heard sound in words: ``"A4 106 bpm"`` (the pitch's nearest note), ``"silence"`` (NaN)."""
    f = np.asarray(features, float).reshape(-1)
    if f.size == 0 or np.isnan(f).all():
        return "silence"
    text = midi_to_name(int(np.rint(f[0])))
    return f"{text} {f[1]:.0f} bpm" if f.size > 1 and np.isfinite(f[1]) else text


def scale_pitches(base: int, scale: str, n: int) -> np.ndarray:
    """(n,) MIDI notes climbing ``scale`` from ``base``."""
    steps = SCALES.get(scale)
    k = np.arange(n)
    return base + 12 * (k // len(steps)) + np.asarray(steps)[k % len(steps)]
