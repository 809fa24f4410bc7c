"""What the runs say beside the claims: the stopping rules and the runs that ruled out the truth.

- **Stopping** (Sect. III-D): every run takes ``max_steps`` touches and records at every step the
  probability of its maximum-likelihood cell (the paper's rule) and the mass near its estimate
  (ours), so both rules are applied after the fact to every method: the paper's at the judged
  method's ``stop_ml`` (:data:`PAPER_STOP_ML` when it sets none), ours at the default
  ``stop_mass`` within each method's ``stop_radius``.
- **The truth ruled out**: a run whose posterior at the true displacement fell below
  :data:`EXCLUDED` of its maximum at any step
  (:meth:`kbcli.core.adaptation.posteriors.posterior.Posterior.log_ratio_at`).

Pure: arrays from the artifact in, table rows (strings) out.
"""

from __future__ import annotations

import math

import numpy as np

from kbcli.core.adaptation.config import AdapterConfig
from kbcli.stages.artifact import Artifact
from kbcli.stages.report.source import methods_of, robot

#: The posterior at the truth below this fraction of its maximum: the truth is ruled out.
EXCLUDED = 1e-12
#: The paper's stopping threshold when the judged method sets none (``pipelines/paper.toml``'s
#: open choice: the paper names no number).
PAPER_STOP_ML = 0.02


def _rows(art: Artifact, mode: str, method: str, strategy: str,
          category: str | None = None) -> np.ndarray:
    exp = art.data["experiments"]
    sel = (exp["mode"] == mode) & (exp["method"] == method) & (exp["strategy"] == strategy)
    if category is not None:
        sel &= exp["category"] == category
    return sel


def _step(art: Artifact, key: str) -> np.ndarray | None:
    """A per-step record ``steps/KEY`` (n, T), or None when the evaluation lacks it (or holds
    only NaN: recorded by an experiment function that does not report it)."""
    steps = art.data.get("steps", {})
    if key not in steps:
        return None
    v = np.asarray(steps[key], float)
    return None if np.isnan(v).all() else v


def excluded(art: Artifact) -> list[dict[str, str]] | None:
    """Per mode, method and strategy: runs, and runs whose posterior put the truth below
    :data:`EXCLUDED` of its maximum at some step; None when the evaluation does not record it
    (made before issue 39)."""
    ratio = _step(art, "truth_logratio")
    if ratio is None:
        return None
    low = np.nanmin(np.where(np.isnan(ratio), 0.0, ratio), axis=1) < math.log(EXCLUDED)
    out = []
    for m in art.attrs["modes"]:
        for x, info in methods_of(art).items():
            for s in info["strategies"]:
                sel = _rows(art, m, x, s)
                if sel.any():
                    out.append({"mode": m, "method": x, "strategy": s, "runs": str(int(sel.sum())),
                                "truth ruled out": str(int(low[sel].sum()))})
    return out


def final_errors(art: Artifact) -> list[dict[str, str]] | None:
    """Per mode, method, category and strategy: the RMSE over runs of the error after the last
    touch and the largest final error (px); None when the evaluation holds no per-run errors."""
    errors = _step(art, "errors")
    if errors is None:
        return None
    T = errors.shape[1]
    out = []
    for m in art.attrs["modes"]:
        for x, info in methods_of(art).items():
            for c in art.attrs["categories"]:
                for s in info["strategies"]:
                    sel = _rows(art, m, x, s, c)
                    if sel.any():
                        e = errors[sel, -1]
                        out.append({"mode": m, "method": x, "category": c, "strategy": s,
                                    "runs": str(int(sel.sum())),
                                    f"RMSE at t={T} px": f"{np.sqrt(np.mean(e ** 2)):.2f}",
                                    "largest final error px": f"{np.max(e):.2f}"})
    return out


