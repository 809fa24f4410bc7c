"""Melodies: the task the robot performs, a looped sequence of (note, duration) pairs (Eq. 1, Fig. 3).

A melody is written as space-separated ``NOTE:BEATS`` tokens, e.g. the paper's Fig. 3 example
``"A:1 D:1 E:0.5 D:2 A:1"``; a token without ``:BEATS`` lasts one beat. Note names are scientific
pitch names (``A`` is ``A4``, ``F#3``, ``Bb4``; see :func:`kbcli.core.instrument.keyboard.name_to_midi`) and
must be keys of the keyboard. A note's tempo is a property of its key (Fig. 2), so a duration in
beats lasts ``beats * 60 / tempo`` seconds when played.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kbcli.core.instrument.keyboard import Keyboard, midi_to_name, name_to_midi
from kbcli.errors import ConfigError

#: The paper's Fig. 3 example, S = {(A, 1), (D, 1), (E, 0.5), (D, 2), (A, 1)}.
DEFAULT_MELODY = "A:1 D:1 E:0.5 D:2 A:1"

#: Limits of a melody: at most this many notes, each lasting at most this many beats.
MAX_NOTES = 256
MAX_BEATS = 16.0


@dataclass(frozen=True)
class Melody:
    """A parsed melody on a given keyboard.

    Attributes
    ----------
    notes : tuple of str
        Note names as written.
    midi : tuple of int
        MIDI pitch of each note.
    durations : tuple of float
        Duration of each note in beats (> 0).
    keys : tuple of int
        Index of the key that plays each note.
    """

    notes: tuple[str, ...]
    midi: tuple[int, ...]
    durations: tuple[float, ...]
    keys: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.notes)

    @property
    def text(self) -> str:
        """Canonical text form (``A4:1 D4:1 ...``)."""
        return " ".join(f"{midi_to_name(m)}:{d:g}" for m, d in zip(self.midi, self.durations, strict=True))


def parse_melody(text: str, keyboard: Keyboard) -> Melody:
    """Parse ``"A:1 D:1 E:0.5"`` into a :class:`Melody` on ``keyboard``.

    Raises
    ------
    ConfigError
        Empty melody or more than :data:`MAX_NOTES` notes, a malformed token, a duration that is
        not a number in (0, :data:`MAX_BEATS`] beats, or a note that is unknown or not on the
        keyboard (the message names it).
    """
    tokens = str(text).split()
    if not tokens:
        raise ConfigError("melody is empty: give notes like 'A:1 D:1 E:0.5 D:2 A:1'")
    if len(tokens) > MAX_NOTES:
        raise ConfigError(f"melody has {len(tokens)} notes, more than the {MAX_NOTES} allowed")
    notes, midi, durations, keys = [], [], [], []
    for tok in tokens:
        name, sep, beats = tok.partition(":")
        if not name:
            raise ConfigError(f"melody token {tok!r} has no note; expected NOTE:BEATS like A:1")
        if sep:
            try:
                dur = float(beats)
            except ValueError:
                raise ConfigError(
                    f"melody token {tok!r}: duration {beats!r} is not a number of beats"
                ) from None
        else:
            dur = 1.0
        if not (math.isfinite(dur) and 0 < dur <= MAX_BEATS):
            raise ConfigError(f"melody token {tok!r}: duration must be > 0 and at most {MAX_BEATS:g} beats, "
                              f"got {beats!r}")
        m = name_to_midi(name)  # ConfigError naming an unknown note
        k = keyboard.note_key(name)  # ConfigError naming a note that is not on the keyboard
        notes.append(name)
        midi.append(m)
        durations.append(dur)
        keys.append(k)
    return Melody(tuple(notes), tuple(midi), tuple(durations), tuple(keys))

