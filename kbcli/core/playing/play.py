"""Playing a melody in a loop with the learned model (paper Sect. III-A, Algorithm 1).

Each step samples an action from p(action | sound) for the current note (line 10): a MATCH (0),
the heard sound matching (Eq. 2) a note with the aimed note's sound, moves on to the next note,
looping after the last (lines 4-6); a NO_MATCH (1) restarts from note 0 (lines 7-9).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import match
from kbcli.core.instrument.melody import Melody
from kbcli.errors import ConfigError

MATCH = 0
NO_MATCH = 1

#: ``touch(actions (n, 2)) -> (landed (n, 2), perceived (n, D))``
Touch = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class PlayStep:
    """One step of Algorithm 1.

    ``target`` is the melody index aimed for, ``cls`` its sound class, ``action`` the finger
    target sent, ``landed`` where it landed, ``perceived`` the heard features (NaN: silence),
    ``heard`` the best-matching note (Eq. 2; -1: none) and ``result`` :data:`MATCH` or
    :data:`NO_MATCH` (the history value H of Sect. III-C).
    """

    step: int
    target: int
    cls: int
    action: np.ndarray
    landed: np.ndarray
    perceived: np.ndarray
    heard: int
    result: int


def note_classes(model, melody: Melody) -> np.ndarray:
    """(N,) int: the model's sound class of each melody note, the class nearest in pitch within
    the model's match threshold.

    Raises
    ------
    ConfigError
        If a note has no class in the model.
    """
    feats = np.asarray(model.class_features_, float)
    pitch = feats[:, 0]
    out = np.empty(len(melody), dtype=np.int64)
    for i, (name, midi) in enumerate(zip(melody.notes, melody.midi, strict=True)):
        d = np.abs(pitch - midi)
        d[0] = np.inf  # class 0 is silence
        d = np.where(np.isnan(d), np.inf, d)
        best = int(np.argmin(d))
        if not d[best] < model.match_threshold:
            raise ConfigError(f"melody note {name!r} is not among the model's sound classes")
        out[i] = best
    return out


def play(model, melody: Melody, touch: Touch, *, rng: np.random.Generator) -> Iterator[PlayStep]:
    """Play ``melody`` in a loop forever (Algorithm 1), yielding a :class:`PlayStep` per touch.

    ``touch(actions (1, 2)) -> (landed (1, 2), perceived (1, D))`` is the only contact with the
    world; ``rng`` draws the actions.
    """
    classes = note_classes(model, melody)
    sounds = np.asarray(model.class_features_, float)[classes]  # (N, D) expected sounds
    n = len(melody)
    target = 0
    step = 0
    while True:
        cls = int(classes[target])
        action = np.asarray(model.sample_actions(cls, 1, rng), float).reshape(2)
        landed, heard = touch(action[None, :])
        landed = np.asarray(landed, float).reshape(2)
        heard = np.asarray(heard, float).reshape(-1)
        m = int(match(heard[None, :], sounds, model.match_threshold)[0])  # Eq. 2
        ok = m >= 0 and classes[m] == cls
        yield PlayStep(step=step, target=target, cls=cls, action=action, landed=landed,
                       perceived=heard, heard=m, result=MATCH if ok else NO_MATCH)
        target = (target + 1) % n if ok else 0
        step += 1


def expected_failure_rate(model, keyboard, melody: Melody, family: str, params: np.ndarray | None,
                          *, rng: np.random.Generator, n_samples: int = 400) -> np.ndarray:
    """Long-run NO_MATCH rate of Algorithm 1 with the keyboard at each pose (evaluation side).

    Each note's failure probability ``f_i`` is estimated from ``n_samples`` model draws (common to
    all poses, ideal reaching); the player's Markov chain over notes (success ``i -> i + 1 mod N``,
    failure ``i -> 0``) has stationary distribution ``pi``: the rate is ``sum_i pi_i f_i``.

    Parameters
    ----------
    keyboard : Keyboard
        The true instrument (its geometry: for benchmarks and evaluation only).
    params : (H, P) ndarray or None
        Poses in ``family``; None for the reference pose only.

    Returns
    -------
    (H,) ndarray (``(1,)`` for ``params=None``)
    """

    classes = note_classes(model, melody)
    n = len(melody)
    if params is None:
        params = np.zeros((1, len(transforms.check_family(family))))
    params = np.atleast_2d(np.asarray(params, float))
    pts = np.concatenate([np.asarray(model.sample_actions(int(c), n_samples, rng), float)
                          for c in classes])  # (n * n_samples, 2)
    ref = transforms.inverse_many(family, params, pts, keyboard.centre)  # (H, n * n_samples, 2)
    keys = keyboard.key_at(ref.reshape(-1, 2)).reshape(len(params), n, n_samples)
    want = np.asarray(melody.keys)[None, :, None]
    f = (keys != want).mean(axis=2)  # (H, N) failure probability of each note
    # stationary distribution of the note chain, solved for every pose at once
    h = len(params)
    p = np.zeros((h, n, n))
    idx = np.arange(n)
    p[:, idx, (idx + 1) % n] += 1.0 - f
    p[:, idx, 0] += f
    a = np.transpose(p, (0, 2, 1)) - np.eye(n)[None]
    a[:, -1, :] = 1.0
    b = np.zeros((h, n, 1))
    b[:, -1, 0] = 1.0
    pi = np.linalg.solve(a, b)[..., 0]
    return (pi * f).sum(axis=1)


def replay(model, melody: Melody, touch: Touch, *, rng: np.random.Generator, n_notes: int = 200,
           correction: np.ndarray | None = None, family: str = "translation",
           centre: np.ndarray | None = None, chunk: int = 32,
           sampler: Callable[[int, int, np.random.Generator], np.ndarray] | None = None
           ) -> np.ndarray:
    """Play ``n_notes`` touches of Algorithm 1 and return their history (vectorised).

    The rules of :func:`play`, with the touches batched: ``chunk`` actions per sound class are
    drawn and touched at once and consumed in order. The draws are i.i.d., so this is Algorithm 1
    exactly, except that in ``dynamics`` mode a class's batch is reached in a row.

    Parameters
    ----------
    correction : (P,) ndarray, optional
        The robot's estimate of the displacement (in ``family``, about ``centre``, default the
        working area's centre): every sampled action ``a`` is sent as ``T_correction(a)``.
    sampler : callable, optional
        ``sampler(cls, n, rng) -> (n, 2)`` draws from p(action | sound) (default
        ``model.sample_actions``).

    Returns
    -------
    (n_notes,) int ndarray
        :data:`MATCH` (0) or :data:`NO_MATCH` (1) per touch.
    """
    if n_notes < 1:
        raise ConfigError(f"n_notes must be >= 1, got {n_notes}")
    classes = note_classes(model, melody)
    if centre is None:
        x0, y0, x1, y1 = model.area
        centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    send = None if correction is None else \
        _Corrected(family, np.asarray(correction, float), centre)
    batches = _Batches(model, classes, touch, model.sample_actions if sampler is None else sampler,
                       rng, chunk, send)
    history = np.empty(n_notes, dtype=np.int64)
    n = len(melody)
    target = 0
    for step in range(n_notes):
        ok = batches.next(int(classes[target]))
        history[step] = MATCH if ok else NO_MATCH
        target = (target + 1) % n if ok else 0
    return history


@dataclass(frozen=True)
class _Corrected:
    """Actions sent as ``T_correction(a)`` (the robot's estimate of the displacement)."""

    family: str
    correction: np.ndarray
    centre: np.ndarray

    def __call__(self, actions: np.ndarray) -> np.ndarray:
        return transforms.apply(self.family, self.correction, actions, self.centre)


class _Batches:
    """The outcomes of touches aimed at each sound class, ``chunk`` touched at once per class and
    handed out in order (a class's next chunk is drawn when its outcomes run out)."""

    def __init__(self, model, classes: np.ndarray, touch: Touch, draw, rng: np.random.Generator,
                 chunk: int, send: Callable[[np.ndarray], np.ndarray] | None) -> None:
        self.model, self.classes, self.touch, self.draw = model, classes, touch, draw
        self.rng, self.chunk, self.send = rng, chunk, send
        self.sounds = np.asarray(model.class_features_, float)[classes]
        self.queues: dict[int, list] = {}  # class -> [ok (k,) bool, next index]

    def _touch(self, cls: int) -> np.ndarray:
        a = np.asarray(self.draw(cls, self.chunk, self.rng), float).reshape(-1, 2)
        if self.send is not None:
            a = self.send(a)
        _, heard = self.touch(a)
        m = match(np.asarray(heard, float).reshape(len(a), -1), self.sounds,
                  self.model.match_threshold)
        return (m >= 0) & (self.classes[np.maximum(m, 0)] == cls)

    def next(self, cls: int) -> bool:
        """Whether the next touch aimed at ``cls`` played it (MATCH)."""
        q = self.queues.get(cls)
        if q is None or q[1] >= len(q[0]):
            q = self.queues[cls] = [self._touch(cls), 0]
        q[1] += 1
        return bool(q[0][q[1] - 1])
