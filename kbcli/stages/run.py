"""Stage ``run``: the closed loop, play -> detect -> adapt -> resume (paper Sect. III, IV-C).

The world (:class:`~kbcli.sim.World`) moves the keyboard from its reference pose to the scene's
after ``perturb_at`` touches, without telling the robot, whose side
(:func:`kbcli.core.playing.loop.closed_loop`) only gets the world's ``touch``. The ``closed_loop``
artifact records every touch (phase, action, landing, heard features, MATCH/NO_MATCH, detector
score, correction; schema 2: ``steps/joint_angles``, ``steps/estimate`` and the posterior after
each adaptation touch, ``posterior/...``) and the success rates before the move, after it until
adapted, and after adaptation.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
from pydantic import Field, field_serializer, field_validator, model_validator

from kbcli.core.adaptation.config import learning_rate, redundancy_radius, robust_blurs
from kbcli.core.adaptation.setup import build_table
from kbcli.core.config import Config, Name, NonNegativeInt, Whole, as_table, between
from kbcli.core.detection.detectors import DetectorConfig
from kbcli.core.instrument import transforms
from kbcli.core.instrument.melody import DEFAULT_MELODY, parse_melody
from kbcli.core.playing.loop import ADAPT, PLAY, LoopStep, adaptation_blocks, closed_loop
from kbcli.errors import ConfigError
from kbcli.sim import World, make_reacher
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import perturb as perturb_stage
from kbcli.stages.adapt import AdaptConfig, check_inputs, end_angles
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.config import MAX_ADAPT_STEPS
from kbcli.stages.models import load_model
from kbcli.stages.play import check_melody_text

#: Most play touches a closed-loop session may take (``steps``).
MAX_LOOP_STEPS = 100_000


class LoopConfig(Config):
    """A closed-loop session: ``melody`` played in a loop for ``steps`` play touches (adaptation
    touches come on top); the world moves the keyboard after ``perturb_at`` touches; each
    adaptation takes at most ``max_adapt_steps`` touches; ``adapt``'s ``mode`` and
    ``reach_noise`` also set the simulated arm."""

    what = "loop"

    melody: Name = DEFAULT_MELODY
    steps: between(Whole, 1, MAX_LOOP_STEPS) = 600
    perturb_at: NonNegativeInt = 200
    max_adapt_steps: between(Whole, 1, MAX_ADAPT_STEPS) = 40
    detector: DetectorConfig = Field(default_factory=DetectorConfig)
    adapt: Any = Field(default_factory=lambda: AdaptConfig(stop=True))

    _melody = field_validator("melody")(check_melody_text)

    _adapt = field_validator("adapt", mode="before")(as_table(AdaptConfig))

    @field_serializer("adapt")
    def _adapt_table(self, v: AdaptConfig) -> dict:
        return v.to_dict()

    @model_validator(mode="after")
    def _perturb_in_session(self) -> LoopConfig:
        if self.perturb_at >= self.steps:
            raise ConfigError(
                f"perturb_at must be a step in [0, {self.steps - 1}], got {self.perturb_at!r}")
        if self.perturb_at < self.detector.warmup:
            raise ConfigError(
                f"perturb_at ({self.perturb_at}) must leave the detector its warm-up of "
                f"n_lt + n_st = {self.detector.warmup} results before the keyboard moves"
            )
        return self


def _rate(results: np.ndarray) -> float | None:
    return float(1.0 - results.mean()) if len(results) else None


class LoopSession:
    """One closed-loop session: iterate it for :class:`~kbcli.core.playing.loop.LoopStep` records,
    then take :meth:`artifact`. ``rng`` is split into the robot's generator and the world's."""

    def __init__(self, cfg: LoopConfig, model_art: Artifact, scene_art: Artifact, *,
                 rng: np.random.Generator, seed: int | None = None, model=None) -> None:
        check_inputs(model_art, scene_art)
        self.cfg, self.model_art, self.scene_art, self.seed = cfg, model_art, scene_art, seed
        self.keyboard = keyboard_stage.load(scene_art)
        self.model = load_model(model_art) if model is None else model
        self.melody = parse_melody(cfg.melody, self.keyboard)
        self.world_family, self.truth = perturb_stage.pose(scene_art)
        self.world = World(keyboard=self.keyboard, reacher=make_reacher(cfg.adapt.sim_config()))
        robot_rng, world_rng = rng.spawn(2)
        acfg = cfg.adapt.adapter_config()
        self._robot = closed_loop(
            self.model, self.melody, self._touch(world_rng),
            play_steps=cfg.steps, detector=cfg.detector, adapter=acfg,
            max_adapt_steps=cfg.max_adapt_steps, rng=robot_rng,
            table=build_table(self.model, acfg),
        )
        self.steps: list[LoopStep] = []
        self.moved_at: int | None = None
        #: the arm's joint angles after each touch (dynamics mode)
        self.joint_angles: list[np.ndarray] = []
        #: (touch, log translation marginal) after each adaptation touch
        self.posteriors: list[tuple[int, np.ndarray]] = []
        self._axes: tuple[np.ndarray, np.ndarray] | None = None

    def _touch(self, world_rng: np.random.Generator):
        def touch(actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            if self.moved_at is None and self.world.touches >= self.cfg.perturb_at:
                self.world.pose, self.world.family = self.truth, self.world_family
                self.moved_at = self.world.touches
            landed, heard = self.world.touch(actions, world_rng)
            ang = end_angles(self.world.reacher)
            if ang is not None and len(ang) == len(landed):
                self.joint_angles.extend(ang)
            return landed, heard

        return touch

    def __iter__(self) -> Iterator[LoopStep]:
        for s in self._robot:
            if s.marginal is not None:
                dx, dy, logp = s.marginal
                self._axes = (dx, dy)
                self.posteriors.append((s.t, logp))
            self.steps.append(s)
            yield s

    def summary(self) -> dict:
        """Success rates before the move, after it (until adapted) and after adaptation."""
        st = self.steps
        phase = np.array([s.phase for s in st])
        result = np.array([s.result for s in st])
        t = np.arange(len(st))
        moved = self.cfg.perturb_at
        play = phase == PLAY
        fired = [s.t for s in st if s.fired and s.t >= moved]
        adapt_t = t[phase == ADAPT]
        first_fire = fired[0] if fired else None
        end_adapt = None
        if first_fire is not None:
            after = adapt_t[adapt_t > first_fire]
            end_adapt = int(after.max()) if len(after) else None
            # the first adaptation ends where the next play touch starts
            nxt = t[(t > first_fire) & play]
            end_adapt = int(nxt[0]) - 1 if len(nxt) else end_adapt
        before = result[play & (t < moved)]
        during = result[play & (t >= moved) & (t <= (first_fire if first_fire is not None else t[-1]))]
        restored = result[play & (t > end_adapt)] if end_adapt is not None else np.array([])
        correction = st[-1].correction if st else np.zeros(0)
        names = transforms.FAMILIES.get(self.cfg.adapt.family).params
        err_px = None
        if end_adapt is not None:
            c = np.asarray(correction, float)
            err_px = float(np.hypot(*(c[-2:] - self.truth[-2:])))
        false_alarms = [s.t for s in st if s.fired and s.t < moved]
        return {
            "adaptation_list": self._adaptations(phase, names),
            "success_before": _rate(before),
            "success_after_perturbation": _rate(during),
            "success_after_adaptation": _rate(restored),
            "perturbed_at": moved,
            "detected_at": first_fire,
            "detection_delay": None if first_fire is None else int(first_fire - moved + 1),
            "false_alarms": len(false_alarms),
            "adaptations": int(sum(1 for s in st if s.fired)),
            "adapt_touches": int((phase == ADAPT).sum()),
            "correction": {n: float(v) for n, v in zip(names, correction, strict=True)},
            "truth": transforms.FAMILIES.get(self.world_family).as_dict(self.truth),
            "correction_error_px": err_px,
            # resolved from the model's own reliability when the config leaves it None
            "redundancy_radius": (redundancy_radius(self.model, self.cfg.adapt.adapter_config())
                                  if self.cfg.adapt.adapter_config().is_robust else 0.0),
            "robust_blurs": ([float(v) for v in robust_blurs(self.model,
                                                             self.cfg.adapt.adapter_config())]
                             if self.cfg.adapt.adapter_config().is_robust else []),
            "robust_eta": (learning_rate(self.model, self.cfg.adapt.adapter_config())
                           if self.cfg.adapt.adapter_config().is_robust else 1.0),
        }

    def _adaptations(self, phase: np.ndarray, names: tuple[str, ...]) -> list[dict]:
        """Each adaptation: the touch the detector fired on, the first adaptation touch, how many,
        the correction it ended with and that correction's error against the truth (px)."""
        out = []
        for first, last in adaptation_blocks(phase):
            c = np.asarray(self.steps[last].correction, float)
            out.append({"fired_at": first - 1, "first": first, "touches": last - first + 1,
                        "correction": {n: float(v) for n, v in zip(names, c, strict=True)},
                        "error_px": float(np.hypot(*(c[-2:] - self.truth[-2:])))})
        return out

    def artifact(self) -> Artifact:
        st = self.steps
        d = self.keyboard.features.shape[1]
        arr = {
            "phase": np.array([s.phase for s in st], dtype=np.int8),
            "action": np.array([s.action for s in st], float).reshape(-1, 2),
            "landed": np.array([s.landed for s in st], float).reshape(-1, 2),
            "perceived": np.array([s.perceived for s in st], float).reshape(-1, d),
            "result": np.array([s.result for s in st], dtype=np.int8),
            "score": np.array([s.score for s in st], float),
            "fired": np.array([s.fired for s in st], dtype=np.uint8),
            "correction": np.array([s.correction for s in st], float),
        }
        n_params = arr["correction"].shape[1] if arr["correction"].ndim == 2 else 0
        arr["estimate"] = np.array([np.full(n_params, np.nan) if s.estimate is None else s.estimate
                                    for s in st], float).reshape(len(st), n_params)
        if len(self.joint_angles) == len(st) and st:
            arr["joint_angles"] = np.array(self.joint_angles, float)
        data = {"steps": arr, "truth": {"params": self.truth}}
        if self.posteriors:
            dx, dy = self._axes
            data["posterior"] = {
                "touch": np.array([t for t, _ in self.posteriors], np.int64),
                "log_translation": np.stack([p for _, p in self.posteriors]),
                "dx": dx, "dy": dy,
            }
        summary = self.summary()
        sim = self.cfg.adapt.sim_config()
        summary["arm"] = {"base": list(sim.base), "link_lengths": list(sim.link_lengths)}
        summary["mode"] = self.cfg.adapt.mode
        return Artifact(
            kind="closed_loop",
            config={"loop": self.cfg.to_dict(), "keyboard": self.model_art.config["keyboard"]},
            seed=self.seed,
            data=data,
            attrs=summary,
            inputs={"model": ref(self.model_art), "scene": ref(self.scene_art)},
        )


def run(cfg: LoopConfig, model_art: Artifact, scene_art: Artifact, *, rng: np.random.Generator,
        seed: int | None = None) -> Artifact:
    """Run a whole closed-loop session and return its artifact."""
    session = LoopSession(cfg, model_art, scene_art, rng=rng, seed=seed)
    for _ in session:
        pass
    return session.artifact()

