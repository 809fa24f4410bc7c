"""The adaptation task as Gymnasium environments, so that any agent can be held against kbcli's.

Importing this package registers two environments::

    import gymnasium
    import kbcli.envs

    env = gymnasium.make("kbcli/KeyboardAdapt-v0")            # the ideal arm (paper Sect. IV-A, B)
    env = gymnasium.make("kbcli/KeyboardAdaptDynamics-v0")    # the realistic arm (Sect. IV-C)

Their options are :class:`~kbcli.envs.config.EnvConfig`'s; kbcli's strategies act in them as
:class:`StrategyAgent`; ``kbcli bench gym`` holds any agent against them (:func:`load_agent`).
"""

from __future__ import annotations

import gymnasium

from kbcli.envs.agents import Agent, StrategyAgent, load_agent
from kbcli.envs.config import EnvConfig
from kbcli.envs.env import ActionError, KeyboardAdaptEnv
from kbcli.envs.rewards import REWARDS

#: The registered environments and the options each one sets.
ENVS: dict[str, dict] = {
    "kbcli/KeyboardAdapt-v0": {"mode": "ideal", "arm": "ideal"},
    "kbcli/KeyboardAdaptDynamics-v0": {"mode": "dynamics", "arm": "realistic"},
}

for _id, _kwargs in ENVS.items():
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point="kbcli.envs.env:KeyboardAdaptEnv",
                           kwargs=dict(_kwargs))

__all__ = ["ENVS", "Agent", "StrategyAgent", "load_agent", "EnvConfig", "KeyboardAdaptEnv",
           "ActionError", "REWARDS"]
