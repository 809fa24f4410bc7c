"""Assembling the ``model_quality`` artifact: thresholds, touches, paired tests, summaries."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats as sps

from kbcli.core.adaptation.config import REDUNDANCY_FACTOR, blur_grid, own_boundary_error, temper
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.quality.config import (
    EXACT,
    IDEAL_ROW,
    QualityConfig,
    adapt_config,
    compared_rows,
    model_names,
)
from kbcli.stages.quality.plan import Task


def threshold(boundary_error: float) -> float:
    """The error (px) a model's adaptation is asked to reach: twice its boundary error, at least
    1 px."""
    return 2.0 * max(float(boundary_error), 0.5)


def touches_to(errors: np.ndarray, tau: float) -> np.ndarray:
    """(n,) first touch (1-based) with error below ``tau``; ``T + 1`` when never."""
    e = np.asarray(errors, float)
    below = e < tau
    return np.where(below.any(axis=1), np.argmax(below, axis=1) + 1, e.shape[1] + 1)


def paired_test(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(median of a - b, two-sided Wilcoxon signed-rank p-value); p = 1 when a == b throughout."""
    d = np.asarray(a, float) - np.asarray(b, float)
    if not np.any(d != 0):
        return 0.0, 1.0
    res = sps.wilcoxon(a, b, zero_method="zsplit", method="auto")
    return float(np.median(d)), float(res.pvalue)


def assemble(cfg: QualityConfig, models: dict[str, Artifact], tasks: list[Task],
             results: dict[int, dict], keyboard_art: Artifact) -> Artifact:
    """The ``model_quality`` artifact (see the module docstring)."""
    n = len(tasks)
    exp = _experiments(cfg, tasks, results)
    errors, cat = exp["errors"], exp["category"]
    exact = exp["model"] == EXACT
    groups = [*[c.name for c in cfg.categories], "all"]
    summary: dict[str, Any] = {}
    model_info = {}
    for name, e, b in model_names(cfg):
        model_info[name] = _model_info(models[name].attrs, e, b)
        tau = model_info[name]["threshold"]
        summary[name] = {g: _group_summary(cfg, exp, name, g, tau) for g in groups}
        if exact.any():  # a perfect model's touches to this model's tau, per category
            model_info[name]["ideal_touches"] = {
                g: float(np.median(touches_to(errors[exact & ((cat == g) if g != "all" else True)],
                                              tau)))
                for g in groups}
    attrs = {"models": model_info, "summary": summary, "rows": list(cfg.rows),
             "baseline": cfg.baseline, "max_steps": cfg.max_steps,
             **({"baselines": dict(cfg.baselines)} if cfg.baselines else {}),
             "categories": [c.name for c in cfg.categories], "n_experiments": n,
             "rows_resolved": {r: adapt_config(cfg, r).to_dict()
                               for r in [*cfg.rows, *([IDEAL_ROW] if exact.any() else [])]}}
    if exact.any():
        attrs["ideal"] = {"row": IDEAL_ROW, "final_median": {
            c.name: float(np.median(errors[exact & (cat == c.name), -1])) for c in cfg.categories}}
    inputs = {"keyboard": ref(keyboard_art)}
    return Artifact(kind="model_quality", config=cfg.to_dict(), seed=cfg.seed,
                    data={"experiments": exp}, attrs=attrs, inputs=inputs)


def _experiments(cfg: QualityConfig, tasks: list[Task], results: dict[int, dict]) -> dict:
    """Every run's labels and its error (n, max_steps) after each touch, in task order."""
    n, T = len(tasks), cfg.max_steps
    return {"model": np.array([t.model for t in tasks]),
            "category": np.array([t.category for t in tasks]),
            "row": np.array([t.method for t in tasks]),
            "param_index": np.array([t.param_index for t in tasks], np.int64),
            "rep": np.array([t.rep for t in tasks], np.int64),
            "errors": np.stack([results[t.row]["errors"] for t in tasks]).reshape(n, T)}


def _model_info(a: dict, exploration: str, budget: int) -> dict:
    """A learned model's quality (from its artifact's attributes) and what the runs set from it."""
    berr = float(a["boundary_error_px"])
    rel = a.get("reliability") or {}
    own = own_boundary_error(rel)  # (capped as the runs used it)
    return {"exploration": exploration, "budget": budget, "accuracy": float(a["accuracy"]),
            "boundary_error": berr, "threshold": threshold(berr),
            "estimated_boundary_error": rel.get("boundary_error"),
            # held-out touches' rate and the pad's, as the calibrated model expects it
            "estimated_mislabel_rate": rel.get("cv_error"),
            "expected_mislabel_rate": rel.get("expected_error"),
            "redundancy_radius": (REDUNDANCY_FACTOR * own if own is not None else None),
            # the widest boundary blur the robust posterior weighs by default
            "widest_blur": max(blur_grid(own)),
            # the learning rate the robust posterior tempers touches with
            "learning_rate": temper(own)}


def _paired(exp: dict, sel: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """(touches to tau, final error) of the selected runs in pairing order (category,
    displacement, repetition)."""
    o = np.lexsort((exp["rep"][sel], exp["param_index"][sel], exp["category"][sel]))
    return touches_to(exp["errors"][sel], tau)[o], exp["errors"][sel][o, -1]


def _group_summary(cfg: QualityConfig, exp: dict, name: str, group: str, tau: float) -> dict:
    """Row -> final error, touches to tau and (but for baseline rows) the paired advantage over
    its baseline row, of one model's runs in one category (or ``all``)."""
    row = exp["row"]
    sel_m = (exp["model"] == name) & ((exp["category"] == group) if group != "all" else True)
    compared = compared_rows(cfg.to_dict())
    per = {}
    for r in cfg.rows:
        sel = sel_m & (row == r)
        t, fin = _paired(exp, sel, tau)
        cell = {
            "final_median": float(np.median(fin)),
            "final_p90": float(np.percentile(fin, 90)),
            "touches_median": float(np.median(t)),
            "reached": float(np.mean(t <= cfg.max_steps)),
            "runs": int(sel.sum()),
        }
        if r in compared:
            base_t, base_final = _paired(exp, sel_m & (row == cfg.baseline_of(r)), tau)
            adv, p = paired_test(base_t, t)
            cell["advantage"] = adv  # median paired difference: touches saved
            cell["pvalue"] = p
            cell["final_vs_baseline"] = paired_test(base_final, fin)[1]
        per[r] = cell
    return per


def fingerprint(cfg: QualityConfig, keyboard_art: Artifact) -> dict:
    from kbcli import __version__

    return {"quality": cfg.to_dict(), "keyboard_sha256": keyboard_art.sha256,
            "kbcli_version": __version__}


