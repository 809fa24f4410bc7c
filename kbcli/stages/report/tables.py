"""The README's tables: resolved options, observations to thresholds, p-values, RMSE, playing
success and the large-displacement ablation (each a list of markdown lines)."""

from __future__ import annotations

import numpy as np

from kbcli.core.adaptation.config import shown
from kbcli.stages.artifact import Artifact
from kbcli.stages.report.source import (
    KEY_OPTIONS,
    RMSE_STEPS,
    cell,
    fmt_med,
    fmt_p,
    methods_of,
    ordered,
    played,
    readings,
    robot,
)


def methods_table(art: Artifact) -> list[str]:
    """The resolved options of every method (rows), methods as columns; differing rows marked; an
    option a method does not read is "n/a" (every one stays recorded in the artifact)."""
    meths = list(methods_of(art))
    info = methods_of(art)
    lines = ["| option | " + " | ".join(f"`{x}`" for x in meths) + " |",
             "|" + "---|" * (len(meths) + 1)]
    for k in ("strategies", "modes", "categories"):
        lines.append(f"| {k} | " + " | ".join(", ".join(info[x][k]) for x in meths) + " |")
    return [*lines, *_robot_rows(art, meths), *_model_rows(art, info, meths),
            *_loop_rows(_loop_options(info, meths), meths)]


#: What the methods table prints for an option a method does not read.
NOT_APPLICABLE = "n/a"


def applicable(art: Artifact, method: str) -> dict:
    """A method's robot options, :data:`NOT_APPLICABLE` for those it does not read (its parts
    and the adapter say which: :func:`kbcli.core.adaptation.config.shown`)."""
    r, strategies = robot(art, method), methods_of(art)[method]["strategies"]
    read = shown(r, strategies)
    return {k: v if k in read else NOT_APPLICABLE for k, v in r.items()}


def _robot_rows(art: Artifact, meths: list[str]) -> list[str]:
    """The robot's options, :data:`KEY_OPTIONS` first; those that differ in bold; "n/a" where an
    option does not apply to a method, and no row for an option no method reads."""
    robots = {x: applicable(art, x) for x in meths}
    keys = [k for k in KEY_OPTIONS if any(k in r for r in robots.values())]
    keys += sorted({k for r in robots.values() for k in r} - set(keys))
    lines = []
    for k in keys:
        vals = [robots[x].get(k, NOT_APPLICABLE) for x in meths]
        if all(v == NOT_APPLICABLE for v in vals):
            continue
        name = f"**{k}**" if len({str(v) for v in vals}) > 1 else k
        lines.append(f"| {name} | " + " | ".join(str(v) for v in vals) + " |")
    return lines


def _loop_options(info: dict, meths: list[str]) -> dict:
    """Option -> method -> value of the loop's options (those of each mode's first strategy;
    reach noise and arm preset per mode)."""
    loop: dict = {}
    for x in meths:
        for mode, by_s in info[x]["options"].items():
            for d in by_s.values():
                for k, v in d.items():
                    if k in ("robot", "mode", "reach_noise", "arm"):
                        continue
                    loop.setdefault(k, {})[x] = v
                loop.setdefault("reach_noise (px)", {}).setdefault(x, {})[mode] = d.get(
                    "reach_noise")
                arm = d.get("arm")
                loop.setdefault("arm (preset)", {}).setdefault(x, {})[mode] = (
                    arm.get("preset", "?") if isinstance(arm, dict) else "ideal")
                break
    return loop


def _model_rows(art: Artifact, info: dict, meths: list[str]) -> list[str]:
    """The options resolved from the model (robust posterior's radius, blurs and eta), for the
    methods that read them ("n/a" for the others; no row when none does)."""
    lines = []
    robots = {x: applicable(art, x) for x in meths}
    for k in ("redundancy_radius", "robust_blurs", "robust_eta"):  # as the model resolved them
        reads = [robots[x].get(k, NOT_APPLICABLE) != NOT_APPLICABLE for x in meths]
        if any(k in info[x].get("from_model", {}) for x in meths) and any(reads):
            vals = [info[x].get("from_model", {}).get(k, "") for x in meths]
            vals = [NOT_APPLICABLE if not ok else
                    (", ".join(f"{v:g}" for v in val) or "none (not robust)")
                    if isinstance(val, list) else
                    (f"{val:.2f}" if isinstance(val, float) else str(val))
                    for val, ok in zip(vals, reads, strict=True)]
            unit = "" if k == "robust_eta" else " (px)"
            lines.append(f"| {k}, resolved from the model{unit} | " + " | ".join(vals) + " |")
    return lines


def _loop_rows(loop: dict, meths: list[str]) -> list[str]:
    lines = []
    for k, by_x in loop.items():
        vals = []
        for x in meths:
            v = by_x.get(x, "")
            if isinstance(v, dict):
                v = ", ".join(f"{m} {n:g}" if isinstance(n, (int, float)) else f"{m} {n}"
                              for m, n in v.items() if n is not None)
            vals.append(str(v))
        lines.append(f"| {k} | " + " | ".join(vals) + " |")
    return lines


