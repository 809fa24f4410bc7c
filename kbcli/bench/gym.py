"""Benchmark of agents through the Gymnasium environment: kbcli's strategies and any agent, side by
side on the same task, seeds and scorer.

Every agent (:func:`kbcli.envs.load_agent`) runs ``experiments`` episodes per displacement category
through ``kbcli/KeyboardAdapt-v0`` (or the dynamics one), ``max_steps`` touches each, with
``belief=True``, on ``kbcli bench adapt --section learned``'s displacements, seeds and table
(``learned-rigid`` for the rigid family): in the ideal environment the built-in agents reproduce its
medians exactly. :func:`step_cost` times one environment step against one ask/tell step.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Annotated, ClassVar

import gymnasium
import numpy as np
from pydantic import AfterValidator, Field, Strict

from kbcli.bench import adapt as adapt_bench
from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.loop import adapt
from kbcli.core.config import Config, Count, Name, NonNegativeInt, each, member_of
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.envs import ENVS, Agent, StrategyAgent
from kbcli.sim import World, make_reacher
from kbcli.stages.perturb import CATEGORIES, draw

#: The built-in agents, in print order (``random`` first: the p-values are against it).
BUILTIN = adapt_bench.STRATEGY_ORDER


class GymBenchConfig(Config):
    """Benchmark settings (see the module docstring)."""

    what: ClassVar[str] = "bench gym"

    experiments: Annotated[int, Strict(), Field(ge=2)] = 50
    max_steps: Count = 40
    seed: NonNegativeInt = 0
    agents: Annotated[tuple[Name, ...], Field(min_length=1)] = BUILTIN
    categories: Annotated[tuple[Name, ...], AfterValidator(
        each(member_of("category", CATEGORIES)))] = tuple(CATEGORIES)
    env: Annotated[Name, AfterValidator(member_of("environment", ENVS))] = \
        "kbcli/KeyboardAdapt-v0"


def make_env(cfg: GymBenchConfig, model: str | None = None, **options) -> gymnasium.Env:
    """The benchmark's environment: ``cfg.env`` on ``model``, ``max_steps`` touches, no stop, the
    belief observed."""
    return gymnasium.make(cfg.env, model=model, max_steps=cfg.max_steps, stop=False, belief=True,
                          **options)


def plan(cfg: GymBenchConfig, env: gymnasium.Env) -> list[adapt_bench.Cell]:
    """One batch per agent and category, with ``kbcli bench adapt``'s displacements and seeds
    (``Cell.strategy``: the agent as given, ``Cell.label``: its name in the table)."""
    base = env.unwrapped
    rigid = FAMILIES.get(base.config.family).rotates
    bcfg = adapt_bench.BenchConfig(
        experiments=cfg.experiments, max_steps=cfg.max_steps, seed=cfg.seed,
        sections=("learned-rigid" if rigid else "learned",), categories=cfg.categories,
        strategies=("random",))
    templates = {c.category: c for c in adapt_bench.plan(bcfg, base.model, base.keyboard)}
    return [adapt_bench.Cell("gym", label(agent), agent, cat, base.adapt_cfg, base.model,
                             templates[cat].truths, templates[cat].seeds, keyboard=base.keyboard)
            for agent in cfg.agents for cat in cfg.categories]


def label(agent: str) -> str:
    """An agent's name in the table: ``file.py:factory`` without its folders (a ``/`` in a label
    would make it a variant of another row, whose p-values are then against another reference)."""
    return agent.rsplit("/", 1)[-1]


def run_cells(cells: list[adapt_bench.Cell], env: gymnasium.Env,
              agents: dict[str, Agent]) -> Iterator[tuple[adapt_bench.Cell, int]]:
    """Run every episode of every batch, yielding ``(cell, i)`` after each (a progress bar)."""
    for cell in cells:
        for i, truth in enumerate(cell.truths):
            errors, angles, ms = episode(env, agents[cell.strategy], cell.seeds[i], truth)
            cell.errors.append(errors)
            cell.angle_errors.append(angles)
            cell.step_ms.append(ms)
            yield cell, i


def fresh(ss: np.random.SeedSequence) -> np.random.SeedSequence:
    """A copy of ``ss`` that has spawned nothing yet (a generator spawns from its seed sequence, so
    one shared by two runs would give the second other children)."""
    return np.random.SeedSequence(ss.entropy, spawn_key=ss.spawn_key)


def agent_seed(ss: np.random.SeedSequence) -> int:
    """The seed an agent's ``reset`` gets for the run of ``ss`` (a stream of its own)."""
    return int(np.random.SeedSequence([ss.entropy, *ss.spawn_key, 1]).generate_state(1)[0])


