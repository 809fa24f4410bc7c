"""Stage ``evaluate``: the paper's evaluation protocol (Sect. IV-B and IV-C, Figs. 5-7), run for
named *methods*.

A **method** is a named table of adapt options plus the strategies it compares
(``[evaluate.methods.NAME]`` in ``pipelines/paper.toml``): ``paper``, the paper's own method (the
KDE posterior of Eq. 7-8, the maximum-likelihood estimate, the model as learned, strategies
``random`` and ``active``); ``kbcli``, whatever :class:`kbcli.core.adaptation.loop.AdapterConfig`'s
defaults are, strategies random, active and infogain; any other name, an ablation. Every option a
method resolves to (defaults included, per mode and strategy) is recorded in the artifact
(``attrs["methods"]``).

Fixed displacement parametrizations are grouped in size categories (:mod:`kbcli.stages.perturb`).
Each is adapted to ``experiments`` times (the paper: 50) by each method and strategy in each mode
(``ideal`` or ``dynamics``). One experiment is one call of the adapt stage's ``experiment`` for
``max_steps`` observations, which also measures the playing success (Algorithm 1, ``play_notes``
touches) after adapting and, once per (mode, parametrization, repetition), before the displacement
and after it without adaptation. Each experiment is seeded by
``SeedSequence(seed, spawn_key=...)`` from its mode, category, parametrization, method, strategy
and repetition, so a result depends neither on the worker nor on which modes or methods were
selected.

The ``evaluation`` artifact (:func:`assemble`) holds RMSE per step (Fig. 7), observations to each
error threshold, Mann-Whitney U p-values against the method's baseline strategy, entropy per step
(Fig. 6), playing success and one example run's posterior snapshots (Fig. 5).
"""

from __future__ import annotations

from kbcli.stages.artifact import Artifact
from kbcli.stages.evaluate.assembly import assemble
from kbcli.stages.evaluate.categories import Category, _paper_categories
from kbcli.stages.evaluate.config import EvaluateConfig, adapt_config, resolved_methods
from kbcli.stages.evaluate.methods import (
    DEFAULT_STRATEGIES,
    KBCLI_METHOD,
    METHOD_KEYS,
    PAPER_METHOD,
    PER_EXPERIMENT,
    Method,
    known_strategies,
)
from kbcli.stages.evaluate.planning import EXPERIMENT, Task, context, context_key, plan
from kbcli.stages.evaluate.worker import (
    EXAMPLE_KEYS,
    PLAY_KEYS,
    PLAY_POOL,
    STEP_KEYS,
    TIME_KEY,
    resolve,
    run_experiment,
    setup,
    timing,
)


def fingerprint(cfg: EvaluateConfig, model_art: Artifact, experiment: str = EXPERIMENT) -> dict:
    """What a checkpoint must match to be resumed: the config, the model and the code version."""
    from kbcli import __version__

    return {
        "evaluate": cfg.to_dict(),
        "model_sha256": model_art.sha256,
        "experiment": experiment,
        "kbcli_version": __version__,
        "n_experiments": len(plan(cfg)),
    }


def run(cfg: EvaluateConfig, model_art: Artifact, experiment: str = EXPERIMENT) -> Artifact:
    """Run the whole protocol in this process, one experiment after another, and return the
    artifact (the CLI runs the same functions through :mod:`kbcli.io.runner` instead, for parallel
    backends and checkpoints)."""
    tasks = plan(cfg)
    state = setup(context(cfg, model_art, experiment))
    results = {t.row: run_experiment(state, t) for t in tasks}
    return assemble(cfg, tasks, results, model_art, state["keyboard"])


__all__ = ["EXPERIMENT", "DEFAULT_STRATEGIES", "PER_EXPERIMENT", "METHOD_KEYS", "EXAMPLE_KEYS",
           "STEP_KEYS", "PLAY_KEYS", "PLAY_POOL", "TIME_KEY", "PAPER_METHOD", "KBCLI_METHOD",
           "Category", "Method", "EvaluateConfig", "Task", "known_strategies", "adapt_config",
           "resolved_methods", "plan", "context", "context_key", "resolve", "setup",
           "run_experiment", "assemble", "timing", "fingerprint", "run", "_paper_categories"]
