"""The instrument: a virtual keyboard laid on a tactile pad (paper Sect. III-A, Fig. 2).

Coordinates are pad pixels, x to the right and y up. The keys' shapes, pitches and tempi come from a
*layout* (:mod:`kbcli.core.instrument.layouts`), placed with the keyboard's lower-left corner at
``origin`` at its *reference pose*; outside the keys is silence (key ``-1``). Each key plays a
sound of D = 2 features, pitch (MIDI note) and tempo (bpm); every two keys must sound further
apart than the matching threshold (Eq. 2). Everything else reads the geometry through
:class:`Keyboard`: nothing assumes square keys.

A displaced keyboard is a transform of the pad (:mod:`kbcli.core.instrument.transforms`): the sound
under finger position ``x`` is the reference sound under ``T^-1(x)``. Perception adds optional
Gaussian noise to the features; matching uses the Manhattan distance with a threshold (Eq. 2).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kbcli.core.instrument import transforms
from kbcli.core.instrument.config import FEATURE_NAMES, KeyboardConfig, key_features
from kbcli.core.instrument.layouts import LAYOUTS, PolygonKey
from kbcli.core.instrument.notes import SCALES, midi_to_name, name_to_midi, sound_name
from kbcli.errors import ConfigError

__all__ = ["SCALES", "LAYOUTS", "FEATURE_NAMES", "KeyboardConfig", "Keyboard", "PolygonKey",
           "match", "midi_to_name", "name_to_midi", "sound_name"]


@dataclass(frozen=True)
class Keyboard:
    """A keyboard built from its config, with vectorized lookups.

    Attributes
    ----------
    features : (K, 2) ndarray
        Pitch and tempo of each key.
    names : tuple of str
        Note name of each key.
    """

    config: KeyboardConfig
    features: np.ndarray = field(init=False, repr=False)
    names: tuple[str, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        g = self.config.geometry
        feats = key_features(g)
        feats.setflags(write=False)
        object.__setattr__(self, "features", feats)
        object.__setattr__(self, "names", tuple(midi_to_name(p) for p in g.pitches))

    # -- geometry -------------------------------------------------------------------------------
    @property
    def layout(self) -> str:
        return self.config.layout.name

    @property
    def shapes(self):
        """The keys' :class:`~kbcli.core.instrument.geometry.KeyShapes` at the reference pose."""
        return self.config.geometry.shapes

    @property
    def n_keys(self) -> int:
        return self.shapes.n_keys

    @property
    def pitches(self) -> np.ndarray:
        """(K,) MIDI note of each key."""
        return self.config.geometry.pitches

    @property
    def size(self) -> np.ndarray:
        """(2,) width and height of the keyboard."""
        x0, y0, x1, y1 = self.bounds
        return np.array([x1 - x0, y1 - y0], float)

    @property
    def centre(self) -> np.ndarray:
        """(2,) centre of the keyboard at its reference pose (the rotation centre of rigid moves)."""
        x0, y0, x1, y1 = self.bounds
        return np.array([(x0 + x1) / 2, (y0 + y1) / 2])

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the keyboard at its reference pose."""
        return tuple(float(v) for v in self.config.geometry.bounds)  # type: ignore[return-value]

    @property
    def area(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the working area: the keyboard plus its margin."""
        m = self.config.margin
        x0, y0, x1, y1 = self.bounds
        return (x0 - m, y0 - m, x1 + m, y1 + m)

    def key_centres(self) -> np.ndarray:
        """(K, 2) a point well inside each key (its centre) at the reference pose."""
        return self.shapes.label_points()

    def key_outlines(self) -> list[np.ndarray]:
        """The outline of each key as a counter-clockwise polygon (pads as 64-gons)."""
        return self.shapes.outlines()

    def sample_in_key(self, key: int, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 2) uniform draws inside ``key`` at the reference pose."""
        return self.shapes.sample(int(key), int(n), rng)

    def key_grid_points(self, per_side: int) -> tuple[np.ndarray, np.ndarray]:
        """An even grid of points inside every key: (m, 2) points and (m,) their keys."""
        return self.shapes.grid_points(int(per_side))

    def key_outline_points(self, spacing: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
        """Points along every key's outline (vertices and at most ``spacing`` px apart) and their
        keys."""
        return self.shapes.outline_points(spacing)

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
            Transform family of ``pose`` (see :data:`kbcli.core.instrument.transforms.FAMILIES`).

        Returns
        -------
        (n,) int ndarray
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        if pose is not None:
            p = transforms.inverse(family, np.asarray(pose, float), p, self.centre)
        return self.shapes.key_at(p)

    def sound_of(self, keys: np.ndarray) -> np.ndarray:
        """Features of key indices, (n, 2); NaN rows for silence (-1)."""
        keys = np.asarray(keys)
        out = np.full((len(keys), self.features.shape[1]), np.nan)
        ok = keys >= 0
        out[ok] = self.features[keys[ok]]
        return out

    def perceive(self, points: np.ndarray, pose: np.ndarray | None = None,
                 family: str = "translation", *, rng: np.random.Generator) -> np.ndarray:
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
        """Index of the (first) key that plays ``note`` (a name like 'A', 'F#3' or a MIDI number)."""
        midi = note if isinstance(note, (int, np.integer)) else name_to_midi(str(note))
        hits = np.flatnonzero(self.pitches == midi)
        if len(hits) == 0:
            lo, hi = midi_to_name(self.pitches.min()), midi_to_name(self.pitches.max())
            raise ConfigError(f"note {note!r} is not on the keyboard (keys span {lo} to {hi})")
        return int(hits[0])

    def key_label(self, key: int) -> str:
        """How messages name a key: its note, and its index when another key plays that note."""
        name = self.names[int(key)]
        return name if self.names.count(name) == 1 else f"{name} (key {int(key)})"

    def describe(self) -> str:
        """One line: the layout, its keys and their range."""
        c = self.config
        lo, hi = midi_to_name(self.pitches.min()), midi_to_name(self.pitches.max())
        what = LAYOUTS.get(c.layout.name).describe(c, self.n_keys)
        return f"{what}, {lo} to {hi}"


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
