"""The adaptation loop of the action space (paper Sect. III-D and III-E), one step at a time.

Each step: the strategy decides an action -> the robot touches (a callback: the World in
simulation, the arm in a closed loop) -> the sound is classified (``model.classify``; 0 silence,
-1 unknown) -> the posterior is updated -> estimates, entropy and the stopping rules are read off.
:func:`adapt` wraps the :class:`~kbcli.core.adaptation.adapter.Adapter`'s ask/tell calls into an
iterator of :class:`Step` records (the ``adapt``, ``run`` and ``evaluate`` stages).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.adapter import Adapter


@dataclass(frozen=True)
class Step:
    """One step of :func:`adapt`."""

    t: int
    action: np.ndarray
    landed: np.ndarray
    perceived: np.ndarray
    cls: int
    ml: np.ndarray
    mean: np.ndarray
    estimate: np.ndarray
    entropy: float
    ml_prob: float
    mass: float
    stop: bool
    ms: float


Touch = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def adapt(adapter: Adapter, touch: Touch, max_steps: int, *, use_landed: bool = True,
          stop: bool = False) -> Iterator[Step]:
    """Run the adaptation as an iterator of steps.

    Parameters
    ----------
    touch : callable
        ``touch(action (2,)) -> (landed (2,), perceived (D,))``.
    max_steps : int
        At most this many observations.
    use_landed : bool
        Observe at the landed position (proprioception) or at the aimed action.
    stop : bool
        End at the first step where :meth:`Adapter.should_stop` holds (else run all steps).

    Yields
    ------
    Step
        ``ms`` is the robot's time for the step: deciding plus updating (not the touch).
    """
    for t in range(1, max_steps + 1):
        t0 = time.perf_counter()
        action = adapter.suggest()
        t1 = time.perf_counter()
        landed, perceived = touch(action)
        landed = np.asarray(landed, float).reshape(2)
        perceived = np.asarray(perceived, float).reshape(-1)
        t2 = time.perf_counter()
        cls = adapter.observe(action, perceived, felt_position=landed if use_landed else None)
        st = step_record(adapter, t, action, landed, perceived, cls, t0=t2, extra_ms=1e3 * (t1 - t0))
        yield st
        if stop and st.stop:
            return


def step_record(adapter: Adapter, t: int, action: np.ndarray, landed: np.ndarray,
                perceived: np.ndarray, cls: int, *, t0: float, extra_ms: float = 0.0) -> Step:
    """The :class:`Step` record of the adapter's state after its ``t``-th observation.

    ``ms`` is the time from ``t0`` (``time.perf_counter()`` when the observation started) to the
    estimates being read, plus ``extra_ms`` (the decision's time).
    """
    post = adapter.posterior
    ml, mean = post.ml(), post.mean()
    ms = 1e3 * (time.perf_counter() - t0) + extra_ms
    return Step(t=t, action=np.asarray(action, float), landed=np.asarray(landed, float),
                perceived=np.asarray(perceived, float), cls=int(cls), ml=ml, mean=mean,
                estimate=adapter.estimate(),
                entropy=post.entropy(), ml_prob=post.ml_prob(),
                mass=adapter.mass_near_estimate(), stop=adapter.should_stop(), ms=ms)


__all__ = ["Step", "Touch", "adapt", "step_record"]