def rules(art: Artifact) -> dict[str, tuple[str, str, float]]:
    """The two stopping rules applied to every run: name -> (label, per-step record, threshold)."""
    judged = robot(art, art.attrs["judged"])
    ml = judged.get("stop_ml") or PAPER_STOP_ML
    mass = float(AdapterConfig.model_fields["stop_mass"].default)
    return {"paper": (f"the paper's: ML cell >= {ml:g}", "ml_prob", float(ml)),
            "ours": (f"ours: mass within stop_radius >= {mass:g}", "mass", mass)}


def stop_steps(values: np.ndarray, threshold: float) -> np.ndarray:
    """(n,) the first step (1-based) at which each run's record reached ``threshold``; 0 when
    it never did within its steps (NaN never reaches)."""
    hit = np.nan_to_num(np.asarray(values, float), nan=-np.inf) >= threshold
    first = np.argmax(hit, axis=1) + 1
    return np.where(hit.any(axis=1), first, 0)


def stopping(art: Artifact, mode: str) -> list[dict[str, str]] | None:
    """Per method, category, strategy and rule: the share of runs the rule stopped within
    ``max_steps``, the median touches to stop and the median error at the stop (runs it never
    stopped: at ``max_steps``), beside the median error at ``max_steps``; None when the
    evaluation does not record what the rules read."""
    errors = _step(art, "errors")
    recs = {k: _step(art, k) for k in ("ml_prob", "mass")}
    if errors is None or any(v is None for v in recs.values()):
        return None
    T = errors.shape[1]
    out = []
    for x, info in methods_of(art).items():
        if mode not in info["modes"]:
            continue
        for c in art.attrs["categories"]:
            if c not in info["categories"]:
                continue
            for s in info["strategies"]:
                sel = _rows(art, mode, x, s, c)
                if not sel.any():
                    continue
                e = errors[sel]
                for _, (label, key, thr) in rules(art).items():
                    t = stop_steps(recs[key][sel], thr)
                    at = np.where(t > 0, t, T) - 1
                    e_stop = e[np.arange(len(e)), at]
                    stopped = t > 0
                    out.append({
                        "method": x, "category": c, "strategy": s, "rule": label,
                        "stopped": f"{100 * stopped.mean():.0f} %",
                        "median touches to stop": (f"{np.median(t[stopped]):g}" if stopped.any()
                                                   else "-"),
                        "median error at stop px": f"{np.median(e_stop):.2f}",
                        "share > 4 px at stop": f"{100 * np.mean(e_stop > 4):.0f} %",
                        f"median error at t={T} px": f"{np.median(e[:, -1]):.2f}"})
    return out


def markdown(rows: list[dict[str, str]]) -> list[str]:
    """Rows of one table as markdown lines."""
    if not rows:
        return []
    cols = list(rows[0])
    return ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols),
            *("| " + " | ".join(r[k] for k in cols) + " |" for r in rows)]


def sections(art: Artifact) -> list[str]:
    """The README sections "Stopping rules" and "Runs that ruled out the truth"."""
    lines = ["## Stopping rules", ""]
    rl = rules(art)
    lines.append(
        "Every run takes max_steps touches (Fig. 7's curves need one length); both stopping rules "
        "are applied after the fact to every run, with the same thresholds for every method: "
        + "; ".join(label for label, _, _ in rl.values())
        + ". A run the rule never stopped counts its error at max_steps. The paper gives no "
        "threshold (kbcli's reading: the judged method's `stop_ml`).")
    for m in art.attrs["modes"]:
        rows = stopping(art, m)
        lines += ["", f"### {m} mode", ""]
        lines += markdown(rows) if rows else ["Not recorded in this evaluation (made before "
                                              "the per-step rule readings were kept)."]
    lines += ["", "## Runs that ruled out the truth", "",
              f"A run rules the truth out when its posterior at the true displacement falls below "
              f"{EXCLUDED:g} of its maximum at some step (read on the grid cells around the "
              "truth); the truth then cannot recover. It should be 0 for every method.", ""]
    rows = excluded(art)
    lines += markdown(rows) if rows else ["Not recorded in this evaluation (made before the "
                                          "truth's place in the posterior was kept)."]
    return [*lines, ""]
