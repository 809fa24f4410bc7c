"""``kbcli bench gym``: any agent against kbcli's strategies, through the Gymnasium environment."""

from __future__ import annotations

from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from kbcli.cli import options as opts
from kbcli.cli.adapt import _fmt_med, _fmt_p
from kbcli.cli.app import bench_app, check_io, command, err, interactive, out, progress
from kbcli.cli.record import load_note, show_table
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
    experiments: Annotated[int, typer.Option(
        "--experiments", help=opts.at_most("Episodes per agent and displacement category",
                                           MAX_EXPERIMENTS))] = 50,
    category: Annotated[list[str] | None, typer.Option(
        "--category", help="Displacement categories (repeat): small, medium, large.",
        show_default="all three")] = None,
    max_steps: Annotated[int, typer.Option("--max-steps", "-T", help=opts.at_most(
        "Touches per episode", MAX_ADAPT_STEPS))] = 40,
    seed: opts.seed_option("Seed of displacements and episodes.") = 0,
    speed_episodes: Annotated[int, typer.Option(
        "--speed-episodes", min=0, help=opts.at_most(
            "Episodes of 20 infogain touches timed through the environment and through the "
            "ask/tell loop (0: no timing)", MAX_SPEED_EPISODES))] = 5,
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
    for _ in progress(bench.run_cells(cells, env, agents), sum(len(c.truths) for c in cells),
                      "episodes"):
        pass
    con = out if interactive() else Console(width=max(out.width, 200), highlight=False)
    where = model or env.unwrapped.model_path
    show_table(con, _table(bench, cfg, bench.summarize(cells), f"{cfg.env} on {where}"))
    err.print("medians: touches until the error first drops below the threshold; (k): episodes "
              "that never got there within T; p: Wilcoxon signed-rank test of the touch counts "
              "against random on the paired episodes (same displacement and seed; the smallest p "
              f"{experiments} pairs can give is {2.0 ** (1 - experiments):.0e})", markup=False)
    if speed_episodes:
        _speed_table(bench, env, speed_episodes, seed, con)


def _table(bench, cfg, rows: list[dict], where: str) -> Table:
    t = Table(title=f"{where}: {cfg.experiments} episodes per row, T = {cfg.max_steps}, the "
                    "displacements and seeds of kbcli bench adapt --section learned",
              title_justify="left")
    for col in ("agent", "category", *(f"<{thr:g}px" for thr in bench.adapt_bench.THRESHOLDS),
                "final median", "final rmse", "p vs random, paired (<4/2/1/0.5)", "ms/step"):
        t.add_column(col, justify="left" if col in ("agent", "category") else "right")
    for r in rows:
        p = " ".join(_fmt_p(v) for v in r["p"]) if r["p"] is not None else ""
        t.add_row(r["label"], r["category"],
                  *(_fmt_med(m, n) for m, n in zip(r["median"], r["never"], strict=True)),
                  f"{r['final_median']:.2f}", f"{r['final_rmse']:.2f}", p, f"{r['ms']:.1f}")
    return t


def _speed_table(bench, env, episodes: int, seed: int, con: Console) -> None:
    """The cost of one environment step against one ask/tell step (the target: <= 1.2x)."""
    r = bench.step_cost(env, episodes=episodes, seed=seed)
    n = len(r["env_ms"])
    t = Table(title=f"one step, infogain on {env.unwrapped.model_path}: {episodes} episodes of "
                    f"{n // episodes} touches each way, one process", title_justify="left")
    for col in ("drive", "median ms/step", "median CPU ms/step", "vs ask/tell (wall)",
                "vs ask/tell (CPU)"):
        t.add_column(col, justify="left" if col == "drive" else "right")
    base_ms, base_cpu = np.median(r["asktell_ms"]), np.median(r["asktell_cpu_ms"])
    for name, key in (("ask/tell (suggest, touch, observe, read)", "asktell"),
                      ("environment (StrategyAgent, env.step)", "env")):
        ms, cpu = np.median(r[f"{key}_ms"]), np.median(r[f"{key}_cpu_ms"])
        t.add_row(name, f"{ms:.2f}", f"{cpu:.2f}", f"{ms / base_ms:.2f}x", f"{cpu / base_cpu:.2f}x")
    show_table(con, t)
    load = load_note()
    con.print(f"the same touches and estimates both ways: {'yes' if r['same'] else 'NO'}; "
              f"wall time on a shared machine{f' (load average {load})' if load else ''}; "
              "CPU time: this process only; target: the environment at most 1.2x")


__all__ = ["bench_gym_cmd"]
