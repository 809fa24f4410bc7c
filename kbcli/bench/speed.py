"""Speed of the adaptation per touch (``kbcli bench speed``).

Two measures, each the median of several repeats, on the learned model, on one thread, wall-clock
and CPU time:

- **per touch** (:func:`touch_times`): deciding plus updating plus reading the estimate, set-up
  excluded, for the paper's method (``paper-active`` with the KDE posterior, fresh samples), the
  same with ``simulate_draw = "shared"``, and kbcli's default (``infogain``, likelihood posterior);
- **as ``kbcli adapt`` runs it** (:func:`adapt_times`): set-up, median touch and the whole run of
  ``touches`` infogain touches with each posterior at its defaults.

Pure: returns rows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.setup import build_table
from kbcli.sim import SimConfig, World, make_reacher
from kbcli.stages.adapt import AdaptConfig, experiment
from kbcli.stages.evaluate.methods import METHOD_KEYS, PAPER_METHOD
from kbcli.stages.models import load_model

#: The true displacement of every timed adaptation, px (a medium move).
TRUTH = (12.0, -7.0)


@dataclass(frozen=True)
class TouchRow:
    """Per-touch time of one strategy and posterior, set-up excluded (ms, medians)."""

    name: str
    runs: int
    touches: int
    cpu_ms: float
    cpu_p90: float
    wall_ms: float


@dataclass(frozen=True)
class AdaptRow:
    """One posterior as ``kbcli adapt`` runs it (ms, medians over the runs)."""

    posterior: str
    runs: int
    touches: int
    setup_ms: float
    touch_ms: float
    per_touch_ms: float
    per_touch_cpu_ms: float


#: issue 26's bound on the paper's active strategy with the KDE posterior, CPU ms per touch.
TARGET_MS = 20.0


def paper_config(**changes) -> AdapterConfig:
    """The adapter options of the ``paper`` evaluation method, with its ``paper-active`` (and
    ``changes``: ``simulate_draw="shared"`` for the faster variant)."""
    opts = {k: v for k, v in PAPER_METHOD.items() if k not in METHOD_KEYS}
    return AdapterConfig.from_dict({**opts, "strategy": "paper-active", **changes})


def touch_times(model, keyboard, cfg: AdapterConfig, name: str, *, runs: int = 3,
                touches: int = 20, seed: int = 0) -> TouchRow:
    """:class:`TouchRow` of ``cfg``: ``runs`` adaptations of ``touches`` touches each, timed per
    touch (suggest, observe, estimate), the model raster built before the clock starts."""
    table = build_table(model, cfg)
    cpu, wall = [], []
    with threadpool_limits(1):
        for r in range(runs):
            rng = np.random.default_rng([seed, r])
            adapter = Adapter(model, cfg, rng=rng, table=table).prepare()
            world = World(keyboard, make_reacher(SimConfig()), np.array(TRUTH), "translation")
            for _ in range(touches):
                c0, w0 = time.process_time(), time.perf_counter()
                action = adapter.suggest()
                c1, w1 = time.process_time(), time.perf_counter()
                felt, heard = world.touch(action[None], rng)
                c2, w2 = time.process_time(), time.perf_counter()
                adapter.observe(action, heard[0], felt_position=felt[0])
                adapter.estimate()
                cpu.append(1e3 * (c1 - c0 + time.process_time() - c2))
                wall.append(1e3 * (w1 - w0 + time.perf_counter() - w2))
    return TouchRow(name, runs, touches, float(np.median(cpu)), float(np.percentile(cpu, 90)),
                    float(np.median(wall)))


def adapt_times(model_artifact, keyboard, posterior: str, *, runs: int = 3, touches: int = 20,
                seed: int = 0) -> AdaptRow:
    """:class:`AdaptRow` of ``posterior``: ``runs`` times, the model loaded from its artifact and
    ``touches`` touches of the adapt stage (:func:`kbcli.stages.adapt.experiment`, which prepares
    the adapter before its first touch and reports that set-up's time)."""
    cfg = AdaptConfig.from_dict({"posterior": posterior, "max_steps": touches})
    setup, touch, total, cpu = [], [], [], []
    with threadpool_limits(1):
        for r in range(runs):
            timings: dict[str, float] = {}
            c0, w0 = time.process_time(), time.perf_counter()
            t0 = time.perf_counter()
            model = load_model(model_artifact)
            load_ms = 1e3 * (time.perf_counter() - t0)
            out = experiment(cfg, model, keyboard, np.array(TRUTH),
                             rng=np.random.default_rng([seed, r]), timings=timings)
            total.append(1e3 * (time.perf_counter() - w0) / touches)
            cpu.append(1e3 * (time.process_time() - c0) / touches)
            setup.append(load_ms + timings["setup_ms"])
            touch.append(float(np.median(out["step_ms"])))
    return AdaptRow(posterior, runs, touches, float(np.median(setup)), float(np.median(touch)),
                    float(np.median(total)), float(np.median(cpu)))
