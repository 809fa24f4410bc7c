"""The closed loop as the robot lives it: play, notice the failure, adapt, resume (paper Sect. III).

The robot plays its melody (:func:`kbcli.core.playing.play.play`), feeding every MATCH / NO_MATCH
to an online failure detector (Sect. III-C). When it fires, the robot adapts (Sect. III-D/E,
:class:`kbcli.core.adaptation.adapter.Adapter`) until the stopping rule holds or a step budget runs
out, and resumes with *corrected* actions: an action ``a`` drawn from its reference-pose model is
sent as ``T_theta(a)`` (Eq. 3). The detector restarts its warm-up, and a later adaptation starts
again from the reference model. The robot's side only calls ``touch``.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.loop import adapt
from kbcli.core.detection.detectors import Detector, DetectorConfig
from kbcli.core.instrument import transforms
from kbcli.core.instrument.melody import Melody
from kbcli.core.playing.play import play
from kbcli.errors import ConfigError

PLAY = 0
ADAPT = 1

#: ``touch(actions (n, 2)) -> (landed (n, 2), perceived (n, D))``
Touch = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def adaptation_blocks(phase: np.ndarray) -> list[tuple[int, int]]:
    """Every adaptation of a session: ``(first, last)`` touch of each run of consecutive
    :data:`ADAPT` touches, in order (the detector fired on the play touch ``first - 1``).

    Parameters
    ----------
    phase : (T,) int ndarray
        :data:`PLAY` or :data:`ADAPT` per touch.
    """
    t = np.flatnonzero(np.asarray(phase) == ADAPT)
    if not len(t):
        return []
    cut = np.flatnonzero(np.diff(t) > 1) + 1
    return [(int(b[0]), int(b[-1])) for b in np.split(t, cut)]


@dataclass(frozen=True)
class LoopStep:
    """One touch of the closed loop.

    Attributes
    ----------
    t : int
        Touch number, from 0 (play and adaptation touches alike).
    phase : int
        :data:`PLAY` or :data:`ADAPT`.
    action, landed : (2,) ndarray
        Where the robot sent the finger, and where it landed.
    perceived : (D,) ndarray
        What it heard (NaN for silence).
    result : int
        Play: 0 MATCH / 1 NO_MATCH; adaptation: -1.
    score : float
        The detector's score after this result (play), NaN during adaptation.
    fired : bool
        Whether the detector fired on this result.
    correction : (P,) ndarray
        The transform the robot applies to its actions after this step.
    estimate : (P,) ndarray or None
        During adaptation: the adapter's current estimate (its belief of where the keyboard is).
    marginal : (dx (n,), dy (m,), log p (m, n) float32) or None
        During adaptation: the log of the adapter's posterior over the translation after this
        touch (the angle summed out), on the grid axes ``dx``, ``dy``.
    """

    t: int
    phase: int
    action: np.ndarray
    landed: np.ndarray
    perceived: np.ndarray
    result: int
    score: float
    fired: bool
    correction: np.ndarray
    estimate: np.ndarray | None = None
    marginal: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


def closed_loop(model, melody: Melody, touch: Touch, *, play_steps: int, detector: DetectorConfig,
                adapter: AdapterConfig, max_adapt_steps: int, rng: np.random.Generator, table=None
               ) -> Iterator[LoopStep]:
    """Run the closed loop until ``play_steps`` play touches are done.

    Parameters
    ----------
    model : SoundModel
        The robot's model of the instrument at its reference pose.
    touch : callable
        The only contact with the world.
    adapter : AdapterConfig
        How to adapt (family, strategy, posterior, stopping rule).
    max_adapt_steps : int
        At most this many touches per adaptation.
    table : LikelihoodTable, optional
        A prebuilt model table for the adapter (see :func:`kbcli.core.adaptation.setup.build_table`).

    Yields
    ------
    LoopStep
    """
    if play_steps < 1:
        raise ConfigError(f"steps must be >= 1, got {play_steps}")
    if max_adapt_steps < 1:
        raise ConfigError(f"max_adapt_steps must be >= 1, got {max_adapt_steps}")
    x0, y0, x1, y1 = model.area
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    correction = np.zeros(len(transforms.check_family(adapter.family)))
    det = Detector(detector)
    t = played = 0
    while played < play_steps:
        fired, n = yield from _play_phase(model, melody, touch, det, adapter.family, correction,
                                          centre, rng, t, play_steps - played)
        t, played = t + n, played + n
        if not fired:
            break
        ad = Adapter(model, adapter, rng=rng, centre=centre, table=table)
        correction, n = yield from _adapt_phase(ad, touch, max_adapt_steps, correction, t)
        t += n
        det.reset()


def _play_phase(model, melody: Melody, touch: Touch, det: Detector, family: str,
                correction: np.ndarray, centre: np.ndarray, rng: np.random.Generator, t: int,
                budget: int) -> Generator[LoopStep, None, tuple[bool, int]]:
    """Play with corrected actions (``T_correction(a)``) until the detector fires or ``budget``
    touches are played; yields their steps from number ``t`` and returns (fired, touches)."""
    sent_actions: list[np.ndarray] = []

    def corrected_touch(actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sent = transforms.apply(family, correction, np.asarray(actions, float).reshape(-1, 2), centre)
        sent_actions.append(sent[0])
        return touch(sent)

    n = 0
    for step in play(model, melody, corrected_touch, rng=rng):
        fired = det.update(step.result)
        yield LoopStep(t=t + n, phase=PLAY, action=sent_actions[-1], landed=step.landed,
                       perceived=step.perceived, result=step.result, score=det.score,
                       fired=fired, correction=correction.copy())
        n += 1
        if fired or n >= budget:
            return fired, n
    return False, n


def _adapt_phase(ad: Adapter, touch: Touch, max_steps: int, correction: np.ndarray,
                 t: int) -> Generator[LoopStep, None, tuple[np.ndarray, int]]:
    """Adapt until the stopping rule holds or ``max_steps`` touches; yields their steps from
    number ``t`` and returns (the correction the adaptation settled on, touches)."""
    def single_touch(action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        landed, heard = touch(np.asarray(action, float).reshape(1, 2))
        return landed[0], heard[0]

    n = 0
    for s in adapt(ad, single_touch, max_steps, stop=True):
        if s.stop or s.t == max_steps:
            correction = np.asarray(s.estimate, float).copy()
        yield LoopStep(t=t + n, phase=ADAPT, action=s.action, landed=s.landed,
                       perceived=s.perceived, result=-1, score=float("nan"), fired=False,
                       correction=correction.copy(), estimate=s.estimate,
                       marginal=_log_marginal(ad))
        n += 1
    return correction, n

def _log_marginal(ad: Adapter) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dx, dy, log translation marginal as float32) of an adapter's posterior."""
    with np.errstate(divide="ignore"):
        logp = np.log(ad.posterior.translation_marginal()).astype(np.float32)
    return ad.grid.dx, ad.grid.dy, logp
