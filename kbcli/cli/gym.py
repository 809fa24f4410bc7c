"""``kbcli bench gym``: any agent against kbcli's strategies, through the Gymnasium environment."""

from __future__ import annotations

from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from kbcli.cli import options as opts
from kbcli.cli.adapt import medians, medians_note, pvalues
from kbcli.cli.app import bench_app, check_io, command, err
from kbcli.cli.record import show_table, timing_note
from kbcli.cli.show import drain, table, wide
from kbcli.stages.config import MAX_ADAPT_STEPS, MAX_EXPERIMENTS

#: Episodes of the step-cost table at most.
MAX_SPEED_EPISODES = 1000


@command(bench_app, name="gym")
def bench_gym_cmd(
    agent: Annotated[list[str] | None, typer.Option(
        "--agent", help=f"Agents to run (repeat): a kbcli strategy ({opts.one_of('strategy')}), "
        "or module:factory or path/file.py:factory, where factory(env) returns a callable "
        "obs -> action.", show_default="random, active, infogain")] = None,
    model: opts.model_option("The robot's model artifact; its keyboard is the world's.",
                             optional=True, show_default="the embedded default model") = None,
    dynamics: Annotated[bool, typer.Option(
        "--dynamics", help="Run kbcli/KeyboardAdaptDynamics-v0 (the realistic arm) instead of "
        "kbcli/KeyboardAdapt-v0 (the ideal arm).")] = False,
    experiments: opts.count_option("--experiments", "Episodes per agent and displacement category",
                                   MAX_EXPERIMENTS) = 50,
    category: opts.Categories = None,
    max_steps: opts.count_option("--max-steps", "Touches per episode", MAX_ADAPT_STEPS, "-T") = 40,
    seed: opts.seed_option("Seed of displacements and episodes.") = 0,
    speed_episodes: opts.count_option("--speed-episodes", "Episodes of 20 infogain touches timed "
                                      "through the environment and through the ask/tell loop (0: "
                                      "no timing)", MAX_SPEED_EPISODES, min=0) = 5,
) -> None:
    """Hold any agent against kbcli's strategies through the Gymnasium environment.

    Reads MODEL (default: the embedded default model) and the agents' modules. Writes nothing.
    Prints per agent and displacement category the median touches until the error first drops
    below 4, 2, 1 and 0.5 px (in brackets: episodes that never got there within T), the median
    and RMSE of the final error, the Wilcoxon signed-rank p-value against random on the paired
    episodes, and the median milliseconds per step (the agent's decision and the environment's
    step). The displacements and seeds are those of kbcli bench adapt --section learned, so the
    built-in agents reproduce its medians. Then the cost of one environment step against one
    ask/tell step (infogain, same model, displacements and seeds).
    """
    from kbcli.bench import gym as bench
    from kbcli.envs import load_agent

    check_io({"--model": model})
    opts.check_counts(("--experiments", experiments, MAX_EXPERIMENTS),
                      ("--max-steps", max_steps, MAX_ADAPT_STEPS),
                      ("--speed-episodes", speed_episodes or None, MAX_SPEED_EPISODES))
    cfg = bench.GymBenchConfig(
        experiments=experiments, max_steps=max_steps, seed=seed,
        agents=tuple(agent) if agent else bench.BUILTIN,
        categories=tuple(category) if category else tuple(bench.CATEGORIES),
        env="kbcli/KeyboardAdaptDynamics-v0" if dynamics else "kbcli/KeyboardAdapt-v0")
    env = bench.make_env(cfg, None if model is None else str(model))
    agents = {spec: load_agent(spec, env) for spec in cfg.agents}
    cells = bench.plan(cfg, env)
    drain(bench.run_cells(cells, env, agents), sum(len(c.truths) for c in cells), "episodes")
    con = wide(200)
    where = model or env.unwrapped.model_path
    show_table(con, _table(bench, cfg, bench.summarize(cells), f"{cfg.env} on {where}"))
    err.print(medians_note(experiments, "touches", "touch", "episodes"), markup=False)
    if speed_episodes:
        _speed_table(bench, env, speed_episodes, seed, con)


def _table(bench, cfg, rows: list[dict], where: str) -> Table:
    t = table(f"{where}: {cfg.experiments} episodes per row, T = {cfg.max_steps}, the "
              "displacements and seeds of kbcli bench adapt --section learned",
              ("agent", "category", *(f"<{thr:g}px" for thr in bench.adapt_bench.THRESHOLDS),
               "final median", "final rmse", "p vs random, paired (<4/2/1/0.5)", "ms/step"), left=2)
    for r in rows:
        t.add_row(r["label"], r["category"], *medians(r), f"{r['final_median']:.2f}",
                  f"{r['final_rmse']:.2f}", pvalues(r), f"{r['ms']:.1f}")
    return t


def _speed_table(bench, env, episodes: int, seed: int, con: Console) -> None:
    """The cost of one environment step against one ask/tell step (the target: <= 1.2x)."""
    r = bench.step_cost(env, episodes=episodes, seed=seed)
    n = len(r["env_ms"])
    t = table(f"one step, infogain on {env.unwrapped.model_path}: {episodes} episodes of "
              f"{n // episodes} touches each way, one process",
              ("drive", "median ms/step", "median CPU ms/step", "vs ask/tell (wall)",
               "vs ask/tell (CPU)"))
    base_ms, base_cpu = np.median(r["asktell_ms"]), np.median(r["asktell_cpu_ms"])
    for name, key in (("ask/tell (suggest, touch, observe, read)", "asktell"),
                      ("environment (StrategyAgent, env.step)", "env")):
        ms, cpu = np.median(r[f"{key}_ms"]), np.median(r[f"{key}_cpu_ms"])
        t.add_row(name, f"{ms:.2f}", f"{cpu:.2f}", f"{ms / base_ms:.2f}x", f"{cpu / base_cpu:.2f}x")
    show_table(con, t)
    con.print(f"the same touches and estimates both ways: {'yes' if r['same'] else 'NO'}; "
              f"{timing_note()}; target: the environment at most 1.2x")


__all__ = ["bench_gym_cmd"]
