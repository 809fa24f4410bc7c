"""The robot keeps what it learned: a model artifact repaired by adaptations' touches.

``kbcli adapt --repair --model-out`` and ``kbcli run --repair --model-out`` write, beside their run,
the input model refitted (:func:`kbcli.core.adaptation.repair.absorb`) with its adaptations'
touches, mapped back by each adaptation's estimate, then calibrated and self-assessed again
(:func:`kbcli.core.model.reliability.assess`); an adaptation whose 90 % credible disc is wider than
``absorb_radius`` px gives nothing, and a generation that absorbed nothing keeps its parent's model
as it was (not refitted nor calibrated anew, so that it adapts exactly as its parent). Its
``inputs`` hold its ``parent`` (recursively) and its attrs ``lineage`` every generation (parent
sha256, touches absorbed, shift, credible radius); a model ``kbcli learn`` writes is generation 0.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from kbcli.core.adaptation.credible import LEVEL, radius, radius_of
from kbcli.core.adaptation.repair import absorb
from kbcli.core.model import accuracy as scoring
from kbcli.core.model import reliability
from kbcli.core.playing.loop import ADAPT
from kbcli.errors import ConfigError
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import Artifact, ref

#: An adaptation whose 90 % credible disc is wider than this (px) is not absorbed.
ABSORB_RADIUS = 3.0
#: Grid (px) of the repaired model's accuracy and boundary error (``kbcli learn``'s).
EVAL_STEP = 1.0
#: Spawn key of the generator of the repaired model's cross-validation folds.
REPAIR_KEY = 42


@dataclass(frozen=True)
class Adaptation:
    """The touches of one adaptation and what it concluded: where each touch aimed and was felt
    to land (n, 2), what it heard (n, D; NaN rows: silence), its class (n,; -1: unknown, never
    absorbed), the estimated translation ``shift`` (2,) and its 90 % credible ``radius`` (px)."""

    aims: np.ndarray
    felt: np.ndarray
    perceived: np.ndarray
    classes: np.ndarray
    shift: np.ndarray
    radius: float

    @classmethod
    def of_adapter(cls, adapter, aims: np.ndarray, perceived: np.ndarray) -> Adaptation:
        """What an :class:`~kbcli.core.adaptation.adapter.Adapter` with ``repair`` concluded (its touches in
        observation order, with the ``aims`` and ``perceived`` features of the touches it
        absorbed)."""
        t = adapter.repair.touches
        est = adapter.estimate()
        return cls(np.asarray(aims, float).reshape(-1, 2), t.points, np.asarray(perceived, float),
                   t.classes, np.asarray(est, float)[-2:], radius(adapter.posterior, est, LEVEL))


def run_adaptation(adapter, run: Artifact | dict) -> Adaptation:
    """The :class:`Adaptation` of ``kbcli adapt``: its adapter at the end and its ``run`` artifact
    (or :func:`~kbcli.stages.adapt.experiment`'s records), whose touches of a known sound are the
    ones the adapter absorbed."""
    data = run.data if isinstance(run, Artifact) else run
    known = np.asarray(data["classes"]) >= 0
    return Adaptation.of_adapter(adapter, np.asarray(data["actions"], float)[known],
                                 np.asarray(data["perceived"], float)[known])


def session_adaptations(steps, model) -> list[Adaptation]:
    """The adaptations of a closed-loop session (``kbcli run``: its
    :class:`~kbcli.core.playing.loop.LoopStep` records), each a run of consecutive adaptation touches
    ending in its estimate (the correction in force after it) and its posterior's credible
    radius; touches classified by ``model``."""
    out, block = [], []
    for s in [*steps, None]:
        if s is not None and s.phase == ADAPT:
            block.append(s)
            continue
        if block:
            last = block[-1]
            heard = np.array([b.perceived for b in block], float)
            dx, dy, logp = last.marginal
            shift = np.asarray(last.correction, float)[-2:]
            out.append(Adaptation(np.array([b.action for b in block], float),
                                  np.array([b.landed for b in block], float), heard,
                                  np.asarray(model.classify(heard), np.int64), shift,
                                  radius_of(dx, dy, np.exp(np.asarray(logp, float)), shift,
                                            LEVEL)))
            block = []
    return out


def absorbed(kept: list[Adaptation], d: int) -> tuple[np.ndarray, ...]:
    """The touches of known sounds of the ``kept`` adaptations, mapped back into the model's
    reference frame by each one's estimate: felt (n, 2), aims (n, 2), heard (n, d), classes
    (n,)."""
    parts = [(a, a.classes >= 0) for a in kept]
    felt = np.vstack([np.empty((0, 2))] + [a.felt[k] - a.shift for a, k in parts])
    aims = np.vstack([np.empty((0, 2))] + [a.aims[k] - a.shift for a, k in parts])
    heard = np.vstack([np.empty((0, d))] + [a.perceived[k] for a, k in parts])
    classes = np.concatenate([np.empty(0, np.int64)] + [a.classes[k] for a, k in parts])
    return felt, aims, heard, classes


def generation(parent: Artifact, adaptations: list[Adaptation], kept: list[Adaptation],
               absorbed: int, source: str, absorb_radius: float) -> dict:
    """The lineage entry of one repair: the parent's sha256 and file, the touches absorbed, the
    adaptations (and the skipped ones), the shifts the kept ones were mapped back by, every
    adaptation's credible radius and the radius they were kept under."""
    return {"parent_sha256": parent.sha256, "parent_file": ref(parent)["file"],
            "source": source, "absorbed": int(absorbed),
            "adaptations": len(adaptations), "skipped": len(adaptations) - len(kept),
            "shifts": [[float(v) for v in a.shift] for a in kept],
            "credible_radius_90": [float(a.radius) for a in adaptations],
            "absorb_radius": float(absorb_radius)}


def repaired_model(parent: Artifact, model, adaptations: list[Adaptation], *,
                   source: str, absorb_radius: float = ABSORB_RADIUS) -> tuple[Artifact, dict]:
    """The repaired model artifact, and a summary (touches absorbed, adaptations skipped).

    ``model`` is the loaded learned model of ``parent``; ``adaptations`` in the order they
    happened; ``source`` (``adapt`` or ``run``) is recorded. ConfigError for the exact model.
    """
    if not hasattr(model, "actions_"):
        raise ConfigError("the exact model has nothing to repair: --model-out needs a learned "
                          "model")
    kept = [a for a in adaptations if a.radius <= absorb_radius]
    felt, aims, heard, classes = absorbed(kept, np.asarray(model.class_features_).shape[1])
    data = copy.deepcopy(parent.data)
    if len(classes):
        fitted = absorb(model, felt, classes, np.zeros(2))
        rng = np.random.default_rng(np.random.SeedSequence(0, spawn_key=(REPAIR_KEY,)))
        feats = np.asarray(fitted.class_features_, float)[fitted.labels_]
        calibrated, rel = reliability.assess(fitted, fitted.actions_, feats, rng=rng)
        rel_dict = rel.to_dict()
        samples = data.get("samples", {})
        for key, extra in (("actions", aims), ("landed", felt), ("perceived", heard)):
            if key in samples:
                samples[key] = np.vstack([np.asarray(samples[key], float), extra])
        samples.pop("start_angles", None)  # an absorbed touch has no start pose of the learning arm
        data["model"] = calibrated.to_arrays()
    else:  # nothing absorbed: the parent's model as it was, not refitted nor calibrated anew
        calibrated, rel_dict = model, parent.attrs.get("reliability")
    kb = keyboard_stage.load(parent)
    pred, true = scoring.key_maps(calibrated, kb, EVAL_STEP)
    acc = scoring.accuracy_from_maps(pred, true)
    berr = scoring.boundary_error(pred, true, EVAL_STEP)
    lineage = [*list(parent.attrs.get("lineage") or []),
               generation(parent, adaptations, kept, len(classes), source, absorb_radius)]
    data["evaluation"] = {**data.get("evaluation", {}), "predicted_keys": pred.astype(np.int16)}
    attrs = {**parent.attrs, "accuracy": acc, "boundary_error_px": berr,
             "n_reaches": int(parent.attrs.get("n_reaches", 0)) + int(len(classes)),
             "reliability": rel_dict, "lineage": lineage,
             "generation": len(lineage), "absorbed_touches": int(len(classes))}
    if rel_dict is None:
        attrs.pop("reliability")
    inputs = {"keyboard": parent.inputs.get("keyboard"), "parent": ref(parent)}
    art = Artifact(kind="model", config=copy.deepcopy(parent.config), seed=parent.seed, data=data,
                   attrs=attrs, inputs={k: v for k, v in inputs.items() if v is not None})
    summary = {"absorbed": int(len(classes)), "skipped": len(adaptations) - len(kept),
               "accuracy": acc, "boundary_error_px": berr,
               "parent_boundary_error_px": parent.attrs.get("boundary_error_px"),
               "generation": len(lineage)}
    return art, summary
