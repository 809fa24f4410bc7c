"""The adaptation task as a Gymnasium environment (paper Sect. III-D, III-E, IV).

An episode is one adaptation: at :meth:`~KeyboardAdaptEnv.reset` the keyboard moves by a hidden
displacement; at each :meth:`~KeyboardAdaptEnv.step` the agent touches the pad and observes what
the robot has (the sound class heard, where it felt its finger land, the step). kbcli's own
:class:`~kbcli.core.adaptation.adapter.Adapter`, fed the same touches, keeps the posterior: the
reward, ``info`` and the stopping rule read it. ``reset(seed=s)`` spawns the robot's and the
world's generators as ``kbcli adapt --seed s`` does, so its numbers repeat bit for bit.
"""

from __future__ import annotations

import functools
import json
import os
import time
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.loop import Step, step_record
from kbcli.core.adaptation.setup import build_table
from kbcli.envs.config import EnvConfig, check_move
from kbcli.envs.rewards import REWARDS
from kbcli.errors import ConfigError, KbcliError, ObservationError
from kbcli.io.artifact import read_artifact
from kbcli.io.paths import default_model_path
from kbcli.sim import World, make_reacher
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.adapt import estimate_errors
from kbcli.stages.models import load_model
from kbcli.stages.perturb import CATEGORIES, draw

#: What ``reset(options=...)`` takes.
RESET_OPTIONS = ("move",)


class ActionError(KbcliError, gymnasium.error.InvalidAction, ValueError):
    """An action the environment cannot take: not two numbers, not finite, or outside the working
    area. Nothing is touched and the episode goes on."""


