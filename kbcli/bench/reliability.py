"""Benchmark of the learned model's calibration and self-assessment.

For each exploration strategy and reach budget, a model learned on the default keyboard
(``kbcli learn``'s stage, several seeds per cell) is measured against the simulator on a 2 px grid
(calibration error against p(key | felt action) by Monte Carlo,
:func:`kbcli.sim.keys_heard_when_felt`; accuracy and boundary error) beside what it estimated of
itself (:mod:`kbcli.core.model.reliability`); :func:`summarise` reports the median over seeds and
their spread. Pure: returns rows.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model import accuracy as scoring
from kbcli.core.model.base import grid_points
from kbcli.core.model.reliability import expected_calibration_error
from kbcli.sim import SimConfig, keys_heard_when_felt
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import learn as learn_stage
from kbcli.stages.models import load_model

GRID_STEP = 2.0
DRAWS = 16


@dataclass(frozen=True)
class Row:
    exploration: str
    budget: int
    seed: int
    accuracy: float
    boundary_error: float
    ece: float
    est_ece: float
    mislabel: float
    est_mislabel: float
    est_boundary_error: float
    calibration: dict
    seconds: float


def measured_ece(model, kb: Keyboard, sim: SimConfig, rng: np.random.Generator) -> float:
    """Calibration error of ``model`` against the simulator on a 2 px grid (module docstring)."""
    _, pts = grid_points(kb.area, GRID_STEP)
    pts = pts.reshape(-1, 2)
    keys = keys_heard_when_felt(sim, kb, pts, DRAWS, rng)
    probs = model.predict_proba(pts)
    ck = scoring.class_keys(model.class_features_, kb)  # class -> key (-1 silence, -2 none)
    pred_key = ck[probs.argmax(axis=1)]
    hit = (keys == pred_key[:, None]).mean(axis=1)
    return expected_calibration_error(probs, hit)


@dataclass(frozen=True)
class Summary:
    """The median over seeds of one exploration and budget's rows (``calibration``: the first
    seed's; ``ece_min``, ``ece_max``: the spread of the measured calibration error)."""

    exploration: str
    budget: int
    seeds: int
    accuracy: float
    boundary_error: float
    ece: float
    ece_min: float
    ece_max: float
    est_ece: float
    mislabel: float
    est_mislabel: float
    est_boundary_error: float
    calibration: dict
    seconds: float


def summarise(rows: list[Row]) -> list[Summary]:
    """One :class:`Summary` per exploration and budget, in the order they first appear."""
    cells: dict[tuple[str, int], list[Row]] = {}
    for r in rows:
        cells.setdefault((r.exploration, r.budget), []).append(r)
    out = []
    for (e, b), rs in cells.items():
        med = {f: float(np.median([getattr(r, f) for r in rs]))
               for f in ("accuracy", "boundary_error", "ece", "est_ece", "mislabel",
                         "est_mislabel", "est_boundary_error", "seconds")}
        ece = [r.ece for r in rs]
        out.append(Summary(exploration=e, budget=b, seeds=len(rs), ece_min=float(min(ece)),
                           ece_max=float(max(ece)), calibration=rs[0].calibration, **med))
    return out


def run(budgets=(150, 300, 800, 1600), explorations=("active", "random"), mode: str = "ideal",
        arm: str = "ideal", seed: int = 0, seeds: int = 1) -> list[Row]:
    """One row per exploration, budget and seed (``seed`` to ``seed + seeds - 1``; see the module
    docstring)."""
    if seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds!r}")
    kb_cfg = KeyboardConfig()
    kb_art = keyboard_stage.run(kb_cfg)
    kb = Keyboard(kb_cfg)
    sim = SimConfig(mode=mode, arm=arm)
    rows = []
    for e, b, s in itertools.product(explorations, budgets, range(seed, seed + seeds)):
        t0 = time.perf_counter()
        art = learn_stage.run(learn_stage.LearnConfig(strategy=e, budget=int(b), sim=sim),
                              kb_art, rng=np.random.default_rng(s), seed=s)
        secs = time.perf_counter() - t0
        model = load_model(art)
        a = art.attrs
        rel = a["reliability"]
        rows.append(Row(e, int(b), int(s), float(a["accuracy"]), float(a["boundary_error_px"]),
                        measured_ece(model, kb, sim, np.random.default_rng(s)),
                        float(rel["cv_ece"]), 1.0 - float(a["accuracy"]),
                        float(rel["expected_error"]), float(rel["boundary_error"]),
                        dict(rel["calibration"]), secs))
    return rows
