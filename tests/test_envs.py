"""The Gymnasium environments (issue 43): Gymnasium's own checks, kbcli's numbers bit for bit,
vector environments, bad input, reproducible resets, a clear error for a bad model at make time.

Most tests run a coarse grid (SMALL: 1 px cells over +-25 px) to stay quick; the numbers compared
with ``kbcli adapt`` are computed with the same options on both sides."""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import kbcli.envs as envs
from kbcli.cli import app
from kbcli.errors import ArtifactError, ConfigError
from kbcli.io.artifact import read_artifact

ROOT = Path(__file__).resolve().parent.parent
MODEL = str(ROOT / "data" / "golden" / "model.h5")
SCENE = ROOT / "data" / "golden" / "scene.h5"
IDEAL, DYNAMICS = envs.ENVS
SMALL = {"resolution": 1.0, "prior_halfwidth": 25.0}
#: check_env's advice that a Box action space be [-1, 1]: kbcli's actions are pad px on purpose
#: (the issue asks for them; gymnasium.wrappers.RescaleAction rescales them for an RL library).
NORMALISED_ADVICE = "we recommend using a symmetric and normalized space"


def small_env(env_id: str = IDEAL, **options) -> gymnasium.Env:
    options.setdefault("max_steps", 6)
    return gymnasium.make(env_id, model=MODEL, adapt={**SMALL, **options.pop("adapt", {})},
                          **options)


def run_episode(env, agent, seed=None, options=None):
    obs, info = env.reset(seed=seed, options=options)
    steps = []
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(agent(obs))
        steps.append((obs, reward, terminated, truncated, info))
        done = terminated or truncated
    return steps


def test_both_environments_are_registered_with_their_arms():
    assert {IDEAL, DYNAMICS} <= set(gymnasium.registry)
    assert gymnasium.registry[DYNAMICS].kwargs == {"mode": "dynamics", "arm": "realistic"}
    ideal, dyn = small_env(IDEAL).unwrapped, small_env(DYNAMICS).unwrapped
    assert ideal.adapt_cfg.mode == "ideal" and dyn.adapt_cfg.mode == "dynamics"
    assert dyn.adapt_cfg.arm.preset == "realistic"


@pytest.mark.parametrize("env_id", [IDEAL, DYNAMICS])
@pytest.mark.parametrize("belief", [False, True])
def test_gymnasium_check_env_passes(env_id, belief):
    env = small_env(env_id, belief=belief)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    other = [str(w.message) for w in caught if NORMALISED_ADVICE not in str(w.message)]
    assert other == []
    assert ("belief" in env.observation_space.spaces) == belief


@pytest.mark.parametrize("strategy, mode, arm", [("infogain", "ideal", "ideal"),
                                                 ("active", "ideal", "ideal"),
                                                 ("random", "ideal", "ideal"),
                                                 ("infogain", "dynamics", "realistic")])
