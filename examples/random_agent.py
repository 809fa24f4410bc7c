"""A random agent in kbcli's Gymnasium environment, and its factory for ``kbcli bench gym``.

    python examples/random_agent.py                    # one episode, printed touch by touch
    kbcli bench gym --agent random --agent examples/random_agent.py:agent

``agent(env)`` is the factory ``kbcli bench gym --agent FILE:agent`` calls with the environment;
it returns a callable ``obs -> action``, here with a ``reset(seed)`` that the benchmark calls at
each episode's start (so the runs are reproducible and paired).
"""

import gymnasium
import numpy as np

import kbcli.envs  # noqa: F401  (registers kbcli/KeyboardAdapt-v0)


class RandomAgent:
    """Touches uniformly at random over the working area (the action space)."""

    def __init__(self, env):
        self.space = env.action_space

    def reset(self, seed=None):
        self.space.seed(seed)

    def __call__(self, obs):
        return self.space.sample()


def agent(env):
    return RandomAgent(env)


if __name__ == "__main__":
    env = gymnasium.make("kbcli/KeyboardAdapt-v0", move=(12.0, -7.0), max_steps=10)
    me = agent(env)
    me.reset(seed=0)
    obs, info = env.reset(seed=0)
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(me(obs))
        done = terminated or truncated
        print(f"touch {obs['step']}: heard class {obs['sound']}, estimate "
              f"{np.round(info['estimate'], 2)}, error {info['error']:.2f} px, "
              f"reward {reward:.2f} nats")
