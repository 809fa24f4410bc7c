"""The layouts pipeline's report: each of issue 11's targets against what was measured
(:func:`targets`) and the report's Markdown (:func:`render`)."""

from __future__ import annotations

import json
import math

import numpy as np

from kbcli import __version__
from kbcli.bench import adapt as adapt_bench
from kbcli.bench import learn as learn_bench
from kbcli.bench.layouts.config import LayoutResult, LayoutsConfig

#: The issue's targets.
TARGET_800, TARGET_1600, TARGET_RATIO, TARGET_GRID_LINES = 0.97, 0.99, 0.5, 0.99
TARGET_TOUCHES, TARGET_PX = 8.0, 2.0


def _pooled_median(rows: list[dict], cells: list, label: str, section: str,
                   threshold: float, ) -> tuple[float, int]:
    """Median touches to ``threshold`` px over every category's runs of one strategy (runs that
    never get there count as T + 1), and how many never did."""
    from kbcli.core.adaptation import stats

    counts = []
    T = 0
    for c in cells:
        if c.section == section and c.label == label:
            e = adapt_bench.counted_errors(c)
            T = c.cfg.max_steps
            counts.append(stats.samples_to_threshold(e, np.array([threshold]))[:, 0])
    if not counts:
        return float("nan"), 0
    allc = np.concatenate(counts).astype(float)
    allc[allc > T] = np.inf  # never got there: counts as more than any number of touches
    return float(np.median(allc)), int(np.isinf(allc).sum())


#: The layout and model class of the target "lines: accuracy >= 99 % at 800 reaches".
LINES_TARGET = ("grid", "lines")


def targets(cfg: LayoutsConfig, res: LayoutResult) -> list[dict]:
    """Each of the issue's targets for one layout: what was asked, what was measured, met or not."""
    active = [r for r in res.learn_rows if r["strategy"] == learn_bench.COMPARED]
    out = [_accuracy_target(active, budget, level)
           for budget, level in ((800, TARGET_800), (1600, TARGET_1600))
           if active and budget in cfg.budgets]
    if active and 800 in cfg.budgets:
        out += _ratio_targets(cfg, res, active) + _lines_target(res, active)
    return out + _adapt_target(cfg, res)


def _accuracy_target(active: list[dict], budget: int, level: float) -> dict:
    """The best class's accuracy at ``budget`` reaches under active exploration, at least
    ``level``."""
    best = max(active, key=lambda r: r["accuracy"][budget])
    v = best["accuracy"][budget]
    return {"target": f"best class, active: accuracy >= {100 * level:g} % at {budget} reaches",
            "measured": f"{100 * v:.2f} % ({best['model_class']})", "met": v >= level}


def _ratio_targets(cfg: LayoutsConfig, res: LayoutResult, active: list[dict]) -> list[dict]:
    """Active exploration needs at most half of random's reaches to 97 % (the best class at 800
    reaches)."""
    best = max(active, key=lambda r: r["accuracy"][800])
    out = []
    for q in learn_bench.ratios(res.learn_rows, 0.97):
        if q["model_class"] != best["model_class"]:
            continue
        a, r = q["active"], q["random"]
        met = bool(np.isfinite(a) and (not np.isfinite(r) or a <= TARGET_RATIO * r))
        shown = (f"active {a:g} vs random {r:g} reaches to 97 %" if np.isfinite(r) else
                 f"active {a:g}, random > {cfg.learn_config().max_budget} (never)")
        out.append({"target": f"active needs at most half of random's reaches to 97 % "
                              f"({q['model_class']})", "measured": shown, "met": met})
    return out


def _lines_target(res: LayoutResult, active: list[dict]) -> list[dict]:
    """:data:`LINES_TARGET`'s class at 800 reaches on its layout, at least 99 %."""
    layout, model_class = LINES_TARGET
    lines = [r for r in active if r["model_class"] == model_class]
    if res.layout != layout or not lines:
        return []
    v = lines[0]["accuracy"][800]
    return [{"target": "lines: accuracy >= 99 % at 800 reaches", "measured": f"{100 * v:.2f} %",
             "met": v >= TARGET_GRID_LINES}]


