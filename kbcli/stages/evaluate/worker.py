"""The worker's side of the evaluation: per-process state (:func:`setup`) and one experiment
(:func:`run_experiment`), whose outputs are padded to ``max_steps`` for the artifact."""

from __future__ import annotations

from typing import Any

import numpy as np

from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.errors import ConfigError
from kbcli.stages.evaluate.config import EvaluateConfig, adapt_config
from kbcli.stages.evaluate.methods import adapt_stage
from kbcli.stages.evaluate.planning import Task, _key

#: What an example run keeps beyond its per-step arrays (Fig. 5).
EXAMPLE_KEYS = ("snapshots", "snapshot_steps", "snapshot_angles", "dx", "dy", "angles")
#: Per-step outputs of an experiment kept for every run, each (T, ...): ``errors`` are those of the
#: method's estimator; ``ml_errors`` and ``mean_errors`` those of both estimates (for the
#: estimator ablation, from the same runs); ``ml_prob`` and ``mass`` what the paper's stopping
#: rule and ours read; ``truth_logratio`` the log of the posterior at the truth over its maximum.
STEP_KEYS = ("errors", "ml_errors", "mean_errors", "entropy", "estimates", "actions", "classes",
             "angle_errors", "ml_prob", "mass", "truth_logratio")
#: Per-step outputs an experiment function may leave out (NaN in the artifact): the stopping
#: rules' readings (``ml_prob``, ``mass``) and the truth's place in the posterior
#: (``truth_logratio``), recorded since issue 39.
OPTIONAL_STEP_KEYS = ("ml_errors", "mean_errors", "ml_prob", "mass", "truth_logratio")
#: Playing success per experiment (floats, NaN when not measured).
PLAY_KEYS = ("play_before", "play_unadapted", "play_adapted")
#: Draws of p(action | sound) per melody class that the replays resample (drawn once per process
#: from a seed of their own, so every process resamples the same pool).
PLAY_POOL = 10000
#: Key of the wall-clock time per step; kept out of the artifact (it differs between runs).
TIME_KEY = "step_ms"


def resolve(name: str) -> Any:
    """The module-level object named ``"package.module:attribute"`` (picklable by reference)."""
    import importlib

    module, _, attr = name.partition(":")
    if not module or not attr:
        raise ConfigError(f"function name {name!r} must look like 'package.module:function'")
    return getattr(importlib.import_module(module), attr)


def setup(ctx: dict) -> dict:
    """Per-process state: the model, the keyboard, the config and the experiment function."""
    from kbcli.stages import keyboard as keyboard_stage
    from kbcli.stages.models import load_model

    art = ctx["model"]
    return {
        "model": load_model(art),
        "keyboard": keyboard_stage.load(art),
        "cfg": EvaluateConfig.from_dict(ctx["evaluate"]),
        "experiment": resolve(ctx["experiment"]),
        "tables": {},
        "samples": {},
    }


def run_experiment(state: dict, task: Task) -> dict[str, np.ndarray]:
    """Run one experiment; returns its per-step arrays (padded to ``max_steps``), its playing
    success, its wall time per step, and (for the example runs only) everything else it returned
    (posterior snapshots)."""
    cfg: EvaluateConfig = state["cfg"]
    acfg = adapt_config(cfg, task.method, task.strategy, task.mode)
    rng = np.random.default_rng(task.seed)
    kw: dict[str, Any] = {
        "table": _table(state, acfg),
        "snapshot_steps": cfg.snapshot_steps if task.example else (),
    }
    samples = _samples(state, acfg, cfg.seed)
    if samples is not None:
        kw["samples"] = samples
    adapt = adapt_stage()
    if cfg.play_notes > 0 and adapt is not None and hasattr(adapt, "PlayCheck"):
        kw["play"] = adapt.PlayCheck(melody=cfg.melody, notes=cfg.play_notes,
                                     reference=task.play_reference)
        if task.play_reference:  # a seed of their own: the same whichever task runs them
            kw["reference_rng"] = np.random.default_rng(task.reference_seed)
        if "play_pool" not in state:  # Algorithm 1's actions: a pool per class, resampled
            from kbcli.core.adaptation.posteriors.kde.samples import ActionSamples

            state["play_pool"] = ActionSamples(state["model"], PLAY_POOL, [cfg.seed, _key("play")])
        kw["play_pool"] = state["play_pool"]
    truth = np.asarray(task.params, float)
    out = state["experiment"](acfg, state["model"], state["keyboard"], truth, rng=rng, **kw)
    out = dict(out)
    if "stop" in out:  # the first step at which the method's stopping rule held (0: never)
        hit = np.flatnonzero(np.asarray(out["stop"], bool))
        out["stop_step"] = int(hit[0]) + 1 if len(hit) else 0
    if "means" in out:  # both estimates' errors, whichever the method reports
        out["mean_errors"] = np.hypot(*(np.asarray(out["means"])[:, -2:] - truth[-2:]).T)
        est = ESTIMATORS.get(acfg.estimator.name)
        out["estimates"] = out[est.record]  # "errors" are those of the method's estimator
    return _normalise(out, cfg.max_steps, cfg.n_params, keep_extra=task.example)


