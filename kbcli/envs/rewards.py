"""What a touch earns in the environment (``gymnasium.make(ID, reward=NAME)``): a function
registered in :data:`REWARDS`, ``fn(before, after, error) -> float``, of the entropy (nats) of
kbcli's posterior before and after the touch and the estimate's error (px) after it, against the
truth the agent never sees.
"""

from __future__ import annotations

from collections.abc import Callable

from kbcli.core.registry import Registry

RewardFn = Callable[[float, float, float], float]

#: The environment's rewards (``reward=``), read with ``REWARDS.get(name)``.
REWARDS: Registry[RewardFn] = Registry("reward")


@REWARDS.register("information")
def information(before: float, after: float, error: float) -> float:
    """The information the touch gave: nats it took off the posterior's entropy."""
    return before - after


@REWARDS.register("error")
def negative_error(before: float, after: float, error: float) -> float:
    """Minus the estimate's error after the touch, px (the truth is the environment's)."""
    return -error


__all__ = ["REWARDS", "RewardFn", "information", "negative_error"]
