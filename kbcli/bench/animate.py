"""Benchmark of ``kbcli animate``: seconds to render a 40-touch adaptation.

The benchmark makes the run it renders: the embedded default model (or a given one) adapting to a
(12, -7) px move in ``dynamics`` mode for 40 touches with the posterior stored at every step (the
worst case), and a 600-touch closed loop. Each is rendered ``repeats`` times to a GIF; reported:
frames, the median process CPU time and the median wall time of the rendering (``kbcli``'s start-up
excluded).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import ClassVar

import numpy as np

from kbcli.core.config import Config, Count, Flag, NonNegativeInt
from kbcli.stages import adapt as adapt_stage
from kbcli.stages import perturb as perturb_stage
from kbcli.stages import run as run_stage
from kbcli.stages.artifact import Artifact

TARGET_S = 15.0


class BenchConfig(Config):
    """Benchmark settings (see the module docstring)."""

    what: ClassVar[str] = "bench animate"

    repeats: Count = 3
    touches: Count = 40
    loop: Flag = True
    seed: NonNegativeInt = 0


def make_runs(cfg: BenchConfig, model_art: Artifact) -> dict[str, Artifact]:
    """The artifacts to render: an adaptation of ``cfg.touches`` touches (and a closed loop)."""
    scene = perturb_stage.run(perturb_stage.PerturbConfig(params=(12.0, -7.0)), model_art,
                              rng=np.random.default_rng(cfg.seed))
    acfg = adapt_stage.AdaptConfig(mode="dynamics", max_steps=cfg.touches)
    runs = {f"adaptation, {cfg.touches} touches": adapt_stage.run(
        acfg, model_art, scene, rng=np.random.default_rng(cfg.seed), seed=cfg.seed,
        snapshot_steps=tuple(range(cfg.touches + 1)))}
    if cfg.loop:
        lcfg = run_stage.LoopConfig(adapt=adapt_stage.AdaptConfig(mode="dynamics", stop=True))
        runs["closed loop, 600 play touches"] = run_stage.run(
            lcfg, model_art, scene, rng=np.random.default_rng(cfg.seed), seed=cfg.seed)
    return runs


def measure(art: Artifact, repeats: int) -> dict:
    """Render ``art`` ``repeats`` times; frames, median CPU and wall seconds."""
    from kbcli.viz.animate import animate

    cpu, wall, frames = [], [], 0
    with tempfile.TemporaryDirectory() as d:
        for i in range(repeats):
            c0, w0 = time.process_time(), time.perf_counter()
            frames = animate(art, Path(d) / f"r{i}.gif")
            cpu.append(time.process_time() - c0)
            wall.append(time.perf_counter() - w0)
        size = (Path(d) / "r0.gif").stat().st_size
    return {"frames": frames, "cpu_s": float(np.median(cpu)), "wall_s": float(np.median(wall)),
            "mb": size / 2**20}