def _adapt_target(cfg: LayoutsConfig, res: LayoutResult) -> list[dict]:
    """Infogain with the learned model: median touches to :data:`TARGET_PX` px at most
    :data:`TARGET_TOUCHES`."""
    if not res.cells:
        return []
    med, never = _pooled_median(res.adapt_rows, res.cells, "infogain", "learned", TARGET_PX)
    if math.isnan(med):
        return []
    return [{"target": f"infogain, learned {cfg.adapt_budget}-reach model: median touches to "
                       f"< {TARGET_PX:g} px <= {TARGET_TOUCHES:g}",
             "measured": (f"{med:g}" if math.isfinite(med) else f"> {cfg.max_steps}")
             + f" (all categories; {never} runs never within T)",
             "met": med <= TARGET_TOUCHES}]


def _md_table(head: list[str], body: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return "\n".join(lines)


def _fmt_med(m: float, never: int) -> str:
    txt = "-" if not math.isfinite(m) else f"{m:g}"
    return txt + (f" ({never})" if never else "")


def render(cfg: LayoutsConfig, results: dict[str, LayoutResult]) -> str:
    """The report's Markdown."""
    lc = cfg.learn_config()
    md = [f"# Learning and adapting on every layout (kbcli {__version__})", "",
          f"Made by `kbcli bench layouts --config {cfg.source}`"
          + (" (`make reproduce-layouts`)" if cfg.source == "pipelines/layouts.toml" else "")
          + " with the settings at the end. Every number below is measured by that run; the "
          "targets are issue 11's.", ""]
    md += ["## Targets", ""]
    rows = []
    for name, res in results.items():
        for t in targets(cfg, res):
            rows.append([name, t["target"], t["measured"], "met" if t["met"] else "**missed**"])
    md += [_md_table(["layout", "target", "measured", "status"], rows), ""]
    md += ["## Learning the model", "",
           f"{cfg.seeds} runs per row ({cfg.mode} mode); median accuracy (%) on a 1 px grid over "
           "the working area at each budget; reaches to 97 % / 99 %: the median first curve point "
           f"(every {lc.resolution} reaches) at or above it (runs that never get there count as "
           f"more than {lc.max_budget}); boundary error (px) at {cfg.boundary_budget} reaches; "
           f"the time of one fit on {lc.max_budget} samples (shared machine).", ""]
    body = []
    for res in results.values():
        head, b = learn_bench.table(lc, res.learn_rows)
        body += b
    md += [_md_table(head, body), ""]
    for res in results.values():
        md += [f"- {line}" for line in learn_bench.ratio_lines(lc, res.learn_rows)]
    md += ["", "## Adapting with a learned model", "",
           f"Each layout's model: `kbcli learn` with active exploration, {cfg.adapt_budget} reaches, "
           f"seed {cfg.seed}, the class with the best median accuracy at {cfg.adapt_budget} reaches "
           "in the table above (or the one configured). Median touches until the error first "
           "drops below each threshold ((k): runs that never got there within "
           f"T = {cfg.max_steps}); translation: {cfg.experiments} runs per strategy and category; "
           f"rigid (angles up to 5 deg; a threshold of t px also needs the angle within t/2 deg): "
           f"{cfg.rigid_experiments} runs. RMSE (px) at the last step.", ""]
    body = []
    for name, res in results.items():
        a = res.model_attrs
        model = (f"{res.model_class}, {100 * a.get('accuracy', float('nan')):.2f} %, "
                 f"{a.get('boundary_error_px', float('nan')):.2f} px")
        for r in res.adapt_rows:
            fam = "rigid" if r["section"] == "learned-rigid" else "translation"
            body.append([name, model, fam, r["label"], r["category"],
                         *[_fmt_med(m, n) for m, n in zip(r["median"], r["never"], strict=True)],
                         f"{r['final_rmse']:.2f}"])
    head = ["layout", "model (class, accuracy, boundary error)", "family", "strategy", "category",
            *[f"< {t:g} px" for t in adapt_bench.THRESHOLDS], "final rmse"]
    md += [_md_table(head, body), ""]
    md += ["## Figures", ""]
    for name in results:
        md += [f"- [{name}]({name}.png): the layout; the {cfg.adapt_budget}-reach model's map "
               "(wrong cells red, reaches black); learning curves (median accuracy of every class "
               "and strategy); adaptation (median error per step of every strategy)."]
    md += ["", "## Settings", "", "```json", json.dumps(cfg.to_dict(), indent=1), "```", ""]
    return "\n".join(md)
