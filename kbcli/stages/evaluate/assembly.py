"""Assembling the ``evaluation`` artifact from every experiment's result, with
:mod:`kbcli.core.adaptation.stats`: curves per mode, method, category and strategy, observations to each
threshold, the tests against the baseline strategy, entropy, playing success and the example runs
(:func:`assemble`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from kbcli.core.adaptation import stats
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.errors import ConfigError
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.evaluate.config import EvaluateConfig, resolved_methods
from kbcli.stages.evaluate.planning import Task
from kbcli.stages.evaluate.worker import PLAY_KEYS, STEP_KEYS

#: Each estimator's errors (the suffix of its keys in the artifact: "" is the method's estimator).
ERRORS = {"": "errors", "_ml": "ml_errors", "_mean": "mean_errors"}

def _stack(results: dict[int, dict], n: int, key: str) -> np.ndarray:
    return np.stack([results[i][key] for i in range(n)])


def _tests(counts: dict[str, np.ndarray], baseline: str) -> dict[str, dict]:
    """Tie-corrected Mann-Whitney U of each strategy's counts against the baseline's."""
    out = {}
    for s, c in counts.items():
        if s == baseline:
            continue
        eff, p = stats.mannwhitney_pvalues(c, counts[baseline])
        out[s] = {"statistic": eff, "pvalue": p,
                  "min_pvalue": np.float64(stats.min_pvalue_unpaired(len(c), len(counts[baseline])))}
    return out


def assemble(cfg: EvaluateConfig, tasks: list[Task], results: dict[int, dict],
             model_art: Artifact, keyboard: Keyboard) -> Artifact:
    """The ``evaluation`` artifact from every experiment's result (``results[row]``).

    Layout (``M``/``X``/``C``/``S`` are mode, method, category and strategy names; ``k``
    thresholds; ``T`` steps):

    - ``experiments/``: the experiment table: ``mode``, ``category``, ``method``, ``strategy`` (n,)
      str; ``param_index``, ``rep``, ``seed_index``, ``steps_taken`` (n,) int; ``stop_step`` (n,)
      int: the first observation at which the method's stopping rule held (``stop_ml``, the
      paper's, and ``stop_mass``, ours, when set), 0 never within ``max_steps``, -1 not recorded;
      ``params`` (n, P);
      ``play_before``, ``play_unadapted``, ``play_adapted`` (n,): measured playing success (share
      of MATCH in ``play_notes`` touches of Algorithm 1) before the displacement, after it without
      adaptation (both measured once per mode, parametrization and repetition, and repeated on
      every row that shares them) and after adaptation with the final estimate; NaN when not
      measured;
    - ``steps/``: ``errors`` (of the method's estimator), ``ml_errors``, ``mean_errors``,
      ``entropy``, ``angle_errors`` (n, T); ``estimates`` (n, T, P); ``actions`` (n, T, 2);
      ``classes`` (n, T);
    - ``thresholds`` (k,) px;
    - ``curves/M/X/C/S/``: ``rmse``, ``mean``, ``std``, ``q25``, ``median``, ``q75`` (T,) of the
      error; ``rmse_by_param`` (G, T); ``rmse_ml``, ``rmse_mean`` (T,) of each estimator;
      ``entropy_mean``, ``entropy_q25``, ``entropy_median``, ``entropy_q75`` (T,);
      ``samples_to_threshold`` (n_MXCS, k); ``median_samples``, ``reached`` (k,) and the same for
      each estimator (``median_samples_ml``, ``reached_ml``, ...);
    - ``pvalues/M/X/C/S/``: ``pvalue``, ``statistic`` (k,) of the tie-corrected Mann-Whitney U test
      of S against the baseline strategy of method X (``statistic``: ``P(S slower) - 1/2``, < 0 when
      S needed fewer observations), the same per estimator (``pvalue_ml``, ``statistic_ml``, ...),
      and ``min_pvalue``, the smallest p-value these sample sizes can give;
    - ``entropy/M/X/S/``: ``mean``, ``q25``, ``median``, ``q75`` (T,) over every category (Fig. 6);
    - ``examples/M/X/S/``: the example run's posterior snapshots (Fig. 5) and ``row``.

    ``attrs["methods"]`` holds every option each method resolved to (:func:`resolved_methods`).
    """
    n = len(tasks)
    missing = [i for i in range(n) if i not in results]
    if missing:
        raise ConfigError(f"{len(missing)} experiment(s) have no result (first: row {missing[0]})")
    table = _experiment_table(tasks, results, cfg.n_params)
    steps = {k: _stack(results, n, k) for k in STEP_KEYS}
    thr = np.asarray(cfg.thresholds, float)
    curves, pvalues, entropy, examples = _summaries(cfg, tasks, results, table, steps, thr)
    # Wall times (TIME_KEY) stay out of the artifact: they differ between identical runs.
    data = {"experiments": table, "steps": steps, "thresholds": thr, "curves": curves,
            "pvalues": pvalues, "entropy": entropy, "examples": examples}
    return Artifact(kind="evaluation", config=cfg.to_dict(), seed=cfg.seed, data=data,
                    attrs=_attrs(cfg, n, model_art), inputs={"model": ref(model_art)})


def _experiment_table(tasks: list[Task], results: dict[int, dict],
                      n_params: int) -> dict[str, np.ndarray]:
    """The ``experiments/`` group: one row per task (see :func:`assemble`)."""
    n = len(tasks)
    return {
        "mode": np.array([t.mode for t in tasks]),
        "category": np.array([t.category for t in tasks]),
        "method": np.array([t.method for t in tasks]),
        "strategy": np.array([t.strategy for t in tasks]),
        "param_index": np.array([t.param_index for t in tasks], np.int64),
        "rep": np.array([t.rep for t in tasks], np.int64),
        "seed_index": np.array([t.seed_index for t in tasks], np.int64),
        "steps_taken": np.array([results[i]["steps_taken"] for i in range(n)], np.int64),
        "stop_step": np.array([results[i].get("stop_step", -1) for i in range(n)], np.int64),
        "params": np.array([t.params for t in tasks], float).reshape(n, n_params),
        **_play_columns(tasks, results),
    }


def _play_columns(tasks: list[Task], results: dict[int, dict]) -> dict[str, np.ndarray]:
    """Playing success per row; the reference replays (before the displacement, unadapted),
    measured once per mode, parametrization and repetition, repeated on every row sharing them."""
    n = len(tasks)
    play = {k: np.array([float(results[i].get(k, np.nan)) for i in range(n)]) for k in PLAY_KEYS}
    refs = {(t.mode, t.category, t.param_index, t.rep): t.row for t in tasks if t.play_reference}
    for k in ("play_before", "play_unadapted"):
        src = play[k].copy()
        play[k] = np.array([src[refs[(t.mode, t.category, t.param_index, t.rep)]]
                            if (t.mode, t.category, t.param_index, t.rep) in refs else np.nan
                            for t in tasks])
    return play


def _summaries(cfg: EvaluateConfig, tasks: list[Task], results: dict[int, dict],
               table: dict[str, np.ndarray], steps: dict[str, np.ndarray],
               thr: np.ndarray) -> tuple[dict, dict, dict, dict]:
    """The ``curves/``, ``pvalues/``, ``entropy/`` and ``examples/`` groups, per mode and method."""
    curves: dict[str, Any] = {}
    pvalues: dict[str, Any] = {}
    entropy: dict[str, Any] = {}
    examples: dict[str, Any] = {}
    for m in cfg.modes:
        curves[m], pvalues[m], entropy[m], examples[m] = {}, {}, {}, {}
        for meth in cfg.methods:
            x = meth.name
            if not any(meth.runs_in(m, c.name) for c in cfg.categories):
                continue
            rows = (table["mode"] == m) & (table["method"] == x)
            strategy = table["strategy"]
            entropy[m][x] = {s: stats.entropy_curves(steps["entropy"][rows & (strategy == s)])
                             for s in meth.strategies}
            curves[m][x], pvalues[m][x] = {}, {}
            for c in cfg.categories:
                if meth.runs_in(m, c.name):
                    in_c = rows & (table["category"] == c.name)
                    curves[m][x][c.name], pvalues[m][x][c.name] = _category(
                        cfg, meth.strategies, in_c, table, steps, thr)
            examples[m][x] = {t.strategy: {"row": np.int64(t.row),
                                           **results[t.row].get("extra", {})}
                              for t in tasks if t.example and t.mode == m and t.method == x}
    return curves, pvalues, entropy, examples


def _category(cfg: EvaluateConfig, strategies: tuple[str, ...], in_c: np.ndarray,
              table: dict[str, np.ndarray], steps: dict[str, np.ndarray],
              thr: np.ndarray) -> tuple[dict, dict]:
    """Curves per strategy and tests against the baseline, for the rows ``in_c`` (one mode,
    method and category)."""
    curves: dict[str, dict] = {}
    counts: dict[str, dict[str, np.ndarray]] = {sfx: {} for sfx in ERRORS}
    for s in strategies:
        sel = in_c & (table["strategy"] == s)
        curves[s], by_estimator = _curves(steps, sel, table["param_index"], thr, cfg.max_steps)
        curves[s]["play_adapted"] = table["play_adapted"][sel]
        for sfx, cnt in by_estimator.items():
            counts[sfx][s] = cnt
    return curves, _pvalues(counts, cfg.baseline)


def _curves(steps: dict[str, np.ndarray], sel: np.ndarray, param_index: np.ndarray,
            thr: np.ndarray, T: int) -> tuple[dict, dict[str, np.ndarray]]:
    """One strategy's curves (see :func:`assemble`) and its observations to each threshold per
    estimator (``""``: the method's, ``"_ml"``, ``"_mean"``)."""
    cur = stats.curves(steps["errors"][sel], param_index[sel])
    cur["rmse_by_param"] = cur.pop("rmse_by_group")
    ent = stats.entropy_curves(steps["entropy"][sel])
    cur.update({f"entropy_{k}": v for k, v in ent.items()})
    counts = {}
    for sfx, key in ERRORS.items():
        e = steps[key][sel]
        if sfx:
            cur[f"rmse{sfx}"] = stats.rmse_curve(e)
        counts[sfx] = stats.samples_to_threshold(np.nan_to_num(e, nan=np.inf), thr)
        cur[f"median_samples{sfx}"] = stats.median_samples(counts[sfx], T)
        cur[f"reached{sfx}"] = stats.reached(counts[sfx], T)
    cur["samples_to_threshold"] = counts[""]
    return cur, counts


def _pvalues(counts: dict[str, dict[str, np.ndarray]], baseline: str) -> dict[str, dict]:
    """Each strategy's tests against the baseline, the method's estimator's (``pvalue``,
    ``statistic``, ``min_pvalue``) then each other estimator's (``pvalue_ml``, ...)."""
    out: dict[str, dict] = {}
    for sfx, by_strategy in counts.items():
        for s, res in _tests(by_strategy, baseline).items():
            entry = out.setdefault(s, {})
            if sfx:
                entry[f"pvalue{sfx}"] = res["pvalue"]
                entry[f"statistic{sfx}"] = res["statistic"]
            else:
                entry.update(res)
    return out


def _attrs(cfg: EvaluateConfig, n: int, model_art: Artifact) -> dict:
    return {
        "n_experiments": n,
        "modes": list(cfg.modes),
        "categories": [c.name for c in cfg.categories],
        "methods": resolved_methods(cfg, _load_model(model_art)),
        "method_order": [m.name for m in cfg.methods],
        "judged": cfg.judged,
        "strategies": list(cfg.strategies),
        "baseline": cfg.baseline,
        "max_steps": cfg.max_steps,
        "play_notes": cfg.play_notes,
        "melody": cfg.melody,
        "model_strategy": model_art.config.get("strategy"),
    }


def _load_model(model_art: Artifact):
    """The model stored in ``model_art``."""
    from kbcli.stages.models import load_model

    return load_model(model_art)



def resummarise(art: Artifact, rows: np.ndarray | None = None, *, error_scale: float = 1.0,
                only: tuple[str, str] | None = None) -> Artifact:
    """The evaluation ``art`` with its summaries (``curves/``, ``pvalues/``, ``entropy/``)
    recomputed from its per-run records, as :func:`assemble` computes them.

    ``rows`` (n,): the experiment rows to summarise, in order, repeats allowed (a bootstrap
    resample; default every row); every per-step error is first multiplied by ``error_scale``
    (1 / sqrt(2) reads each run's RMSE over the two coordinates); ``only=(mode, method)``
    summarises those alone (``rows`` then holds only theirs). Returns an in-memory artifact (no
    sha256) without example runs; ConfigError when the artifact lacks the per-run records.
    """
    cfg = EvaluateConfig.from_dict(art.config)
    if only is not None:
        cfg = cfg.with_overrides(mode=only[0], methods=(only[1],))
    exp, steps = art.data["experiments"], art.data.get("steps", {})
    missing = [k for k in ("errors", "entropy") if k not in steps]
    if missing:
        raise ConfigError(f"{art.path or 'the evaluation'} has no per-run {missing[0]!r}")
    idx = np.arange(len(exp["mode"])) if rows is None else np.asarray(rows, np.int64)
    table = {k: np.asarray(v)[idx] for k, v in exp.items()}
    st = {k: np.asarray(v)[idx] for k, v in steps.items()}
    for k in ERRORS.values():
        st[k] = st[k] * error_scale if k in st else np.full(st["errors"].shape, np.nan)
    curves, pvalues, entropy, _ = _summaries(cfg, [], {}, table, st, art.array("thresholds"))
    data = {**art.data, "experiments": table, "steps": st, "curves": curves,
            "pvalues": pvalues, "entropy": entropy, "examples": {}}
    return Artifact(kind=art.kind, config=art.config, seed=art.seed, data=data,
                    attrs=art.attrs, inputs=art.inputs, schema_version=art.schema_version,
                    kbcli_version=art.kbcli_version, path=art.path)
