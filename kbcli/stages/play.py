"""Stage ``play``: the robot plays a melody in a loop while the keyboard moves (Algorithm 1).

The simulated :class:`~kbcli.sim.World` holds the model's keyboard at its reference pose until step
``perturb_at``, then at the scene's true pose; the robot's side
(:func:`kbcli.core.playing.play.play`) only gets its ``touch``. The ``history`` artifact records per
step the action, landing, perceived features, aimed note and MATCH (0) / NO_MATCH (1), which
:mod:`kbcli.stages.detect` reads. :class:`Session` iterates over the steps; :func:`run` plays a
whole session.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from pydantic import field_validator, model_validator

from kbcli.core.config import Config, Name, NonNegativeInt, Whole, between
from kbcli.core.instrument.melody import DEFAULT_MELODY, MAX_NOTES, parse_melody
from kbcli.core.playing.play import NO_MATCH, PlayStep, play
from kbcli.errors import ConfigError
from kbcli.sim import PRESETS, SimConfig, World, make_reacher
from kbcli.sim.config import Arm, ModeName, ReachNoise
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import perturb as perturb_stage
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.models import load_model

#: Most actions a play session may take (``steps``).
MAX_PLAY_STEPS = 100_000
#: Longest melody text (characters; :func:`~kbcli.core.instrument.melody.parse_melody` also allows at most
#: :data:`~kbcli.core.instrument.melody.MAX_NOTES` notes).
MAX_MELODY_CHARS = 64 * MAX_NOTES


def check_melody_text(v: str) -> str:
    """``v`` unless it has more than :data:`~kbcli.core.instrument.melody.MAX_NOTES` notes or is longer than
    :data:`MAX_MELODY_CHARS` (a field validator; the message counts notes, the user's unit)."""
    if len(v) > MAX_MELODY_CHARS:
        n = len(v.split())
        if n > MAX_NOTES:
            raise ValueError(f"must be at most {MAX_NOTES} notes, got {n}")
        each = MAX_MELODY_CHARS // MAX_NOTES
        raise ValueError(f"must be at most {MAX_NOTES} notes of at most {each} characters each "
                         f"({MAX_MELODY_CHARS} in all), got {len(v)} characters")
    return v


class PlayConfig(Config):
    """A play session: ``steps`` actions playing ``melody`` (``"A:1 D:1 E:0.5 D:2 A:1"``); from
    ``perturb_at`` (needs a scene; default with one: ``steps // 2``) the keyboard is at the scene's
    pose. ``arm`` may be a preset name or a table; ``reach_noise`` in px."""

    what = "play"

    melody: Name = DEFAULT_MELODY
    steps: between(Whole, 1, MAX_PLAY_STEPS) = 300
    perturb_at: NonNegativeInt | None = None
    mode: ModeName = "ideal"
    reach_noise: ReachNoise = 0.0
    arm: Arm = PRESETS.get("ideal")

    _melody = field_validator("melody")(check_melody_text)

    @model_validator(mode="after")
    def _perturb_in_session(self) -> PlayConfig:
        if self.perturb_at is not None and self.perturb_at >= self.steps:
            raise ConfigError(
                f"perturb_at must be a step in [0, {self.steps - 1}], got {self.perturb_at!r}")
        return self


class Session:
    """One play session, an iterator of :class:`~kbcli.core.playing.play.PlayStep`.

    The keyboard goes where ``scene_art`` puts it at ``perturb_at`` (without a scene it stays).
    ``rng`` is split into the robot's generator and the world's, so the same seed gives the same
    actions before the perturbation whatever the scene.
    """

    def __init__(self, cfg: PlayConfig, model_art: Artifact, scene_art: Artifact | None = None, *,
                 rng: np.random.Generator, seed: int | None = None) -> None:
        self.cfg = cfg
        self.model_art = model_art
        self.scene_art = scene_art
        self.seed = seed
        kb = keyboard_stage.load(model_art)
        self.keyboard = kb
        self.melody = parse_melody(cfg.melody, kb)
        model = load_model(model_art)
        if scene_art is not None:
            if keyboard_stage.load(scene_art).config != kb.config:
                raise ConfigError("the scene moves a different keyboard than the model's")
            self.family, self.params = perturb_stage.pose(scene_art)
            self.perturb_at = cfg.steps // 2 if cfg.perturb_at is None else cfg.perturb_at
        else:
            if cfg.perturb_at is not None:
                raise ConfigError("perturb_at needs a scene (kbcli perturb) to move the keyboard to")
            self.family, self.params, self.perturb_at = "translation", None, None
        self.sim = SimConfig(mode=cfg.mode, reach_noise=cfg.reach_noise, arm=cfg.arm)
        self.world = World(keyboard=kb, reacher=make_reacher(self.sim))
        robot_rng, world_rng = rng.spawn(2)

        def touch(actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return self.world.touch(actions, world_rng)

        self._player = play(model, self.melody, touch, rng=robot_rng)
        self.steps: list[PlayStep] = []

    def __len__(self) -> int:
        return self.cfg.steps

    def __iter__(self) -> Iterator[PlayStep]:
        for i in range(len(self.steps), self.cfg.steps):
            if self.perturb_at is not None and i == self.perturb_at:
                self.world.pose = self.params  # the world moves; the robot is not told
                self.world.family = self.family
            st = next(self._player)
            self.steps.append(st)
            yield st

    def artifact(self) -> Artifact:
        """The history artifact of the steps played so far."""
        st = self.steps
        n = len(st)
        d = self.keyboard.features.shape[1]
        result = np.array([s.result for s in st], dtype=np.uint8)
        perturbed = np.zeros(n, dtype=bool)
        if self.perturb_at is not None:
            perturbed[self.perturb_at:] = True
        data = {
            "action": np.array([s.action for s in st], float).reshape(n, 2),
            "landed": np.array([s.landed for s in st], float).reshape(n, 2),
            "perceived": np.array([s.perceived for s in st], float).reshape(n, d),
            "target": np.array([s.target for s in st], dtype=np.int64),
            "cls": np.array([s.cls for s in st], dtype=np.int64),
            "heard": np.array([s.heard for s in st], dtype=np.int64),
            "result": result,
            "perturbed": perturbed,
            "melody": {
                "midi": np.array(self.melody.midi, dtype=np.int64),
                "durations": np.array(self.melody.durations, float),
                "keys": np.array(self.melody.keys, dtype=np.int64),
            },
        }
        before = result[~perturbed]
        after = result[perturbed]
        attrs = {
            "steps": n,
            "perturb_at": self.perturb_at,
            "melody": self.melody.text,
            "failure_rate_before": float(before.mean()) if len(before) else None,
            "failure_rate_after": float(after.mean()) if len(after) else None,
            "no_match": int((result == NO_MATCH).sum()),
        }
        inputs = {"model": ref(self.model_art)}
        if self.scene_art is not None:
            inputs["scene"] = ref(self.scene_art)
        return Artifact(
            kind="history",
            config={
                **self.cfg.to_dict(),
                "perturb_at": self.perturb_at,
                "keyboard": self.keyboard.config.to_dict(),
                "sim": self.sim.to_dict(),
            },
            seed=self.seed,
            data=data,
            attrs=attrs,
            inputs=inputs,
        )


def run(cfg: PlayConfig, model_art: Artifact, scene_art: Artifact | None = None, *,
        rng: np.random.Generator, seed: int | None = None) -> Artifact:
    """Play a whole session and return its history artifact."""
    session = Session(cfg, model_art, scene_art, rng=rng, seed=seed)
    for _ in session:
        pass
    return session.artifact()


def heard_audio(history: Artifact, keyboard_features: np.ndarray, *, sample_rate: int) -> np.ndarray:
    """What was heard in a history, as audio samples (see :func:`kbcli.core.instrument.audio.render`).

    Silent steps last the aimed note's duration at that note's tempo (from ``keyboard_features``,
    the reference features of the keys).
    """
    from kbcli.core.instrument.audio import render

    target = history.array("target")
    keys = history.array("melody/keys")[target]
    beats = history.array("melody/durations")[target]
    tempo = np.asarray(keyboard_features, float)[keys, 1]
    return render(history.array("perceived"), beats, tempo, sample_rate=sample_rate)