def _table(state: dict, acfg):
    """The model raster for ``acfg``, built once per process and shared by every experiment that
    rasterises the same way (it depends on the robot's settings, not on the strategy)."""
    adapt = adapt_stage()
    if acfg is None or adapt is None:
        return None
    key = acfg.adapter_config().replace(strategy="random")
    if key not in state["tables"]:
        state["tables"][key] = adapt.build_shared_table(acfg, state["model"])
    return state["tables"][key]


def _samples(state: dict, acfg, seed: int):
    """The KDE posterior's per-class samples, shared by every experiment of the process with the
    same sampling settings; drawn from ``SeedSequence([seed, cls])`` once per class, so every
    process draws the same ones (None for other posteriors)."""
    adapt = adapt_stage()
    if acfg is None or adapt is None:
        return None
    r = acfg.adapter_config()
    key = r.kind.sample_key(r)  # None: no samples shared (or drawn anew at every touch)
    if key is None:
        return None
    if key not in state["samples"]:
        state["samples"][key] = adapt.build_shared_samples(acfg, state["model"], [seed],
                                                           table=_table(state, acfg))
    return state["samples"][key]


def _pad(a: np.ndarray, length: int) -> np.ndarray:
    if len(a) >= length:
        return a[:length]
    if len(a) == 0:
        return np.full((length,) + a.shape[1:], np.nan)
    return np.concatenate([a, np.repeat(a[-1:], length - len(a), axis=0)])


def _normalise(out: dict, steps: int, n_params: int, keep_extra: bool) -> dict[str, np.ndarray]:
    res: dict[str, Any] = {}
    taken = len(np.asarray(out["errors"]))
    res["steps_taken"] = np.int64(taken)
    res["stop_step"] = np.int64(out.get("stop_step", -1))
    shapes = {"estimates": (n_params,), "actions": (2,)}
    for k in STEP_KEYS:
        if k in out:
            a = np.asarray(out[k])
            a = a.astype(np.int64) if k == "classes" else a.astype(np.float64)
            res[k] = _pad(a.reshape((len(a),) + shapes.get(k, ())), steps)
        elif k == "angle_errors":
            res[k] = np.zeros(steps)
        elif k in OPTIONAL_STEP_KEYS:
            res[k] = np.full(steps, np.nan)
        else:
            raise KeyError(f"the experiment returned no {k!r}")
    for k in PLAY_KEYS:
        res[k] = np.float64(out.get(k, np.nan))
    res[TIME_KEY] = np.asarray(out.get(TIME_KEY, np.zeros(taken)), np.float64)
    if keep_extra:
        extra = {k: np.asarray(v) for k, v in out.items() if k in EXAMPLE_KEYS}
        if extra:
            res["extra"] = extra
    return res


def timing(results: dict[int, dict]) -> np.ndarray:
    """All per-step wall times (ms) of ``results``, for the CLI's summary."""
    parts = [np.ravel(r[TIME_KEY]) for r in results.values() if TIME_KEY in r]
    return np.concatenate(parts) if parts else np.zeros(0)