def episode(env: gymnasium.Env, agent: Agent, ss: np.random.SeedSequence,
            truth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One episode at ``truth`` from ``ss``: the error (px) and angle error (deg) after each
    touch, and each step's milliseconds (the agent's decision and the environment's step)."""
    env.unwrapped.np_random = np.random.default_rng(fresh(ss))
    if callable(reset := getattr(agent, "reset", None)):
        reset(seed=agent_seed(ss))
    obs, _ = env.reset(options={"move": truth})
    errors, angles, ms = [], [], []
    done = False
    while not done:
        t0 = time.perf_counter()
        obs, _, terminated, truncated, info = env.step(agent(obs))
        ms.append(1e3 * (time.perf_counter() - t0))
        errors.append(info["error"])
        angles.append(info["angle_error"])
        done = terminated or truncated
    return np.asarray(errors), np.asarray(angles), np.asarray(ms)


def summarize(cells: list[adapt_bench.Cell]) -> list[dict]:
    """``kbcli bench adapt``'s rows (:func:`~kbcli.bench.adapt.summarize`), each with the median
    final error (px) beside."""
    rows = adapt_bench.summarize(cells)
    for row, cell in zip(rows, cells, strict=True):
        row["final_median"] = float(np.median(np.asarray(cell.errors, float)[:, -1]))
    return rows


def step_cost(env: gymnasium.Env, *, strategy: str = "infogain", episodes: int = 5,
              steps: int = 20, seed: int = 0, category: str = "medium") -> dict:
    """Milliseconds of one environment step against one ask/tell step, same strategy and model.

    Episode ``i`` runs twice from the same seed and displacement, one after the other (so a busy
    machine slows both alike): through kbcli's ask/tell loop (:func:`kbcli.core.adaptation.loop.adapt`:
    ``suggest()``, the touch, ``observe()``, the estimates, entropy and stopping rule read after
    it), and through the environment (``StrategyAgent(strategy)``, then ``env.step``). Each step
    is timed whole, in wall and in this process's CPU time: ``asktell_ms``, ``env_ms``,
    ``asktell_cpu_ms``, ``env_cpu_ms`` (episodes * steps,); ``same``: whether both drives touched
    the same places and estimated the same.
    """
    base = env.unwrapped
    acfg = base.adapt_cfg.with_robot(strategy=strategy)
    steps = min(steps, base.config.max_steps)
    truths = draw(category, base.config.family, episodes, rng=np.random.default_rng(seed))
    agent = StrategyAgent(strategy, env)
    out = {k: [] for k in ("asktell_ms", "env_ms", "asktell_cpu_ms", "env_cpu_ms")}
    same = True
    for i, ss in enumerate(np.random.SeedSequence(seed).spawn(episodes)):
        a = _asktell_steps(base, acfg, ss, truths[i], steps, out)
        b = _env_steps(env, agent, ss, truths[i], steps, out)
        same = same and np.array_equal(a, b)
    return {**{k: np.asarray(v) for k, v in out.items()}, "same": same}


def _asktell_steps(base, acfg, ss, truth, steps: int, out: dict) -> np.ndarray:
    robot_rng, world_rng = np.random.default_rng(fresh(ss)).spawn(2)
    adapter = Adapter(base.model, acfg.adapter_config(), rng=robot_rng, table=base.table).prepare()
    world = World(base.keyboard, make_reacher(acfg.sim_config()), np.asarray(truth, float),
                  base.config.family)

    def touch(action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        felt, heard = world.touch(action[None, :], world_rng)
        return felt[0], heard[0]

    loop = adapt(adapter, touch, steps, use_landed=acfg.feedback == "landed")
    estimates = []
    for _ in range(steps):
        t0, c0 = time.perf_counter(), time.process_time()
        st = next(loop)
        out["asktell_ms"].append(1e3 * (time.perf_counter() - t0))
        out["asktell_cpu_ms"].append(1e3 * (time.process_time() - c0))
        estimates.append(st.estimate)
    return np.asarray(estimates)


def _env_steps(env, agent, ss, truth, steps: int, out: dict) -> np.ndarray:
    env.unwrapped.np_random = np.random.default_rng(fresh(ss))
    obs, _ = env.reset(options={"move": truth})
    estimates = []
    for _ in range(steps):
        t0, c0 = time.perf_counter(), time.process_time()
        obs, _, _, _, info = env.step(agent(obs))
        out["env_ms"].append(1e3 * (time.perf_counter() - t0))
        out["env_cpu_ms"].append(1e3 * (time.process_time() - c0))
        estimates.append(info["estimate"])
    return np.asarray(estimates)


__all__ = ["BUILTIN", "GymBenchConfig", "make_env", "plan", "label", "run_cells", "episode", "fresh", "agent_seed",
           "summarize", "step_cost"]
