"""Benchmark of the arm presets: how far a reach lands from its target, and from where the robot
feels it landed.

For each arm preset (:data:`kbcli.sim.arms.PRESETS`) and reach mode, the arm reaches ``reaches``
targets uniform over the default keyboard's working area, one after the other. Reported per preset
and mode: the median and 95th percentile of ``|landed - target|``, ``|felt - landed|`` and
``|contact - landed|``, and the simulated reaches per second. Pure: returns rows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.sim import MODES, SimConfig, contact_points, make_reacher
from kbcli.sim.arms import PRESETS


@dataclass(frozen=True)
class ArmRow:
    preset: str
    mode: str
    landing: tuple[float, float]  # median, p95 of |landed - target|, px
    felt: tuple[float, float]  # median, p95 of |felt - landed|, px
    contact: tuple[float, float]  # median, p95 of |contact - landed|, px
    reaches_per_s: float


def _stats(d: np.ndarray) -> tuple[float, float]:
    return float(np.median(d)), float(np.percentile(d, 95))


def landing_statistics(sim: SimConfig, targets: np.ndarray,
                       rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Reach ``targets`` (n, 2) in turn; the landing, felt and contact errors (n,) px each."""
    reacher = make_reacher(sim)
    t0 = time.perf_counter()
    landed = reacher.reach(targets, rng)
    seconds = time.perf_counter() - t0
    felt = reacher.last_felt
    contact = contact_points(sim, landed, rng)
    return {
        "landing": np.hypot(*(landed - targets).T),
        "felt": np.hypot(*(felt - landed).T),
        "contact": np.hypot(*(contact - landed).T),
        "seconds": np.float64(seconds),
    }


def run(reaches: int = 500, seed: int = 0, presets: tuple[str, ...] = PRESETS.names(),
        modes: tuple[str, ...] = MODES.names()) -> list[ArmRow]:
    """One row per preset and mode (see the module docstring)."""
    kb = Keyboard(KeyboardConfig())
    x0, y0, x1, y1 = kb.area
    rows = []
    for name in presets:
        for mode in modes:
            rng = np.random.default_rng(seed)
            targets = rng.uniform((x0, y0), (x1, y1), size=(reaches, 2))
            s = landing_statistics(SimConfig(mode=mode, arm=PRESETS.get(name)), targets, rng)
            rows.append(ArmRow(name, mode, _stats(s["landing"]), _stats(s["felt"]),
                               _stats(s["contact"]), reaches / max(float(s["seconds"]), 1e-9)))
    return rows
