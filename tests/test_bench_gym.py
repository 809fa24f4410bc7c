"""``kbcli bench gym`` (issue 43): the built-in agents reproduce ``kbcli bench adapt``'s medians,
any agent enters as ``module:factory`` or ``file.py:factory``, and a bad agent is one line."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers import one_line_error

from kbcli.bench import adapt as adapt_bench
from kbcli.bench import gym as bench
from kbcli.cli import app
from kbcli.envs import StrategyAgent, load_agent
from kbcli.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
MODEL = str(ROOT / "data" / "golden" / "model.h5")


def test_builtin_agents_reproduce_bench_adapt_exactly():
    # 2 experiments (the fewest a bench takes): every cell's errors and summary still compared
    cfg = bench.GymBenchConfig(experiments=2, max_steps=6, categories=("small",), seed=1)
    env = bench.make_env(cfg, MODEL)
    agents = {a: load_agent(a, env) for a in cfg.agents}
    cells = bench.plan(cfg, env)
    list(bench.run_cells(cells, env, agents))
    gym_rows = bench.summarize(cells)

    base = env.unwrapped
    acfg = adapt_bench.BenchConfig(experiments=2, max_steps=6, categories=("small",), seed=1,
                                   sections=("learned",))
    ref = [c for c in adapt_bench.plan(acfg, base.model, base.keyboard) if "/" not in c.label]
    list(adapt_bench.run_cells(ref))
    ref_rows = adapt_bench.summarize(ref)
    assert [r["label"] for r in gym_rows] == [r["label"] for r in ref_rows] == list(bench.BUILTIN)
    for g, r in zip(gym_rows, ref_rows, strict=True):
        assert np.array_equal(g["median"], r["median"], equal_nan=True), g["label"]
        for key in ("never", "p", "final_rmse", "rmse"):
            assert g[key] == r[key], (g["label"], key)
    for g, r in zip(cells, ref, strict=True):
        assert np.array_equal(np.asarray(g.errors), np.asarray(r.errors))


def test_an_agent_from_a_module_or_a_file(tmp_path, monkeypatch):
    (tmp_path / "my_agents.py").write_text(textwrap.dedent("""
        import numpy as np

        class Corner:
            def __init__(self, env):
                self.low = env.action_space.low
                self.seeds = []

            def act(self, obs):
                return self.low + obs["step"]

            def reset(self, seed=None):
                self.seeds.append(seed)

        def corner(env):
            return Corner(env)

        def centre(env):
            return lambda obs: (env.action_space.low + env.action_space.high) / 2

        def nothing(env):
            return 3

        def broken(env):
            raise FileNotFoundError("policy.zip: no trained policy")
        """))
    monkeypatch.chdir(tmp_path)
    cfg = bench.GymBenchConfig(experiments=2, max_steps=2, categories=("small",),
                               agents=("my_agents:corner", "my_agents.py:centre"))
    env = bench.make_env(cfg, MODEL, adapt={"resolution": 1.0, "prior_halfwidth": 25.0})
    corner, centre = (load_agent(a, env) for a in cfg.agents)
    obs, _ = env.reset(seed=0)
    assert np.array_equal(centre(obs), [400.0, 350.0])
    assert np.array_equal(corner(obs), env.action_space.low)
    cells = bench.plan(cfg, env)
    list(bench.run_cells(cells, env, dict(zip(cfg.agents, (corner, centre), strict=True))))
    seeds = corner._agent.seeds
    assert len(seeds) == 2 and seeds[0] != seeds[1]  # one per run, from the run's seed
    assert seeds[0] == bench.agent_seed(cells[0].seeds[0])
    assert [c.label for c in cells] == ["my_agents:corner", "my_agents.py:centre"]
    for spec, fragment in (("my_agents:missing", "has no callable 'missing'"),
                           ("my_agents:nothing", "returned int, not an agent"),
                           ("my_agents:broken", "broken(env) failed: FileNotFoundError: "
                                                "policy.zip: no trained policy"),
                           ("no_such_module:agent", "No module named 'no_such_module'"),
                           ("gone.py:agent", "gone.py: no such file"),
                           ("infogainn", "unknown agent 'infogainn'")):
        with pytest.raises(ConfigError, match="agent") as exc:
            load_agent(spec, env)
        assert fragment in str(exc.value)
    assert isinstance(load_agent("active", env), StrategyAgent)


def test_bench_gym_command_prints_the_tables(runner, monkeypatch):
    monkeypatch.chdir(ROOT)
    r = runner.invoke(app, ["bench", "gym", "--agent", "random", "--agent",
                            "examples/random_agent.py:agent", "--model", MODEL,
                            "--experiments", "2", "--max-steps", "3", "--category", "small",
                            "--speed-episodes", "1"])
    assert r.exit_code == 0, r.output
    assert "random_agent.py:agent" in r.output and "kbcli/KeyboardAdapt-v0" in r.output
    assert "the same touches and estimates both ways: yes" in r.output
    one_line_error(runner.invoke(app, ["bench", "gym", "--agent", "nobody", "--model", MODEL,
                                       "--experiments", "2"]), "unknown agent 'nobody'")
    one_line_error(runner.invoke(app, ["bench", "gym", "--model", "/nowhere/m.h5"]),
                   "/nowhere/m.h5")