class KeyboardAdaptEnv(gymnasium.Env):
    """Recover a displaced keyboard's pose by touching it (``kbcli/KeyboardAdapt-v0``).

    Parameters
    ----------
    **options
        :class:`~kbcli.envs.config.EnvConfig`'s fields, as ``gymnasium.make(ID, **options)``
        passes them.

    Attributes
    ----------
    action_space : Box (2,)
        Where to touch: the model's working area, pad px (``x0, y0`` to ``x1, y1``).
    observation_space : Dict
        ``sound``: Discrete, the heard class (-1 unknown, 0 silence, 1.. the model's sounds; -1 at
        step 0, nothing heard yet); ``felt``: Box (2,) where the robot felt its finger land, pad
        px, within the arm's reach (the working area's centre at step 0); ``step``: Discrete, the
        touches so far; with ``belief``, ``belief``: Box ``grid shape`` float32, kbcli's posterior
        probability of each displacement cell (``(dy, dx)``, or ``(angle, dy, dx)`` for rigid).
    adapter : Adapter
        kbcli's robot side of the current episode (its posterior, from the touches only).
    truth : (P,) ndarray
        The current episode's displacement: the environment's, never the agent's.

    Raises
    ------
    ArtifactError, KbcliError
        A missing or unreadable model file, or one that is not a model (one line naming it).
    ConfigError
        An invalid option (one line naming it and what is allowed).
    """

    metadata = {"render_modes": []}

    def __init__(self, **options: Any) -> None:
        self.config = EnvConfig.from_dict(options)
        self.adapt_cfg = self.config.adapt_config()
        self.robot_cfg = self.adapt_cfg.adapter_config()
        path = default_model_path() if self.config.model is None else self.config.model
        self.model_path = str(path)
        #: the model, its keyboard and its raster (shared by every episode, and by every
        #: environment of this process on the same model file and robot options)
        self.model, self.keyboard, self.table = _setup(self.model_path, self.robot_cfg)
        first = Adapter(self.model, self.robot_cfg, rng=np.random.default_rng(0),
                        table=self.table).prepare()  # the raster's blurred maps, built once
        self.action_space = spaces.Box(np.array(first.area[:2]), np.array(first.area[2:]),
                                       dtype=np.float64)
        self.observation_space = self._observation_space(first.grid.shape)
        self.adapter: Adapter | None = None
        self.truth: np.ndarray | None = None
        self._world: World | None = None
        self._world_rng: np.random.Generator | None = None
        self._entropy = 0.0
        self._done = False

    def _observation_space(self, grid_shape: tuple[int, ...]) -> spaces.Dict:
        sim = self.adapt_cfg.sim_config()
        reach = float(sum(sim.link_lengths))
        base = np.asarray(sim.base, float)
        parts = {"sound": spaces.Discrete(int(self.model.n_classes) + 1, start=-1),
                 "felt": spaces.Box(base - reach, base + reach, dtype=np.float64),
                 "step": spaces.Discrete(self.config.max_steps + 1)}
        if self.config.belief:
            parts["belief"] = spaces.Box(0.0, 1.0, shape=grid_shape, dtype=np.float32)
        return spaces.Dict(parts)

    # -- the episode -------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Move the keyboard (hidden) and start a new adaptation.

        Parameters
        ----------
        seed : int, optional
            Seeds ``np_random`` (None: go on from it).
        options : dict, optional
            ``{"move": (dx, dy)}`` (rigid: ``(angle, dx, dy)``): this episode's displacement.
        """
        super().reset(seed=seed)
        move = self._reset_move(options)
        robot_rng, world_rng, draw_rng = self.np_random.spawn(3)
        truth = move if move is not None else self._draw(draw_rng)
        self.truth = np.asarray(truth, float)
        family = self.config.family
        self.adapter = Adapter(self.model, self.robot_cfg, rng=robot_rng,
                               table=self.table).prepare()
        self._world = World(self.keyboard, make_reacher(self.adapt_cfg.sim_config()), self.truth,
                            family)
        self._world_rng = world_rng
        self._entropy = self.adapter.entropy()
        self._done = False
        a = self.adapter
        centre = np.mean(np.reshape(a.area, (2, 2)), axis=0)
        return self._obs(-1, centre, 0), self._info(a.estimate(), a.entropy(),
                                                     a.posterior.ml_prob(),
                                                     a.mass_near_estimate(), a.should_stop())

    def _reset_move(self, options: dict[str, Any] | None) -> tuple[float, ...] | None:
        opts = {} if options is None else options
        if not isinstance(opts, dict):
            raise ConfigError(f"reset options must be a dict, got {opts!r}")
        if unknown := [k for k in opts if k not in RESET_OPTIONS]:
            raise ConfigError(f"unknown reset option {unknown[0]!r}; valid: "
                              f"{', '.join(RESET_OPTIONS)}")
        if opts.get("move") is not None:
            return check_move(opts["move"], self.config.family, "reset option move")
        return self.config.move

    def _draw(self, rng: np.random.Generator) -> np.ndarray:
        """A displacement of the config's category (or of a category drawn uniformly first)."""
        cat = self.config.category
        if cat is None:
            cat = list(CATEGORIES)[int(rng.integers(len(CATEGORIES)))]
        return draw(cat, self.config.family, 1, rng=rng,
                    max_angle=self.robot_cfg.max_angle)[0]

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """Touch at ``action`` (pad px); kbcli's posterior takes in what the robot heard and felt.

        Raises
        ------
        ActionError
            An action that is not two finite numbers inside the working area (nothing touched).
        gymnasium.error.ResetNeeded
            Before :meth:`reset`, or after the episode ended.
        """
        if self.adapter is None or self._done:
            raise gymnasium.error.ResetNeeded(
                "the episode has ended: call reset() before step()" if self._done
                else "call reset() before step()")
        a = self._action(action)
        t0 = time.perf_counter()
        felt, heard = self._world.touch(a[None, :], self._world_rng)
        felt, heard = np.asarray(felt[0], float), np.asarray(heard[0], float)
        landed = self.adapt_cfg.feedback == "landed"
        cls = self.adapter.observe(a, heard, felt_position=felt if landed else None)
        st = step_record(self.adapter, self.adapter.touches, a, felt, heard, cls, t0=t0)
        return self._outcome(st)

    def _outcome(self, st: Step) -> tuple[dict, float, bool, bool, dict]:
        err, angle_err = estimate_errors(st.estimate, self.truth, self.robot_cfg.family,
                                         self.config.family)
        reward = float(REWARDS.get(self.config.reward)(self._entropy, st.entropy, err))
        self._entropy = st.entropy
        terminated = bool(self.config.stop and st.stop)
        truncated = not terminated and st.t >= self.config.max_steps
        self._done = terminated or truncated
        info = self._info(st.estimate, st.entropy, st.ml_prob, st.mass, st.stop, (err, angle_err))
        return self._obs(st.cls, st.landed, st.t), reward, terminated, truncated, info

    def _action(self, action: Any) -> np.ndarray:
        """``action`` as a (2,) float array inside the working area; :class:`ActionError`."""
        a = np.asarray(action)
        if a.shape != (2,):
            raise ActionError(f"action must have shape (2,) (x, y in pad px), got shape {a.shape}")
        if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise ActionError(f"action must be two numbers (x, y in pad px), got {a.tolist()!r}")
        try:
            return self.adapter.check_action(a.astype(float))
        except ObservationError as exc:
            raise ActionError(str(exc)) from None

    # -- what the agent sees -----------------------------------------------------------------------
    def _obs(self, cls: int, felt: np.ndarray, t: int) -> dict[str, Any]:
        obs = {"sound": int(cls), "felt": np.array(felt, dtype=np.float64), "step": int(t)}
        if self.config.belief:
            obs["belief"] = self.adapter.posterior.probs.astype(np.float32)
        return obs

    def _info(self, estimate: np.ndarray, entropy: float, ml_prob: float, mass: float,
              stop: bool, errors: tuple[float, float] | None = None) -> dict[str, Any]:
        """The robot's estimate, its error against the truth (px; and deg), the posterior's entropy
        (nats), the probability of its most probable cell, the mass near the estimate, and whether
        the stopping rule holds."""
        if errors is None:
            errors = estimate_errors(estimate, self.truth, self.robot_cfg.family,
                                     self.config.family)
        return {"estimate": np.array(estimate, float), "error": float(errors[0]),
                "angle_error": float(errors[1]), "entropy": float(entropy),
                "ml_prob": float(ml_prob), "mass": float(mass), "stop": bool(stop)}


def _setup(path: str, robot_cfg) -> tuple:
    """The model of the artifact at ``path``, its keyboard and its raster for ``robot_cfg``: read
    and built once per process for the same file (size and time unchanged) and options (the raster
    takes seconds; eight environments of a vector share it)."""
    try:
        st = os.stat(path)
        key = (path, os.path.realpath(path), st.st_size, st.st_mtime_ns)
    except OSError:
        key = (path, None, None, None)  # read_artifact says what is wrong with it
    return _setup_cached(key, json.dumps(robot_cfg.to_dict(), sort_keys=True))


@functools.lru_cache(maxsize=4)
def _setup_cached(key: tuple, robot_json: str) -> tuple:
    art = read_artifact(key[0], "model")
    model = load_model(art)
    robot_cfg = AdapterConfig.from_dict(json.loads(robot_json))
    return model, keyboard_stage.load(art), build_table(model, robot_cfg)


__all__ = ["KeyboardAdaptEnv", "ActionError", "RESET_OPTIONS"]
