"""A small reinforcement-learning agent on kbcli's belief: Stable-Baselines3's PPO, trained in
``kbcli/KeyboardAdapt-v0`` and entered in ``kbcli bench gym`` beside kbcli's strategies.

Needs the ``rl`` extra, which is never part of ``make test``; install a CPU build of torch first
(a plain ``pip install torch`` may fetch a CUDA build of several GB)::

    pip install torch==2.13.0          # here: a local CPU wheel (elsewhere: PyTorch's CPU index)
    pip install -e ".[rl]"             # stable-baselines3
    python examples/ppo_agent.py --timesteps 50000 -o out/ppo-agent.zip
    KBCLI_PPO=out/ppo-agent.zip kbcli bench gym --agent random --agent infogain \\
        --agent examples/ppo_agent.py:agent

What the policy sees (:func:`features`): kbcli's posterior over the displacement (``belief=True``)
summed over blocks of 9 x 9 cells (4.5 px at the default 0.5 px grid: 21 x 21 numbers), where the
robot felt its finger land (scaled to the working area), the heard class (one-hot) and the step.
It acts in the working area rescaled to [-1, 1] (``gymnasium.wrappers.RescaleAction``); the reward
is the information a touch gave (nats), an episode ends at kbcli's stopping rule or after
``--max-steps`` touches, and each reset moves the keyboard by a displacement of a category drawn
at random.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import gymnasium
import numpy as np

import kbcli.envs  # noqa: F401  (registers kbcli/KeyboardAdapt-v0)

#: Belief cells summed per block side.
POOL = 9
#: The step is scaled by this many touches (the benchmark's T).
STEP_SCALE = 40.0
#: Where ``agent(env)`` finds the trained policy (``KBCLI_PPO`` overrides it).
DEFAULT_POLICY = "out/ppo-agent.zip"


def features(obs: dict, n_classes: int, area: np.ndarray) -> np.ndarray:
    """The policy's input: pooled belief, felt position, heard class (one-hot), step."""
    belief = np.asarray(obs["belief"], np.float64)
    for axis in range(belief.ndim):
        belief = np.add.reduceat(belief, np.arange(0, belief.shape[axis], POOL), axis=axis)
    centre, half = (area[:2] + area[2:]) / 2, (area[2:] - area[:2]) / 2
    sound = np.zeros(n_classes + 1)
    sound[int(obs["sound"]) + 1] = 1.0  # -1 (unknown, or nothing heard yet) .. n_classes - 1
    felt = (np.asarray(obs["felt"], float) - centre) / half
    return np.concatenate([belief.ravel(), felt, sound,
                           [float(obs["step"]) / STEP_SCALE]]).astype(np.float32)


class Features(gymnasium.ObservationWrapper):
    """The environment as the policy sees it (:func:`features`)."""

    def __init__(self, env: gymnasium.Env) -> None:
        super().__init__(env)
        base = env.unwrapped
        self.n_classes = int(base.model.n_classes)
        self.area = np.concatenate([env.action_space.low, env.action_space.high])
        size = len(features(env.observation_space.sample(), self.n_classes, self.area))
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (size,), np.float32)

    def observation(self, obs: dict) -> np.ndarray:
        return features(obs, self.n_classes, self.area)


def training_env(max_steps: int, model: str | None) -> gymnasium.Env:
    env = gymnasium.make("kbcli/KeyboardAdapt-v0", model=model, belief=True, max_steps=max_steps,
                         reward="information")
    return gymnasium.wrappers.RescaleAction(Features(env), -1.0, 1.0)


def train(timesteps: int, output: Path, *, max_steps: int = 20, seed: int = 0,
          model: str | None = None) -> float:
    """Train PPO for ``timesteps`` touches and save it to ``output``; returns the seconds taken."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)  # a small MLP: one core is enough, and the machine is shared
    env = training_env(max_steps, model)
    env.reset(seed=seed)
    ppo = PPO("MlpPolicy", env, n_steps=1024, batch_size=128, n_epochs=5, gamma=0.9,
              learning_rate=3e-4, policy_kwargs={"net_arch": [64, 64]}, seed=seed, device="cpu",
              verbose=0)
    t0 = time.perf_counter()
    ppo.learn(total_timesteps=timesteps)
    seconds = time.perf_counter() - t0
    output.parent.mkdir(parents=True, exist_ok=True)
    ppo.save(output)
    return seconds


def agent(env: gymnasium.Env):
    """The trained policy as an agent of ``kbcli bench gym`` (``KBCLI_PPO``: its file)."""
    from stable_baselines3 import PPO

    path = os.environ.get("KBCLI_PPO", DEFAULT_POLICY)
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no trained policy (python examples/ppo_agent.py "
                                f"-o {path} trains one)")
    ppo = PPO.load(path, device="cpu")
    space, n = env.action_space, int(env.unwrapped.model.n_classes)
    area = np.concatenate([space.low, space.high])

    def act(obs: dict) -> np.ndarray:
        a, _ = ppo.predict(features(obs, n, area), deterministic=True)
        return space.low + (np.clip(a, -1.0, 1.0) + 1.0) / 2.0 * (space.high - space.low)

    return act


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--timesteps", type=int, default=50000, help="touches to train on")
    p.add_argument("--max-steps", type=int, default=20, help="touches per training episode")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", default=None, help="model artifact (default: the embedded one)")
    p.add_argument("-o", "--output", type=Path, default=Path(DEFAULT_POLICY))
    args = p.parse_args()
    seconds = train(args.timesteps, args.output, max_steps=args.max_steps, seed=args.seed,
                    model=args.model)
    print(f"wrote {args.output}: PPO, {args.timesteps} touches in {seconds:.0f} s")


if __name__ == "__main__":
    main()
