"""Stage ``quality``: does a better model make active adaptation pay? (the paper's Sect. IV-C).

The paper's robot result was not significant, and the authors blamed "the model learned with the
iCub robot", asking for "more experiments to confirm this hypothesis". This stage runs them:

1. **learn** a model for every exploration strategy x reach budget of ``[quality]`` (e.g. active
   and random exploration, 100 to 1600 reaches) with the configured arm (``realistic`` by default),
   each from its own seed; its quality is measured against the simulator (accuracy, boundary
   error) and self-estimated (:mod:`kbcli.core.reliability`);
2. **adapt** with every model, for every row (a strategy and its adapt options: random, active and
   infogain with the robust posterior, and infogain with the plain posterior for reference), to
   the paper's fixed displacements (small / medium / large), ``experiments`` times each. The
   repetitions share their seeds across rows (a paired design: the same displacement, the same
   arm noise draws where the touches coincide), so each row is compared with the baseline by the
   Wilcoxon signed-rank test;
3. **assemble** the ``model_quality`` artifact: every run's error per step, and per model, category
   and row: the final error (after ``max_steps`` touches), the touches to the model's threshold
   ``tau = 2 max(boundary error, 0.5 px)`` (runs that never get there count ``max_steps + 1``), and
   the advantage over the baseline (median of the paired differences in touches to ``tau``,
   positive when the row needs fewer) with its p-value.

Every experiment is one call of the adapt stage's ``experiment`` (the robot's side never reads the
truth), seeded by a child of ``SeedSequence(seed)`` chosen by its place in the grid, so results do
not depend on the number of workers or the backend (:mod:`kbcli.io.runner`). The report
(:func:`report`) draws the advantage against the model's boundary error and says, from the data,
whether the paper's explanation holds.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np
from scipy import stats as sps

from kbcli.core.adapt import REDUNDANCY_FACTOR, blur_grid, own_boundary_error, table_key, temper
from kbcli.core.config import check_known, check_names, check_whole
from kbcli.errors import ConfigError
from kbcli.sim import MODES
from kbcli.sim.arms import arm_config
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.evaluate import Category, _paper_categories

#: Rows of the default sweep: name -> adapt options (strategy included).
DEFAULT_ROWS = {
    "random": {"strategy": "random"},
    "active": {"strategy": "active"},
    "infogain": {"strategy": "infogain"},
    "infogain-plain": {"strategy": "infogain", "robust": False},
}
#: The reference row adapted with the exact model (the keyboard's own map) when ``ideal`` is on.
IDEAL_ROW = "exact-infogain"
#: Its model's name among the sweep's experiments.
EXACT = "exact"
#: Options the sweep sets itself for every experiment (not allowed in a row or ``adapt``).
FIXED = ("mode", "arm", "reach_noise", "max_steps", "family", "stop")
LEARN_KEY = 1
ADAPT_KEY = 2


@dataclass(frozen=True, kw_only=True)
class QualityConfig:
    """The model-quality sweep (the ``[quality]`` table of ``pipelines/model-quality.toml``).

    Parameters
    ----------
    seed : int
        Root of every model's and experiment's seed.
    budgets : tuple of int
        Reaches of each learned model.
    explorations : tuple of str
        Exploration strategies (``active``, ``random``).
    mode : str
        Reach mode of learning and adapting (``ideal`` or ``dynamics``).
    arm : str or table
        Arm preset (:mod:`kbcli.sim.arms`) of learning and adapting.
    reach_noise : float
        Extra landing scatter, px.
    rows : mapping
        Name -> adapt options (``strategy`` and any adapt option, e.g. ``robust = false``).
    baseline : str
        The row the others are compared with.
    experiments : int
        Repetitions per displacement, model and row.
    max_steps : int
        Touches per adaptation.
    categories : tuple of Category
        The displacements (the paper's by default).
    adapt : mapping
        Adapt options shared by every row.
    ideal : bool
        Also adapt with the exact model (the keyboard's own map, no model error), with infogain,
        on the same displacements and seeds: the touches infogain needs to reach each learned
        model's threshold when the model is perfect, a reference for what a better model could
        buy (not a strict bound: infogain is greedy, and a lucky run does better).
    """

    seed: int = 2024
    budgets: tuple[int, ...] = (100, 150, 200, 300, 400, 800, 1600)
    explorations: tuple[str, ...] = ("active", "random")
    mode: str = "dynamics"
    arm: Any = "realistic"
    reach_noise: float = 0.0
    rows: Any = field(default_factory=lambda: dict(DEFAULT_ROWS))
    baseline: str = "random"
    experiments: int = 8
    max_steps: int = 30
    categories: tuple[Category, ...] = field(default_factory=_paper_categories)
    adapt: Any = field(default_factory=dict)
    ideal: bool = True

    def __post_init__(self) -> None:
        from kbcli.stages.learn import strategies as learn_strategies

        check_whole("quality.seed", self.seed, 0)
        check_whole("quality.experiments", self.experiments, 1)
        check_whole("quality.max_steps", self.max_steps, 1)
        if not isinstance(self.ideal, bool):
            raise ConfigError(f"quality.ideal must be true or false, got {self.ideal!r}")
        b = self.budgets
        if isinstance(b, (str, bytes)) or not b or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 10 for v in b):
            raise ConfigError(f"quality.budgets must be whole numbers >= 10, got {b!r}")
        object.__setattr__(self, "budgets", tuple(sorted(set(b))))
        object.__setattr__(self, "explorations", check_names("quality.explorations", self.explorations))
        for e in self.explorations:
            if e not in learn_strategies() or e == "exact":
                raise ConfigError(f"unknown exploration {e!r}; valid: active, random")
        if self.mode not in MODES:
            raise ConfigError(f"unknown mode {self.mode!r}; valid: {', '.join(MODES)}")
        object.__setattr__(self, "arm", arm_config(self.arm).to_dict())
        rn = self.reach_noise
        if isinstance(rn, bool) or not isinstance(rn, (int, float)) or not math.isfinite(rn) \
                or rn < 0:
            raise ConfigError(f"quality.reach_noise must be >= 0 px, got {rn!r}")
        if not isinstance(self.rows, (dict, MappingProxyType)) or not self.rows:
            raise ConfigError("quality.rows must be a table of name = {strategy = ..., ...}")
        rows = {}
        for name, opts in self.rows.items():
            if not isinstance(opts, (dict, MappingProxyType)) or "strategy" not in opts:
                raise ConfigError(f"quality.rows.{name} must be a table with a strategy")
            fixed = sorted(set(opts) & set(FIXED))
            if fixed:
                raise ConfigError(f"quality.rows.{name}.{fixed[0]} is set by the sweep itself")
            if name == IDEAL_ROW:
                raise ConfigError(f"quality.rows.{name}: the name is kept for the exact model's "
                                  "reference (quality.ideal)")
            rows[str(name)] = dict(opts)
        object.__setattr__(self, "rows", MappingProxyType(rows))
        if self.baseline not in rows:
            raise ConfigError(f"quality.baseline {self.baseline!r} must name a row "
                              f"({', '.join(rows)})")
        if not isinstance(self.adapt, (dict, MappingProxyType)):
            raise ConfigError("quality.adapt must be a table of adapt options")
        fixed = sorted(set(self.adapt) & set(FIXED + ("strategy",)))
        if fixed:
            raise ConfigError(f"quality.adapt.{fixed[0]} is set by the sweep or its rows")
        object.__setattr__(self, "adapt", MappingProxyType(dict(self.adapt)))
        cats = tuple(self.categories)
        if not cats or not all(isinstance(c, Category) for c in cats):
            raise ConfigError("quality.categories must hold at least one category")
        object.__setattr__(self, "categories", cats)
        for name in rows:  # let the adapt stage check every row's options
            adapt_config(self, name)

    def to_dict(self) -> dict:
        return {
            "seed": self.seed, "budgets": list(self.budgets),
            "explorations": list(self.explorations), "mode": self.mode, "arm": dict(self.arm),
            "reach_noise": float(self.reach_noise),
            "rows": {k: dict(v) for k, v in self.rows.items()}, "baseline": self.baseline,
            "experiments": self.experiments, "max_steps": self.max_steps,
            "categories": {c.name: c.to_dict() for c in self.categories},
            "adapt": dict(self.adapt), "ideal": self.ideal,
        }

    def __reduce__(self):  # the read-only mappings do not pickle; the dict form does
        return (QualityConfig.from_dict, (self.to_dict(),))

    @classmethod
    def from_dict(cls, d: dict) -> QualityConfig:
        """Build from the ``[quality]`` table; unknown keys are rejected."""
        if not isinstance(d, dict):
            raise ConfigError("[quality] must be a table")
        check_known(cls, d, "quality")
        d = dict(d)
        for k in ("budgets", "explorations"):
            if k in d:
                if not isinstance(d[k], (list, tuple)):
                    raise ConfigError(f"quality.{k} must be a list, got {d[k]!r}")
                d[k] = tuple(d[k])
        if "categories" in d:
            cats = d["categories"]
            if not isinstance(cats, dict):
                raise ConfigError("quality.categories must be a table of name = {limit, "
                                  "displacements}")
            out = []
            for name, t in cats.items():
                if not isinstance(t, dict) or "displacements" not in t or \
                        set(t) - {"limit", "displacements"}:
                    raise ConfigError(f"quality.categories.{name} must have displacements (and "
                                      "may have limit)")
                out.append(Category(name=name, limit=t.get("limit"),
                                    displacements=tuple(tuple(r) for r in t["displacements"])))
            d["categories"] = tuple(out)
        return cls(**d)

    def with_overrides(self, *, experiments: int | None = None,
                       budgets: tuple[int, ...] | None = None) -> QualityConfig:
        cfg = self
        if experiments is not None:
            cfg = replace(cfg, experiments=experiments)
        if budgets is not None:
            cfg = replace(cfg, budgets=budgets)
        return cfg


def adapt_config(cfg: QualityConfig, row: str):
    """The adapt stage's config of one row (or of :data:`IDEAL_ROW`: infogain)."""
    from kbcli.stages.adapt import AdaptConfig

    opts = {"strategy": "infogain"} if row == IDEAL_ROW else dict(cfg.rows[row])
    values = {**dict(cfg.adapt), **opts, "mode": cfg.mode, "arm": dict(cfg.arm),
              "reach_noise": float(cfg.reach_noise), "max_steps": cfg.max_steps,
              "family": "translation", "stop": False}
    return AdaptConfig.from_dict(values)


def model_names(cfg: QualityConfig) -> list[tuple[str, str, int]]:
    """(name, exploration, budget) of every model of the sweep, in artifact order."""
    return [(f"{e}-{b}", e, b) for e in cfg.explorations for b in cfg.budgets]


# -- phase 1: learning ------------------------------------------------------------------------------
@dataclass(frozen=True)
class LearnTask:
    name: str
    exploration: str
    budget: int
    seed: int


def learn_tasks(cfg: QualityConfig) -> list[LearnTask]:
    """One task per model; model ``i`` is learned with seed ``SeedSequence(seed, (1, i))``'s."""
    out = []
    for i, (name, e, b) in enumerate(model_names(cfg)):
        ss = np.random.SeedSequence(cfg.seed, spawn_key=(LEARN_KEY, i))
        out.append(LearnTask(name, e, b, int(ss.generate_state(1)[0])))
    return out


def learn_setup(ctx: dict) -> dict:
    from kbcli.stages.learn import LearnConfig

    return {"keyboard": ctx["keyboard"], "cfg": QualityConfig.from_dict(ctx["quality"]),
            "LearnConfig": LearnConfig}


def learn_one(state: dict, task: LearnTask) -> dict:
    """Learn one model; returns its artifact as ``{"artifact": Artifact}``."""
    from kbcli.sim import SimConfig
    from kbcli.stages import learn as learn_stage

    cfg: QualityConfig = state["cfg"]
    sim = SimConfig(mode=cfg.mode, reach_noise=float(cfg.reach_noise), arm=dict(cfg.arm))
    lc = state["LearnConfig"](strategy=task.exploration, budget=task.budget, sim=sim)
    art = learn_stage.run(lc, state["keyboard"], rng=np.random.default_rng(task.seed),
                          seed=task.seed)
    return {"artifact": art}


# -- phase 2: adapting ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task:
    row: int
    model: str
    category: str
    param_index: int
    params: tuple[float, ...]
    method: str
    rep: int
    entropy: int
    spawn_key: tuple[int, ...]


def plan(cfg: QualityConfig) -> list[Task]:
    """Every adaptation of the sweep, in artifact order (model, category, displacement, row,
    repetition; then, with ``ideal``, the exact model's). The seed depends on (category,
    displacement, repetition) only: the same for every model and row (paired)."""
    tasks: list[Task] = []
    names = [n for n, _, _ in model_names(cfg)]
    for name, rows in [*((n, list(cfg.rows)) for n in names),
                       *([(EXACT, [IDEAL_ROW])] if cfg.ideal else [])]:
        for ci, cat in enumerate(cfg.categories):
            for p, params in enumerate(cat.displacements):
                for row in rows:
                    for rep in range(cfg.experiments):
                        tasks.append(Task(len(tasks), name, cat.name, p, tuple(params), row, rep,
                                          int(cfg.seed), (ADAPT_KEY, ci, p, rep)))
    return tasks


def adapt_setup(ctx: dict) -> dict:
    from kbcli.stages import keyboard as keyboard_stage
    from kbcli.stages.models import load_model

    cfg = QualityConfig.from_dict(ctx["quality"])
    models = {name: load_model(art) for name, art in ctx["models"].items()}
    kb = keyboard_stage.load(next(iter(ctx["models"].values())))
    if cfg.ideal:
        from kbcli.stages.learn import exact_artifact

        models[EXACT] = load_model(exact_artifact(ctx["keyboard"]))
    return {"cfg": cfg, "models": models, "keyboard": kb, "tables": {}}


def adapt_one(state: dict, task: Task) -> dict:
    """One adaptation; returns the error (px) after every touch and the wall time per step."""
    from kbcli.stages import adapt as adapt_stage

    cfg: QualityConfig = state["cfg"]
    acfg = adapt_config(cfg, task.method)
    model = state["models"][task.model]
    key = (task.model, table_key(model, acfg.adapter_config()))
    if key not in state["tables"]:
        # keep the current model's tables only, which plan() runs together (two for the shipped
        # rows, robust and plain, about 0.1 GB each): clearing at a fixed count rebuilt them at
        # every displacement
        if any(m != task.model for m, _ in state["tables"]):
            state["tables"].clear()
        state["tables"][key] = adapt_stage.build_shared_table(acfg, model)
    rng = np.random.default_rng(np.random.SeedSequence(task.entropy, spawn_key=task.spawn_key))
    out = adapt_stage.experiment(acfg, model, state["keyboard"], np.asarray(task.params, float),
                                 rng=rng, table=state["tables"][key])
    return {"errors": np.asarray(out["errors"], float), "step_ms": np.asarray(out["step_ms"])}


# -- assembling ---------------------------------------------------------------------------------
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
    n, T = len(tasks), cfg.max_steps
    errors = np.stack([results[t.row]["errors"] for t in tasks]).reshape(n, T)
    model = np.array([t.model for t in tasks])
    cat = np.array([t.category for t in tasks])
    row = np.array([t.method for t in tasks])
    pidx = np.array([t.param_index for t in tasks], np.int64)
    rep = np.array([t.rep for t in tasks], np.int64)
    summary: dict[str, Any] = {}
    model_info = {}
    exact = model == EXACT
    for name, e, b in model_names(cfg):
        a = models[name].attrs
        berr = float(a["boundary_error_px"])
        tau = threshold(berr)
        rel = a.get("reliability") or {}
        own = own_boundary_error(rel)  # (capped as the runs used it)
        model_info[name] = {"exploration": e, "budget": b, "accuracy": float(a["accuracy"]),
                            "boundary_error": berr, "threshold": tau,
                            "estimated_boundary_error": rel.get("boundary_error"),
                            # held-out touches' rate (as before) and the pad's, as the
                            # calibrated model expects it (models learned since 2026-12-02)
                            "estimated_mislabel_rate": rel.get("cv_error"),
                            "expected_mislabel_rate": rel.get("expected_error"),
                            "redundancy_radius": (REDUNDANCY_FACTOR * own
                                                  if own is not None else None),
                            # the widest boundary blur the robust posterior weighs by default
                            "widest_blur": max(blur_grid(own)),
                            # the learning rate the robust posterior tempers touches with
                            "learning_rate": temper(own)}
        per: dict[str, Any] = {}
        for group in [*[c.name for c in cfg.categories], "all"]:
            sel_m = (model == name) & ((cat == group) if group != "all" else True)
            base_sel = sel_m & (row == cfg.baseline)
            order = np.lexsort((rep[base_sel], pidx[base_sel], cat[base_sel]))
            base_t = touches_to(errors[base_sel], tau)[order]
            base_final = errors[base_sel][order, -1]
            per[group] = {}
            for r in cfg.rows:
                sel = sel_m & (row == r)
                o = np.lexsort((rep[sel], pidx[sel], cat[sel]))
                t = touches_to(errors[sel], tau)[o]
                fin = errors[sel][o, -1]
                cell = {
                    "final_median": float(np.median(fin)),
                    "final_p90": float(np.percentile(fin, 90)),
                    "touches_median": float(np.median(t)),
                    "reached": float(np.mean(t <= T)),
                    "runs": int(sel.sum()),
                }
                if r != cfg.baseline:
                    adv, p = paired_test(base_t, t)
                    cell["advantage"] = adv  # median paired difference: touches saved
                    cell["pvalue"] = p
                    cell["final_vs_baseline"] = paired_test(base_final, fin)[1]
                per[group][r] = cell
        if exact.any():  # a perfect model's touches to this model's tau, per category
            model_info[name]["ideal_touches"] = {
                g: float(np.median(touches_to(errors[exact & ((cat == g) if g != "all" else True)],
                                              tau)))
                for g in [*[c.name for c in cfg.categories], "all"]}
        summary[name] = per
    data = {
        "experiments": {"model": model, "category": cat, "row": row, "param_index": pidx,
                        "rep": rep, "errors": errors},
    }
    attrs = {"models": model_info, "summary": summary, "rows": list(cfg.rows),
             "baseline": cfg.baseline, "max_steps": T,
             "categories": [c.name for c in cfg.categories], "n_experiments": n,
             "rows_resolved": {r: adapt_config(cfg, r).to_dict()
                               for r in [*cfg.rows, *([IDEAL_ROW] if exact.any() else [])]}}
    if exact.any():
        attrs["ideal"] = {"row": IDEAL_ROW, "final_median": {
            c.name: float(np.median(errors[exact & (cat == c.name), -1])) for c in cfg.categories}}
    inputs = {"keyboard": ref(keyboard_art)}
    return Artifact(kind="model_quality", config=cfg.to_dict(), seed=cfg.seed, data=data,
                    attrs=attrs, inputs=inputs)


def fingerprint(cfg: QualityConfig, keyboard_art: Artifact) -> dict:
    from kbcli import __version__

    return {"quality": cfg.to_dict(), "keyboard_sha256": keyboard_art.sha256,
            "kbcli_version": __version__}


# -- the report ---------------------------------------------------------------------------------
def hypothesis(art: Artifact, row: str) -> dict:
    """Whether ``row``'s advantage over the baseline shrinks as the model gets worse.

    Spearman's rank correlation, over the models, between the boundary error and the advantage
    (touches saved to each model's threshold, pooled over categories), and how many models show a
    significant advantage (p < 0.01) among the better and the worse half (split at the median
    boundary error).
    """
    info, summ = art.attrs["models"], art.attrs["summary"]
    names = list(info)
    berr = np.array([info[m]["boundary_error"] for m in names], float)
    adv = np.array([summ[m]["all"][row]["advantage"] for m in names], float)
    pv = np.array([summ[m]["all"][row]["pvalue"] for m in names], float)
    if len(names) >= 3 and np.ptp(adv) > 0 and np.ptp(berr) > 0:
        rho, p = sps.spearmanr(berr, adv)
        rho, p = float(rho), float(p)
    else:
        rho, p = float("nan"), float("nan")
    cut = np.median(berr)
    good, bad = berr <= cut, berr > cut
    return {"row": row, "rho": rho, "p": p, "models": len(names),
            "significant_good": int(np.sum((pv < 0.01) & (adv > 0) & good)),
            "good": int(good.sum()),
            "significant_bad": int(np.sum((pv < 0.01) & (adv > 0) & bad)), "bad": int(bad.sum()),
            "median_split_px": float(cut)}


def verdict(h: dict) -> str:
    """The paper's explanation, judged on one row from :func:`hypothesis`."""
    if not np.isfinite(h["rho"]):
        return "not measured (fewer than three models, or no spread)"
    sig = h["p"] < 0.05
    if h["rho"] < 0 and sig:
        return (f"holds: the advantage shrinks as the boundary error grows (Spearman rho = "
                f"{h['rho']:.2f}, p = {h['p']:.1e})")
    if h["rho"] > 0 and sig:
        return (f"contradicted: the advantage grows with the boundary error (rho = {h['rho']:.2f}, "
                f"p = {h['p']:.1e})")
    return (f"not supported: no significant trend of the advantage with the boundary error "
            f"(rho = {h['rho']:.2f}, p = {h['p']:.2f})")


def targets(art: Artifact, row: str = "infogain") -> list[dict]:
    """Issue 9's targets, per model and category, as measured (for the report's table)."""
    info, summ = art.attrs["models"], art.attrs["summary"]
    base = art.attrs["baseline"]
    out = []
    for m, mi in _ordered(info):
        for c in art.attrs["categories"]:
            s, b = summ[m][c].get(row), summ[m][c][base]
            if s is None:
                continue
            bound = max(1.0, mi["boundary_error"])
            ideal = (mi.get("ideal_touches") or {}).get(c)
            out.append({
                "model": m, "category": c, "final": s["final_median"], "bound": bound,
                "final_ok": s["final_median"] <= bound,
                "random_final": b["final_median"],
                "not_worse": s["final_median"] <= b["final_median"] or
                s.get("final_vs_baseline", 1.0) >= 0.05,
                "touches": s["touches_median"], "random_touches": b["touches_median"],
                "half": s["touches_median"] <= 0.5 * b["touches_median"],
                "ideal_touches": ideal,
                # within infogain's reach? not if it needs more than half with a perfect model
                "attainable": None if ideal is None else ideal <= 0.5 * b["touches_median"],
                "weak": 150 <= mi["budget"] <= 400,
            })
    return out


def report(art: Artifact) -> str:
    """The README of a model-quality report (figures are drawn by :mod:`kbcli.viz.quality`)."""
    a = art.attrs
    cfg = art.config
    rows = [r for r in a["rows"] if r != a["baseline"]]
    lines = [
        "# Does a better model make active adaptation pay? (the paper's Sect. IV-C hypothesis)",
        "",
        f"Generated by `kbcli report` from `{art.path or 'a model_quality artifact'}` (sha256 "
        f"`{(art.sha256 or '?')[:16]}`, kbcli {art.kbcli_version}).",
        "",
        f"- {a['n_experiments']} adaptations: {len(a['models'])} models ({', '.join(cfg['explorations'])} "
        f"exploration x {', '.join(str(b) for b in cfg['budgets'])} reaches), "
        f"{cfg['mode']} mode, arm `{cfg['arm']['preset']}`; {len(a['rows'])} rows x "
        f"{len(a['categories'])} categories x {cfg['experiments']} repetitions per displacement; "
        f"{a['max_steps']} touches each; seed {art.seed}.",
        "- rows (every resolved adapt option in `rows_resolved` of the artifact): "
        + "; ".join(f"`{r}` = {json.dumps(cfg['rows'][r], sort_keys=True)}" for r in a["rows"])
        + f"; baseline `{a['baseline']}`.",
        *([f"- reference: `{a['ideal']['row']}`, infogain with the exact model (the keyboard's own "
           "map: no model error) on the same displacements and seeds, once for the sweep; its "
           "touches to each model's tau are what infogain needs when the model is perfect "
           "(median final error: " + ", ".join(f"{c} {v:.2f} px" for c, v in
                                              a["ideal"]["final_median"].items()) + ")."]
          if a.get("ideal") else []),
        "- threshold of each model: tau = 2 x max(its boundary error, 0.5 px); *advantage*: the "
        "median over paired runs (same displacement and seed) of the baseline's touches to tau "
        "minus the row's (positive: the row needs fewer; a run that never gets there counts "
        f"{a['max_steps'] + 1}); p: two-sided Wilcoxon signed-rank test on those pairs.",
        "",
        "![advantage against boundary error](advantage.png)",
        "",
        "## The paper's explanation, tested",
        "",
        "The paper: the active strategy's advantage was not significant on the robot because "
        "\"the model learned with the iCub robot was not accurate enough\". If so, the advantage "
        "should shrink as the model's boundary error grows.",
        "",
        "| row | Spearman rho (advantage vs boundary error) | p | significant advantage, better half | worse half | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        h = hypothesis(art, r)
        lines.append(f"| {r} | {h['rho']:.2f} | {h['p']:.1e} | {h['significant_good']} of "
                     f"{h['good']} | {h['significant_bad']} of {h['bad']} | {verdict(h)} |")
    lines += ["", "## Models", "",
              "| model | accuracy | boundary error (px) | self-estimated (px) | mislabel rate: measured / expected by the model / held-out touches | tau (px) | spot radius (px) | widest blur (px) | learning rate |",
              "|---|---|---|---|---|---|---|---|---|"]
    for m, mi in _ordered(a["models"]):
        est = mi.get("estimated_boundary_error")
        rates = [mi.get("expected_mislabel_rate"), mi.get("estimated_mislabel_rate")]
        lines.append(f"| {m} | {100 * mi['accuracy']:.1f} % | {mi['boundary_error']:.2f} | "
                     + (f"{est:.2f}" if est is not None else "n/a") + " | "
                     f"{100 * (1 - mi['accuracy']):.1f} % / "
                     + " / ".join(f"{100 * v:.1f} %" if v is not None else "n/a" for v in rates)
                     + f" | {mi['threshold']:.2f} | "
                     + (f"{mi['redundancy_radius']:.1f}" if mi.get("redundancy_radius") is not None
                        else "n/a") + " | "
                     + (f"{mi['widest_blur']:.1f}" if mi.get("widest_blur") is not None
                        else "n/a") + " | "
                     + (f"{mi['learning_rate']:.3g}" if mi.get("learning_rate") is not None
                        else "n/a") + " |")
    lines += ["", "## Per model and category", "",
              "Final error (median px after the last touch), touches to tau (median), advantage "
              "over the baseline and its p-value.", "",
              "| model | category | " + " | ".join(a["rows"]) + " |",
              "|---|---|" + "---|" * len(a["rows"])]
    for m, _ in _ordered(a["models"]):
        for c in [*a["categories"], "all"]:
            cells = []
            for r in a["rows"]:
                s = a["summary"][m][c][r]
                txt = f"{s['final_median']:.2f} px, {s['touches_median']:g} t"
                if "advantage" in s:
                    txt += f", adv {s['advantage']:+g} (p {s['pvalue']:.1e})"
                cells.append(txt)
            lines.append(f"| {m} | {c} | " + " | ".join(cells) + " |")
    tg = targets(art)
    if tg:
        ok_final = sum(t["final_ok"] for t in tg)
        ok_nw = sum(t["not_worse"] for t in tg)
        weak = [t for t in tg if t["weak"] and t["category"] != "small"]
        ok_half = sum(t["half"] for t in weak)
        measured_ideal = [t for t in weak if t["attainable"] is not None]
        out_of_reach = [t for t in measured_ideal if not t["attainable"]]
        within = [t for t in measured_ideal if t["attainable"]]
        lines += ["", "## Issue 9's targets for infogain, as measured", "",
                  f"- final error after {a['max_steps']} touches <= max(1 px, the model's boundary "
                  f"error): {ok_final} of {len(tg)} (model, category) cells;",
                  f"- no worse than random (median final error, or no significant difference at "
                  f"p < 0.05): {ok_nw} of {len(tg)} cells;",
                  f"- weak models (150-400 reaches), medium and large displacements: at most half "
                  f"of random's touches to tau: {ok_half} of {len(weak)} cells (small "
                  f"displacements start within tau of the truth and are left out)"
                  + (f"; in {len(out_of_reach)} of those {len(measured_ideal)} cells even "
                     f"infogain with the exact model (a perfect model, same displacements and "
                     f"seeds) needs more than half of random's touches: out of infogain's reach "
                     f"there whatever the model"
                     + (f" ({sum(t['half'] for t in within)} of the {len(within)} others met)."
                        if within else ".")
                     if measured_ideal else "."),
                  "", "| model | category | infogain final | bound | random final | infogain touches | random touches | exact model's touches |",
                  "|---|---|---|---|---|---|---|---|"]
        for t in tg:
            mark = "" if (t["final_ok"] and t["not_worse"]) else " **(missed)**"
            ideal = "n/a" if t["ideal_touches"] is None else f"{t['ideal_touches']:g}"
            lines.append(f"| {t['model']} | {t['category']} | {t['final']:.2f}{mark} | "
                         f"{t['bound']:.2f} | {t['random_final']:.2f} | {t['touches']:g} | "
                         f"{t['random_touches']:g} | {ideal} |")
    return "\n".join(lines) + "\n"


__all__ = ["QualityConfig", "plan", "learn_tasks", "assemble", "report", "hypothesis", "verdict",
           "targets", "threshold", "touches_to", "paired_test"]


def _ordered(models: dict) -> list[tuple[str, dict]]:
    """The models' (name, info) by exploration, then budget (not by name: 1600 after 800)."""
    return sorted(models.items(), key=lambda kv: (str(kv[1].get("exploration", "")),
                                                  float(kv[1].get("budget", 0)), kv[0]))
