"""The adapt stage itself: :func:`run` adapts to a scene artifact with a model artifact and returns
a ``run`` artifact (:func:`check_inputs` refuses mismatched inputs)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.errors import ArtifactError, KbcliError
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.adapt.config import DEFAULT_SNAPSHOTS, AdaptConfig
from kbcli.stages.adapt.loop import experiment
from kbcli.stages.adapt.record import run_attrs, run_data
from kbcli.stages.artifact import Artifact, ref
from kbcli.stages.models import load_model


def _inside_prior(cfg: AdaptConfig, truth: np.ndarray, world_family: str) -> bool:
    """Whether the true pose lies in the robot's prior box (else no estimate can reach it)."""
    inside = bool(np.all(np.abs(truth[-2:]) <= cfg.robot.prior_halfwidth))
    angle = transforms.FAMILIES.get(world_family).angle(truth)
    limit = cfg.robot.max_angle if transforms.FAMILIES.get(cfg.robot.family).rotates else 0.0
    return inside and abs(angle) <= limit + 1e-9

def _resolved(kb: dict | None) -> dict | None:
    """A keyboard table with every default filled in (schema 1 tables lack ``layout``)."""
    if kb is None:
        return None
    try:
        return KeyboardConfig.from_dict(kb).to_dict()
    except KbcliError:
        return kb


def check_inputs(model_artifact: Artifact, scene_artifact: Artifact) -> None:
    """Refuse artifacts of the wrong kind and a scene whose keyboard is not the model's."""
    if model_artifact.kind != "model":
        raise ArtifactError(f"{model_artifact.path or 'model'}: is a {model_artifact.kind} "
                            f"artifact, expected model")
    if scene_artifact.kind != "scene":
        raise ArtifactError(f"{scene_artifact.path or 'scene'}: is a {scene_artifact.kind} "
                            f"artifact, expected scene")
    km, ks = (_resolved(a.config.get("keyboard")) for a in (model_artifact, scene_artifact))
    if km != ks:
        diff = sorted(k for k in set(km or {}) | set(ks or {})
                      if (km or {}).get(k) != (ks or {}).get(k))
        raise KbcliError(f"the scene's keyboard does not match the model's (differs in "
                         f"{', '.join(diff) or 'everything'}): perturb the keyboard the model "
                         f"was learned on")


def run(cfg: AdaptConfig, model_artifact: Artifact, scene_artifact: Artifact, *,
        rng: np.random.Generator, seed: int | None = None,
        snapshot_steps: tuple[int, ...] = DEFAULT_SNAPSHOTS, model=None,
        on_step: Callable[[int], None] | None = None,
        timings: dict[str, float] | None = None, keep: dict | None = None) -> Artifact:
    """Adapt to a scene with a model: the ``run`` artifact.

    ``seed`` is recorded (``rng`` should be ``default_rng(seed)``); ``model``: the already loaded
    model of ``model_artifact``; ``timings`` receives ``setup_ms``, from the model artifact to the
    adapter ready (loading included); ``on_step`` and ``keep`` as in
    :func:`~kbcli.stages.adapt.experiment`. ArtifactError or KbcliError for wrong kinds or
    mismatching keyboards.
    """
    check_inputs(model_artifact, scene_artifact)
    t0 = time.perf_counter()
    model = load_model(model_artifact) if model is None else model
    load_ms = 1e3 * (time.perf_counter() - t0)
    kb = keyboard_stage.load(scene_artifact)
    world_family = scene_artifact.config["family"]
    truth = np.asarray(scene_artifact.config["params"], float)
    res = experiment(cfg, model, kb, truth, rng=rng, world_family=world_family,
                     snapshot_steps=snapshot_steps, on_step=on_step, timings=timings, keep=keep)
    if timings is not None:
        timings["setup_ms"] = timings.get("setup_ms", 0.0) + load_ms
    attrs = run_attrs(res, cfg.adapter_config(), truth=truth, world_family=world_family)
    attrs["truth_inside_prior"] = _inside_prior(cfg, truth, world_family)
    sim = cfg.sim_config()
    attrs["mode"] = cfg.mode
    attrs["arm"] = {"base": list(sim.base), "link_lengths": list(sim.link_lengths)}
    return Artifact(
        kind="run",
        config={"adapt": cfg.to_dict(), "keyboard": model_artifact.config["keyboard"],
                "snapshot_steps": [int(s) for s in snapshot_steps]},
        seed=seed,
        data=run_data(res),
        attrs=attrs,
        inputs={"model": ref(model_artifact), "scene": ref(scene_artifact)},
    )