def test_strategy_agent_gives_kbcli_adapts_numbers_bit_for_bit(strategy, mode, arm, runner,
                                                               tmp_path):
    out = tmp_path / "run.h5"
    r = runner.invoke(app, ["adapt", "--model", MODEL, "--scene", str(SCENE), "--strategy",
                            strategy, "--mode", mode, "--arm", arm, "--max-steps", "8",
                            "--resolution", "1", "--prior-halfwidth", "25", "--seed", "3",
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    run = read_artifact(out, "run").data
    move = read_artifact(SCENE, "scene").config["params"]
    env = small_env(IDEAL if mode == "ideal" else DYNAMICS, move=move, max_steps=8, stop=False)
    steps = run_episode(env, envs.StrategyAgent(strategy, env), seed=3)
    got = {"actions": [s[0]["felt"] for s in steps], "classes": [s[0]["sound"] for s in steps],
           "errors": [s[4]["error"] for s in steps], "entropy": [s[4]["entropy"] for s in steps],
           "means": [s[4]["estimate"] for s in steps], "mass": [s[4]["mass"] for s in steps],
           "stop": [s[4]["stop"] for s in steps]}
    got["landed"] = got.pop("actions")
    for key, values in got.items():
        assert np.array_equal(np.asarray(run[key]), np.asarray(values)), key
    assert len(steps) == 8 and steps[-1][3] and not any(s[2] for s in steps)


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec_runs_eight_environments(mode):
    vec = gymnasium.make_vec(IDEAL, num_envs=8, vectorization_mode=mode, model=MODEL,
                             max_steps=3, belief=True, adapt=SMALL)
    try:
        obs, info = vec.reset(seed=0)
        assert obs["belief"].shape[0] == 8 and obs["felt"].shape == (8, 2)
        vec.action_space.seed(0)
        for t in range(1, 4):
            obs, reward, terminated, truncated, info = vec.step(vec.action_space.sample())
            assert np.all(obs["step"] == t) and reward.shape == (8,)
        assert truncated.all()
        # seeds 0..7: eight different displacements, so eight different first errors
        assert len(set(np.round(info["error"], 9))) == 8
    finally:
        vec.close()


@pytest.mark.parametrize("action, fragment", [
    (np.array([300.0, 300.0, 1.0]), "shape (2,)"),
    (np.array([[300.0, 300.0]]), "shape (2,)"),
    (np.array([np.nan, 300.0]), "finite"),
    (np.array([300.0, np.inf]), "finite"),
    (np.array([10.0, 300.0]), "outside the working area"),
    (np.array(["a", "b"]), "two numbers"),
])
def test_a_bad_action_is_refused_clearly_and_the_episode_goes_on(action, fragment):
    env = small_env()
    obs, _ = env.reset(seed=0)
    with pytest.raises(envs.ActionError, match="action") as exc:
        env.step(action)
    assert fragment in str(exc.value) and "\n" not in str(exc.value)
    assert isinstance(exc.value, gymnasium.error.InvalidAction)
    assert isinstance(exc.value, ValueError)
    obs, *_ = env.step(np.array([300.0, 300.0]))
    assert obs["step"] == 1


def test_step_before_reset_or_after_the_end_asks_for_a_reset():
    env = small_env(max_steps=1).unwrapped
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(np.array([300.0, 300.0]))
    env.reset(seed=0)
    *_, truncated, _ = env.step(np.array([300.0, 300.0]))
    assert truncated
    with pytest.raises(gymnasium.error.ResetNeeded, match="episode has ended"):
        env.step(np.array([300.0, 300.0]))


def _fixed(obs):
    return np.array([250.0 + 20 * obs["step"], 320.0])


def test_a_reset_without_seed_is_reproducible_from_np_random():
    a, b = small_env(), small_env()
    first = [run_episode(e, _fixed, seed=5) for e in (a, b)]
    saved = copy.deepcopy(a.unwrapped.np_random)
    second = [run_episode(e, _fixed) for e in (a, b)]
    for x, y in (first, second):
        assert [s[4]["error"] for s in x] == [s[4]["error"] for s in y]
    assert [s[4]["error"] for s in first[0]] != [s[4]["error"] for s in second[0]]
    c = small_env()
    c.unwrapped.np_random = saved  # replay the episode a's np_random would give next
    replay = run_episode(c, _fixed)
    assert [s[4]["error"] for s in replay] == [s[4]["error"] for s in second[0]]


@pytest.mark.parametrize("model, fragment", [
    ("/nowhere/model.h5", "/nowhere/model.h5: no such file"),
    (str(SCENE), "is a scene artifact, expected model"),
    (str(ROOT / "README.md"), "README.md: not an HDF5 file"),
])
def test_a_missing_or_wrong_model_fails_at_make_in_one_line(model, fragment):
    with pytest.raises(ArtifactError) as exc:
        gymnasium.make(IDEAL, model=model)
    assert fragment in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("options, fragment", [
    ({"rewards": "error"}, "unknown env option 'rewards'"),
    ({"reward": "speed"}, "unknown reward 'speed'; valid: information, error"),
    ({"move": (1.0, 2.0, 3.0)}, "move must be 2 finite numbers (dx, dy)"),
    ({"move": (1.0, 2.0), "category": "small"}, "either category or move"),
    ({"adapt": {"strategy": "random"}}, "the agent chooses the actions"),
    ({"adapt": {"resolution": -1}}, "adapt.resolution must be greater than 0"),
    ({"max_steps": 0}, "env.max_steps must be a whole number in [1, 10000]"),
])
def test_bad_options_fail_at_make_in_one_line(options, fragment):
    with pytest.raises(ConfigError) as exc:
        gymnasium.make(IDEAL, model=MODEL, **options)
    assert fragment in str(exc.value) and "\n" not in str(exc.value)


def test_bad_reset_options_are_refused():
    env = small_env()
    with pytest.raises(ConfigError, match="unknown reset option 'moved'; valid: move"):
        env.reset(options={"moved": (1, 2)})
    with pytest.raises(ConfigError, match="2 finite numbers"):
        env.reset(options={"move": (1, np.nan)})


def test_rewards_are_the_information_gained_or_minus_the_error():
    env = small_env(reward="information", stop=False, move=(4.0, -3.0))
    _, info0 = env.reset(seed=1)
    steps = run_episode(env, _fixed, seed=1, options=None)
    gained = sum(s[1] for s in steps)
    assert gained == pytest.approx(info0["entropy"] - steps[-1][4]["entropy"], abs=1e-9)
    env = small_env(reward="error", stop=False, move=(4.0, -3.0))
    for _obs, reward, *_, info in run_episode(env, _fixed, seed=1):
        assert reward == -info["error"]
        assert info["error"] == pytest.approx(np.hypot(*(info["estimate"] - [4.0, -3.0])))


def test_the_belief_is_kbcli_posterior():
    env = small_env(belief=True, move=(4.0, -3.0))
    obs, _ = env.reset(seed=0)
    assert np.allclose(obs["belief"], obs["belief"].flat[0]) and obs["step"] == 0
    obs, *_ = env.step(np.array([300.0, 300.0]))
    post = env.unwrapped.adapter.posterior
    assert obs["belief"].dtype == np.float32 and obs["belief"].shape == post.grid.shape
    assert np.array_equal(obs["belief"], post.probs.astype(np.float32))
    assert obs["belief"].sum() == pytest.approx(1.0, abs=1e-4)


def test_terminated_at_kbcli_stopping_rule_truncated_at_max_steps():
    agent_env = small_env(max_steps=40, stop=True, move=(4.0, -3.0))
    steps = run_episode(agent_env, envs.StrategyAgent("infogain", agent_env), seed=0)
    assert steps[-1][2] and not steps[-1][3] and steps[-1][4]["stop"]
    assert not any(s[4]["stop"] for s in steps[:-1]) and len(steps) < 40
    env = small_env(max_steps=len(steps) + 2, stop=False, move=(4.0, -3.0))
    later = run_episode(env, envs.StrategyAgent("infogain", env), seed=0)
    assert not any(s[2] for s in later) and later[-1][3] and len(later) == len(steps) + 2


@pytest.mark.parametrize("category", ["small", "medium", "large"])
def test_reset_draws_a_displacement_of_the_category(category):
    from kbcli.stages.perturb import CATEGORIES

    env = small_env(category=category)
    lo, hi = CATEGORIES[category]
    for seed in range(5):
        env.reset(seed=seed)
        assert lo < np.hypot(*env.unwrapped.truth) <= hi


def test_strategy_agent_needs_its_environment_current_step():
    env = small_env()
    agent = envs.StrategyAgent("infogain", env)
    obs, _ = env.reset(seed=0)
    env.step(agent(obs))
    with pytest.raises(ConfigError, match="observation is of step 0"):
        agent(obs)
    with pytest.raises(ConfigError, match="unknown strategy 'nope'"):
        envs.StrategyAgent("nope", env)
    with pytest.raises(ConfigError, match="acts in a kbcli environment"):
        envs.StrategyAgent("infogain", gymnasium.make("CartPole-v1"))


def test_the_tutorial_random_agent_runs(monkeypatch, capsys):
    """The ten-line random agent of docs/tutorials/agent.md runs its episode to the end."""
    import re

    text = (ROOT / "docs" / "tutorials" / "agent.md").read_text()
    code = re.search(r"<!-- agent-example -->\s*```python\n(.*?)```", text, re.S).group(1)
    assert len(code.strip().splitlines()) <= 12
    monkeypatch.chdir(ROOT)
    exec(compile(code, "agent.md", "exec"), {"__name__": "tutorial"})
    assert re.search(r"^\d+ touches: estimate \[.*\], error [\d.]+ px$", capsys.readouterr().out,
                     re.M)
