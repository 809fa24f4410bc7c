"""Benchmark of the learned model's calibration and self-assessment (issue 9).

For each exploration strategy and reach budget, a model is learned on the default keyboard with
the given arm and mode (``kbcli learn``'s stage, calibration included), then measured against the
simulator on a 2 px grid over the working area:

- **calibration**: the expected calibration error (15 bins of the top probability) of
  p(sound | felt action) against the simulator's own p(key | felt action), drawn by Monte Carlo
  (16 touches per grid point: the arm's proprioceptive noise and bias, its finger's contact disc;
  :func:`kbcli.sim.keys_heard_when_felt`);
- the model's accuracy and boundary error (:mod:`kbcli.core.accuracy`);

beside what the model estimated of itself from its samples alone (:mod:`kbcli.core.reliability`:
cross-validated calibration error, mislabel rate and boundary error). Pure: returns rows.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from kbcli.core import accuracy as scoring
from kbcli.core.keyboard import Keyboard, KeyboardConfig
from kbcli.core.model import grid_points
from kbcli.core.reliability import expected_calibration_error
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


def run(budgets=(150, 300, 800, 1600), explorations=("active", "random"), mode: str = "ideal",
        arm: str = "ideal", seed: int = 0) -> list[Row]:
    """One row per exploration and budget (see the module docstring)."""
    kb_cfg = KeyboardConfig()
    kb_art = keyboard_stage.run(kb_cfg)
    kb = Keyboard(kb_cfg)
    sim = SimConfig(mode=mode, arm=arm)
    rows = []
    for e in explorations:
        for b in budgets:
            t0 = time.perf_counter()
            art = learn_stage.run(learn_stage.LearnConfig(strategy=e, budget=int(b), sim=sim),
                                  kb_art, rng=np.random.default_rng(seed), seed=seed)
            secs = time.perf_counter() - t0
            model = load_model(art)
            a = art.attrs
            rel = a["reliability"]
            rows.append(Row(e, int(b), float(a["accuracy"]), float(a["boundary_error_px"]),
                            measured_ece(model, kb, sim, np.random.default_rng(seed)),
                            float(rel["cv_ece"]), 1.0 - float(a["accuracy"]),
                            float(rel["cv_error"]), float(rel["boundary_error"]),
                            dict(rel["calibration"]), secs))
    return rows
