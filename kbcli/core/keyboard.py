"""The instrument: a virtual keyboard of square keys laid on a tactile pad (paper Sect. III-A, Fig. 2).

Coordinates are pad pixels, x to the right and y up. At its *reference pose* the keyboard's lower-left
corner sits at ``origin``; key ``k`` is row ``k // cols`` (row 0 at the bottom), column ``k % cols``.
Outside the keys is silence (key index ``-1``). Each key plays a sound described by a D-dimensional
feature vector; here D = 2: pitch (MIDI note number) and tempo (beats per minute). In the paper every
key changes both. Pitches climb a scale row by row; tempo grows with the column and with the row.

A displaced keyboard is described by a transform of the pad (:mod:`kbcli.core.transforms`): the sound
under finger position ``x`` is the reference sound under ``T^-1(x)``.

Perception adds optional Gaussian noise to the features; matching a perceived sound to a list of
known sounds uses the Manhattan distance with a threshold (Eq. 2, Algorithm 1).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from kbcli.core import transforms
from kbcli.core.config import check_known
from kbcli.errors import ConfigError

SCALES: dict[str, tuple[int, ...]] = {
    "diatonic": (0, 2, 4, 5, 7, 9, 11),  # C major
    "chromatic": tuple(range(12)),
    "pentatonic": (0, 2, 4, 7, 9),
}
NOTE_NAMES = ("C", "C#", "D", "D#", "E", "F", "F#", "G", "G#", "A", "A#", "B")
_NOTE_RE = re.compile(r"^([A-Ga-g])([#b]?)(-?\d+)?$")
DEFAULT_OCTAVE = 4
FEATURE_NAMES = ("pitch", "tempo")


def _positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{name} must be a positive finite number, got {value!r}")


def _non_negative(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ConfigError(f"{name} must be a finite number >= 0, got {value!r}")


def midi_to_name(midi: int) -> str:
    """MIDI note number -> scientific pitch name (60 -> 'C4')."""
    return f"{NOTE_NAMES[int(midi) % 12]}{int(midi) // 12 - 1}"


def sound_name(features) -> str:
    """A heard sound in words: ``"A4 96 bpm"`` (the pitch's nearest note), ``"silence"`` (NaN)."""
    f = np.asarray(features, float).reshape(-1)
    if f.size == 0 or np.isnan(f).all():
        return "silence"
    text = midi_to_name(int(np.rint(f[0])))
    return f"{text} {f[1]:.0f} bpm" if f.size > 1 and np.isfinite(f[1]) else text


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


@dataclass(frozen=True, kw_only=True)
class KeyboardConfig:
    """Geometry and sounds of a keyboard. All lengths in pad pixels.

    Parameters
    ----------
    rows, cols : int
        Number of key rows and columns.
    key_size : float
        Side of a square key.
    origin : tuple of float
        Lower-left corner of the keyboard at its reference pose.
    margin : float
        Width of the band around the keyboard that belongs to the robot's working area (where it
        explores, where displaced keys can be, and where model accuracy is measured).
    base_note : str
        Note of key 0 (bottom-left); the next keys climb ``scale`` row by row.
    scale : str
        One of ``SCALES``.
    tempo_base, tempo_col_step, tempo_row_step : float
        Tempo of key (r, c) is ``tempo_base + c * tempo_col_step + r * tempo_row_step`` bpm.
    noise_std : float
        Standard deviation of the Gaussian noise added to perceived features (pitch and tempo units).
    match_threshold : float
        Manhattan distance below which a perceived sound matches a known one (Eq. 2).
    """

    rows: int = 4
    cols: int = 8
    key_size: float = 50.0
    origin: tuple[float, float] = (200.0, 250.0)
    margin: float = 50.0
    base_note: str = "C3"
    scale: str = "diatonic"
    tempo_base: float = 60.0
    tempo_col_step: float = 4.0
    tempo_row_step: float = 30.0
    noise_std: float = 0.0
    match_threshold: float = 1.5

    def __post_init__(self) -> None:
        for name in ("rows", "cols"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ConfigError(f"{name} must be a whole number >= 1, got {v!r}")
        if self.rows * self.cols > 256:
            raise ConfigError(f"rows x cols must be at most 256 keys, got {self.rows * self.cols}")
        _positive("key_size", self.key_size)
        _positive("match_threshold", self.match_threshold)
        _non_negative("margin", self.margin)
        _non_negative("noise_std", self.noise_std)
        for name in ("tempo_base", "tempo_col_step", "tempo_row_step"):
            _non_negative(name, getattr(self, name))
        if self.tempo_base <= 0:
            raise ConfigError(f"tempo_base must be > 0 bpm, got {self.tempo_base!r}")
        if len(self.origin) != 2 or not all(
            isinstance(v, (int, float)) and math.isfinite(v) for v in self.origin
        ):
            raise ConfigError(f"origin must be two finite numbers, got {self.origin!r}")
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        if self.scale not in SCALES:
            raise ConfigError(f"unknown scale {self.scale!r}; valid: {', '.join(SCALES)}")
        name_to_midi(self.base_note)
        top = self.pitches().max()
        if top > 127:
            raise ConfigError(f"the highest key would be MIDI {top}, above 127: lower base_note")

    def pitches(self) -> np.ndarray:
        """MIDI pitch of every key, (rows * cols,) int."""
        steps = SCALES[self.scale]
        base = name_to_midi(self.base_note)
        k = np.arange(self.rows * self.cols)
        return base + 12 * (k // len(steps)) + np.asarray(steps)[k % len(steps)]

    def to_dict(self) -> dict:
        return {
            "rows": self.rows,
            "cols": self.cols,
            "key_size": self.key_size,
            "origin": list(self.origin),
            "margin": self.margin,
            "base_note": self.base_note,
            "scale": self.scale,
            "tempo_base": self.tempo_base,
            "tempo_col_step": self.tempo_col_step,
            "tempo_row_step": self.tempo_row_step,
            "noise_std": self.noise_std,
            "match_threshold": self.match_threshold,
        }

    @classmethod
    def from_dict(cls, d: dict) -> KeyboardConfig:
        """Build from a mapping (a TOML table, an artifact's config); unknown keys are rejected."""
        check_known(cls, d, "keyboard")
        d = dict(d)
        if "origin" in d:
            d["origin"] = tuple(d["origin"])
        return cls(**d)


@dataclass(frozen=True)
class Keyboard:
    """A keyboard built from its config, with vectorized lookups.

    Attributes
    ----------
    features : (K, 2) ndarray
        Pitch and tempo of each key.
    names : list of str
        Note name of each key.
    """

    config: KeyboardConfig
    features: np.ndarray = field(init=False, repr=False)
    names: tuple[str, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        c = self.config
        k = np.arange(c.rows * c.cols)
        tempo = c.tempo_base + (k % c.cols) * c.tempo_col_step + (k // c.cols) * c.tempo_row_step
        feats = np.column_stack([c.pitches().astype(float), tempo.astype(float)])
        feats.setflags(write=False)
        object.__setattr__(self, "features", feats)
        object.__setattr__(self, "names", tuple(midi_to_name(p) for p in c.pitches()))

    # -- geometry -------------------------------------------------------------------------------
    @property
    def n_keys(self) -> int:
        return self.config.rows * self.config.cols

    @property
    def size(self) -> np.ndarray:
        """(2,) width and height of the keyboard."""
        return np.array([self.config.cols, self.config.rows], float) * self.config.key_size

    @property
    def centre(self) -> np.ndarray:
        """(2,) centre of the keyboard at its reference pose (the rotation centre of rigid moves)."""
        return np.asarray(self.config.origin) + self.size / 2

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the keyboard at its reference pose."""
        x0, y0 = self.config.origin
        w, h = self.size
        return (x0, y0, x0 + w, y0 + h)

    @property
    def area(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the working area: the keyboard plus its margin."""
        m = self.config.margin
        x0, y0, x1, y1 = self.bounds
        return (x0 - m, y0 - m, x1 + m, y1 + m)

    def key_centres(self) -> np.ndarray:
        """(K, 2) centre of each key at the reference pose."""
        c = self.config
        k = np.arange(self.n_keys)
        return np.column_stack(
            [
                c.origin[0] + (k % c.cols + 0.5) * c.key_size,
                c.origin[1] + (k // c.cols + 0.5) * c.key_size,
            ]
        )

    def key_at(
        self, points: np.ndarray, pose: np.ndarray | None = None, family: str = "translation"
    ) -> np.ndarray:
        """Key index under each point, -1 for silence.

        Parameters
        ----------
        points : (n, 2) ndarray
            Finger positions on the pad.
        pose : (P,) ndarray, optional
            Displacement of the keyboard, in the parameters of ``family`` (None: reference pose).
        family : str
            Transform family of ``pose`` (see :data:`kbcli.core.transforms.FAMILIES`).

        Returns
        -------
        (n,) int ndarray
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        if pose is not None:
            p = transforms.inverse(family, np.asarray(pose, float), p, self.centre)
        c = self.config
        u = (p - np.asarray(c.origin)) / c.key_size
        col = np.floor(u[:, 0])
        row = np.floor(u[:, 1])
        inside = (col >= 0) & (col < c.cols) & (row >= 0) & (row < c.rows)
        out = np.full(len(p), -1, dtype=np.int64)
        out[inside] = (row[inside] * c.cols + col[inside]).astype(np.int64)
        return out

    def sound_of(self, keys: np.ndarray) -> np.ndarray:
        """Features of key indices, (n, 2); NaN rows for silence (-1)."""
        keys = np.asarray(keys)
        out = np.full((len(keys), self.features.shape[1]), np.nan)
        ok = keys >= 0
        out[ok] = self.features[keys[ok]]
        return out

    def perceive(
        self,
        points: np.ndarray,
        pose: np.ndarray | None = None,
        family: str = "translation",
        *,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """What the robot hears with its finger at ``points``: features plus noise, NaN for silence.

        Returns
        -------
        (n, 2) ndarray
        """
        s = self.sound_of(self.key_at(points, pose, family))
        if self.config.noise_std > 0:
            s = s + rng.normal(0.0, self.config.noise_std, size=s.shape)
        return s

    def note_key(self, note: str | int) -> int:
        """Index of the key that plays ``note`` (a name like 'A', 'F#3' or a MIDI number)."""
        midi = note if isinstance(note, (int, np.integer)) else name_to_midi(str(note))
        hits = np.flatnonzero(self.config.pitches() == midi)
        if len(hits) == 0:
            lo, hi = self.names[0], self.names[-1]
            raise ConfigError(f"note {note!r} is not on the keyboard (keys span {lo} to {hi})")
        return int(hits[0])


def match(perceived: np.ndarray, known: np.ndarray, threshold: float) -> np.ndarray:
    """Match perceived sounds to known sounds by Manhattan distance (Eq. 2).

    Parameters
    ----------
    perceived : (n, D) ndarray
        Perceived features; a NaN row is silence and matches nothing.
    known : (m, D) ndarray
        Known sounds.
    threshold : float
        A perceived sound matches its nearest known sound when their distance is below this.

    Returns
    -------
    (n,) int ndarray
        Index into ``known`` of the match, or -1 for no match (silence or too far from all).
    """
    perceived = np.atleast_2d(np.asarray(perceived, float))
    known = np.atleast_2d(np.asarray(known, float))
    if known.shape[0] == 0 or known.size == 0:  # nothing known: nothing matches
        return np.full(len(perceived), -1, dtype=np.int64)
    d = np.abs(perceived[:, None, :] - known[None, :, :]).sum(axis=-1)  # (n, m)
    d = np.where(np.isnan(d), np.inf, d)
    best = np.argmin(d, axis=1)
    ok = d[np.arange(len(d)), best] < threshold
    return np.where(ok, best, -1)
