"""Planning the evaluation: one :class:`Task` per experiment, in artifact row order, each with its
own seed (:func:`plan`); and what every worker shares (:func:`context`)."""

from __future__ import annotations

import hashlib
import json
import zlib
from dataclasses import dataclass

import numpy as np

from kbcli.stages.artifact import Artifact
from kbcli.stages.config import check_total
from kbcli.stages.evaluate.config import EvaluateConfig

#: The experiment function, ``experiment(cfg, model, keyboard, true_params, *, rng, ...) -> dict``.
EXPERIMENT = "kbcli.stages.adapt:experiment"


@dataclass(frozen=True)
class Task:
    """One experiment: what a worker needs to run it (picklable, immutable).

    The seed is stored as the (entropy, spawn_key) of its ``SeedSequence``, not as the object:
    spawning from a ``SeedSequence`` mutates it, so a shared object would seed a rerun differently.
    ``play_reference``: this experiment also replays the melody before the displacement and after it
    without adaptation (once per mode, parametrization and repetition: the first method and strategy
    that runs there), from :attr:`reference_seed` (not from the experiment's own seed).
    """

    row: int
    seed_index: int
    mode: str
    category: str
    param_index: int
    params: tuple[float, ...]
    method: str
    strategy: str
    rep: int
    entropy: int
    spawn_key: tuple[int, ...]
    example: bool
    play_reference: bool = False

    @property
    def seed(self) -> np.random.SeedSequence:
        """A fresh ``SeedSequence`` for this experiment."""
        return np.random.SeedSequence(self.entropy, spawn_key=self.spawn_key)

    @property
    def reference_seed(self) -> np.random.SeedSequence:
        """The seed of the reference replays (before the displacement, unadapted):
        ``SeedSequence(seed, spawn_key=(mode, category, parametrization, "reference",
        repetition))``, without method or strategy, so they measure the same whichever
        experiment runs them."""
        mode, cat, p = self.spawn_key[:3]
        return np.random.SeedSequence(self.entropy,
                                      spawn_key=(mode, cat, p, _key("reference"), self.rep))


def _key(name: str) -> int:
    return zlib.crc32(name.encode())


def plan(cfg: EvaluateConfig) -> list[Task]:
    """The experiments of ``cfg`` in artifact row order (mode, category, parametrization, method,
    strategy, repetition), each with its seed.

    The seed is ``SeedSequence(cfg.seed, spawn_key=(mode, category, parametrization, method,
    strategy, repetition))`` (names as CRC-32 numbers; the method's ``seed_name``), so an experiment gets the same seed whatever
    else is selected. ``seed_index`` numbers the experiments in that order.
    """
    check_total(sum(len(meth.strategies) * cfg.experiments for mode in cfg.modes
                    for cat in cfg.categories for _ in cat.displacements for meth in cfg.methods
                    if meth.runs_in(mode, cat.name)), "evaluate")
    tasks: list[Task] = []
    seen: set = set()
    for mode in cfg.modes:
        for cat in cfg.categories:
            for p, params in enumerate(cat.displacements):
                for meth in cfg.methods:
                    if not meth.runs_in(mode, cat.name):
                        continue
                    for strategy in meth.strategies:
                        for rep in range(cfg.experiments):
                            key = (_key(mode), _key(cat.name), p, _key(meth.seed_name), _key(strategy),
                                   rep)
                            ref_key = (mode, cat.name, p, rep)
                            tasks.append(Task(
                                row=len(tasks), seed_index=len(tasks), mode=mode,
                                category=cat.name, param_index=p, params=params,
                                method=meth.name, strategy=strategy, rep=rep, entropy=cfg.seed,
                                spawn_key=key,
                                example=cat.name == cfg.example and p == 0 and rep == 0,
                                play_reference=cfg.play_notes > 0 and ref_key not in seen,
                            ))
                            seen.add(ref_key)
    return tasks


def context(cfg: EvaluateConfig, model_art: Artifact, experiment: str = EXPERIMENT) -> dict:
    """What every worker shares: the model artifact, the config and the experiment's name."""
    return {"model": model_art, "evaluate": cfg.to_dict(), "experiment": experiment}


def context_key(ctx: dict) -> str:
    """A digest identifying a context (model file hash, config and experiment function)."""
    art = ctx["model"]
    ident = {"model": art.sha256 or json.dumps(art.config, sort_keys=True, default=str),
             "evaluate": ctx["evaluate"], "experiment": ctx["experiment"]}
    return hashlib.sha256(json.dumps(ident, sort_keys=True, default=str).encode()).hexdigest()
