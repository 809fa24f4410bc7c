"""Agents of the environment: kbcli's own strategies (:class:`StrategyAgent`), and any agent
named ``module:callable`` or ``file.py:callable`` (:func:`load_agent`).

An agent is a callable ``agent(obs) -> action`` (or has ``act(obs)``), optionally with
``reset(seed)``, which ``kbcli bench gym`` calls at each episode's start. ``load_agent`` builds one
from a factory, ``factory(env) -> agent`` (``examples/ppo_agent.py`` loads a policy there).
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.envs.env import KeyboardAdaptEnv
from kbcli.errors import ConfigError

Agent = Callable[[dict], np.ndarray]


class StrategyAgent:
    """One of kbcli's strategies (``infogain``, ``active``, ``random``, ...) as an agent.

    It plans as ``Adapter.suggest`` does, on the environment's ``adapter`` (built from this
    agent's own touches, never the truth) with the episode's robot generator: run with the same
    seed, its touches, estimates and errors are ``kbcli adapt``'s, bit for bit. ``env`` is one
    kbcli environment (wrapped or not), ``strategy`` a name in
    :data:`kbcli.core.adaptation.strategies.STRATEGIES`.

    Examples
    --------
    ::

        env = gymnasium.make("kbcli/KeyboardAdapt-v0", move=(12, -7))
        agent = StrategyAgent("infogain", env)
        obs, info = env.reset(seed=0)
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(agent(obs))
            done = terminated or truncated
    """

    def __init__(self, strategy: str, env: gymnasium.Env) -> None:
        self._fn = STRATEGIES.get(strategy)
        base = getattr(env, "unwrapped", env)
        if not isinstance(base, KeyboardAdaptEnv):
            raise ConfigError(f"StrategyAgent acts in a kbcli environment "
                              f"(gymnasium.make('kbcli/KeyboardAdapt-v0')), got {env!r}")
        self.strategy = strategy
        self.env = base
        self._cfg = None  # (the environment's adapter config, it with the agent's strategy)

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: its generator is the episode's robot generator, which
        ``env.reset(seed=...)`` seeds."""

    def __call__(self, obs: dict) -> np.ndarray:
        """(2,) the strategy's next touch (pad px) on the current posterior."""
        adapter = self.env.adapter
        if adapter is None:
            raise gymnasium.error.ResetNeeded("call env.reset() before asking the agent")
        if int(obs["step"]) != adapter.touches:
            raise ConfigError(f"StrategyAgent acts on its environment's current posterior: the "
                              f"observation is of step {int(obs['step'])}, the environment is at "
                              f"step {adapter.touches}")
        ctx = adapter.context()
        if ctx.cfg.strategy.name != self.strategy:  # the agent's strategy, with its own options
            if self._cfg is None or self._cfg[0] is not adapter.cfg:
                self._cfg = (adapter.cfg, adapter.cfg.replace(strategy=self.strategy))
            ctx = dataclasses.replace(ctx, cfg=self._cfg[1])
        return np.asarray(self._fn(ctx, adapter.rng), float)

    act = __call__

    def __repr__(self) -> str:
        return f"StrategyAgent({self.strategy!r})"


def load_agent(spec: str, env: gymnasium.Env) -> Agent:
    """The agent ``spec`` names, for ``env``: a strategy's name (a :class:`StrategyAgent`), or
    ``module:factory`` / ``path/file.py:factory``, where ``factory(env)`` returns the agent.

    Modules are imported from the current folder too (as ``python -m`` would find them).

    Raises
    ------
    ConfigError
        An unknown name, a module or file that cannot be imported, a missing factory, a factory
        that fails (its exception's message in the line) or returns no callable agent.
    """
    if spec in STRATEGIES:
        return StrategyAgent(spec, env)
    where, _, name = spec.rpartition(":")
    if not where or not name:
        raise ConfigError(f"unknown agent {spec!r}: give a kbcli strategy "
                          f"({', '.join(STRATEGIES.names())}) or module:factory "
                          f"(or file.py:factory)")
    factory = getattr(_module(where, spec), name, None)
    if not callable(factory):
        raise ConfigError(f"agent {spec}: {where} has no callable {name!r}")
    try:
        agent = factory(env)
    except Exception as exc:  # the user's code, at the boundary: one line saying what failed
        raise ConfigError(f"agent {spec}: {name}(env) failed: {type(exc).__name__}: "
                          f"{exc}") from exc
    act = agent if callable(agent) else getattr(agent, "act", None)
    if not callable(act):
        raise ConfigError(f"agent {spec}: {name}(env) returned {type(agent).__name__}, not an "
                          f"agent (a callable obs -> action, or an object with act(obs))")
    return agent if callable(agent) else _WithReset(act, agent)


def _module(where: str, spec: str) -> Any:
    """The module of ``module`` or ``file.py`` (imported from the current folder too)."""
    if where.endswith(".py"):
        path = Path(where)
        if not path.is_file():
            raise ConfigError(f"agent {spec}: {where}: no such file")
        mod_spec = importlib.util.spec_from_file_location(f"kbcli_agent_{path.stem}", path)
        module = importlib.util.module_from_spec(mod_spec)
        try:
            mod_spec.loader.exec_module(module)
        except ImportError as exc:  # what the agent's file needs is not installed
            raise ConfigError(f"agent {spec}: {exc}") from None
        return module
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        return importlib.import_module(where)
    except ImportError as exc:
        raise ConfigError(f"agent {spec}: {exc}") from None


class _WithReset:
    """An agent object with ``act(obs)``, made callable (its ``reset`` kept)."""

    def __init__(self, act: Agent, agent: Any) -> None:
        self._act, self._agent = act, agent

    def __call__(self, obs: dict) -> np.ndarray:
        return self._act(obs)

    def reset(self, seed: int | None = None) -> None:
        if callable(reset := getattr(self._agent, "reset", None)):
            reset(seed=seed)


__all__ = ["Agent", "StrategyAgent", "load_agent"]