def threshold_table(art: Artifact, mode: str) -> list[str]:
    thr = art.array("thresholds")
    head = ("| method | category | strategy | " + " | ".join(f"< {t:g} px" for t in thr) + " |")
    lines = [head, "|" + "---|" * (len(thr) + 3)]
    for x, c, s, cur in ordered(art, "curves", mode):
        cells = [f"{fmt_med(m)} ({100 * r:.0f} %)" for m, r in
                 zip(cur["median_samples"], cur["reached"], strict=True)]
        lines.append(f"| {x} | {c} | {s} | " + " | ".join(cells) + " |")
    return lines


def pvalue_table(art: Artifact, mode: str) -> list[str]:
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    head = ("| method | category | test | smallest attainable p | "
            + " | ".join(f"< {t:g} px" for t in thr) + " |")
    lines = [head, "|" + "---|" * (len(thr) + 4)]
    for x, c, s, pv in ordered(art, "pvalues", mode):
        cells = []
        for p, stat in zip(pv["pvalue"], pv["statistic"], strict=True):
            sign = "" if p >= 0.05 else (" (faster)" if stat < 0 else " (slower)")
            cells.append(fmt_p(p) + sign)
        mp = float(pv.get("min_pvalue", np.nan))
        mp_txt = "< 1e-300" if mp == 0 else fmt_p(mp)
        lines.append(f"| {x} | {c} | {s} vs {base} | {mp_txt} | " + " | ".join(cells) + " |")
    return lines


def rmse_table(art: Artifact, mode: str) -> list[str]:
    T = int(art.attrs["max_steps"])
    steps = [t for t in RMSE_STEPS if t <= T] or [T]
    head = "| method | category | strategy | " + " | ".join(f"t={t}" for t in steps) + " |"
    lines = [head, "|" + "---|" * (len(steps) + 3)]
    for x, c, s, cur in ordered(art, "curves", mode):
        r = cur["rmse"]
        lines.append(f"| {x} | {c} | {s} | " + " | ".join(f"{r[t - 1]:.2f}" for t in steps) + " |")
    return lines


def _iqr(v: np.ndarray) -> str:
    if len(v) == 0:
        return "not measured"
    q = np.quantile(v, [0.25, 0.5, 0.75])
    return f"{100 * q[1]:.1f} % ({100 * q[0]:.1f}-{100 * q[2]:.1f})"


def play_table(art: Artifact) -> list[str]:
    exp = art.data["experiments"]
    lines = ["| mode | method | category | before the displacement | after it, not adapted | "
             "after adaptation, per strategy |", "|---|---|---|---|---|---|"]
    for m in art.attrs["modes"]:
        for x in [x for x in methods_of(art) if x in art.data["curves"].get(m, {})]:
            for c in [c for c in art.attrs["categories"] if c in art.data["curves"][m][x]]:
                sel = (exp["mode"] == m) & (exp["method"] == x) & (exp["category"] == c)
                after = "; ".join(f"{s} {_iqr(played(art, sel & (exp['strategy'] == s), 'play_adapted'))}"
                                  for s in methods_of(art)[x]["strategies"])
                lines.append(f"| {m} | {x} | {c} | {_iqr(played(art, sel, 'play_before'))} | "
                             f"{_iqr(played(art, sel, 'play_unadapted'))} | {after} |")
    return lines


def ablation_table(art: Artifact, mode: str, category: str = "large") -> list[str]:
    """Large displacements: each method and estimator, the baseline against the others."""
    thr = art.array("thresholds")
    base = art.attrs["baseline"]
    js = [j for j, t in enumerate(thr) if t in (4.0, 2.0, 1.0)] or list(range(len(thr)))
    T = int(art.attrs["max_steps"])
    head = ("| method | posterior | estimator | strategy | RMSE at t=" + str(T) + " | "
            + " | ".join(f"obs. to < {thr[j]:g} px" for j in js)
            + " | " + " | ".join(f"p vs {base} (< {thr[j]:g} px)" for j in js) + " |")
    lines = [head, "|" + "---|" * (5 + 2 * len(js))]
    for x in methods_of(art):
        cur, pvs = cell(art, mode, x, category)
        if cur is None:
            continue
        r = robot(art, x)
        for est, sfx in readings(art, x):
            if sfx and f"rmse{sfx}" not in cur[base]:
                continue
            label = x if not sfx else f"{x} (same runs)"
            for s in [s for s in methods_of(art)[x]["strategies"] if s in cur]:
                c = cur[s]
                rm = c["rmse" if not sfx else f"rmse{sfx}"][-1]
                meds = [f"{fmt_med(c[f'median_samples{sfx}'][j])} "
                        f"({100 * c[f'reached{sfx}'][j]:.0f} %)" for j in js]
                ps = ["" if s == base else fmt_p(pvs[s][f"pvalue{sfx}"][j]) for j in js]
                lines.append(f"| {label} | {r.get('posterior', '?')} | {est} | {s} | {rm:.2f} | "
                             + " | ".join(meds) + " | " + " | ".join(ps) + " |")
    return lines
