"""Rules across the entries of an artifact (``check(artifact) -> message or None``) and the
predicates that say which datasets an artifact must hold (``when(artifact) -> bool``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from kbcli.core.model import classes as model_classes
from kbcli.core.model.classes import MODEL_CLASSES
from kbcli.errors import KbcliError
from kbcli.io.schema.spec import MIN_SOUNDS, TYPES

# -- which artifacts hold what ---------------------------------------------------------------------

def learned(art) -> bool:
    """A learned model (not the exact model of the keyboard), as its model class says; a class
    this kbcli does not know is checked as learned (its arrays are then named unknown)."""
    name = model_class_of(art)
    return name not in MODEL_CLASSES or MODEL_CLASSES.get(name).learned


def model_class_of(art) -> str:
    """The model class a model artifact names (:func:`kbcli.core.model.classes.model_class_of`)."""
    return model_classes.model_class_of(art.config)


def of_class(name: str) -> Callable[[Any], bool]:
    """``when`` predicate: a learned model of model class ``name``."""
    def when(art) -> bool:
        return learned(art) and model_class_of(art) == name

    when.__name__ = f"of_class_{name}"
    return when


def has_posterior(art) -> bool:
    """A closed loop that recorded its adaptation posteriors."""
    return "posterior" in art.data


def methods(art) -> list[str]:
    """The evaluation's method names, in their stored order."""
    a = art.attrs
    order = a.get("method_order")
    return [str(m) for m in (order if isinstance(order, list) else a.get("methods") or [])]


def n_keys(art) -> int | None:
    """Number of keys of the artifact's keyboard (from its config), if it can be built."""
    try:
        from kbcli.stages import keyboard as keyboard_stage

        return keyboard_stage.load(art).n_keys
    except Exception:  # noqa: BLE001 - a broken keyboard config is reported by its own reader
        return None


# -- rules -----------------------------------------------------------------------------------------

def keyboard(art) -> str | None:
    """The artifact's keyboard config must build a keyboard (every stage rebuilds it)."""
    from kbcli.stages import keyboard as keyboard_stage

    try:
        keyboard_stage.load(art)
    except KbcliError as exc:
        return f"its keyboard config is invalid ({exc})"
    except (TypeError, ValueError, KeyError, AttributeError, OverflowError) as exc:
        return f"its keyboard config is malformed ({type(exc).__name__}: {exc})"
    return None


def model_class(art) -> str | None:
    """A learned model names a registered model class."""
    if not learned(art):
        return None
    from kbcli.core.model.classes import MODEL_CLASSES

    name = model_class_of(art)
    if name not in MODEL_CLASSES:
        return (f"config model_class {name!r} is not one of {', '.join(MODEL_CLASSES)}; you may "
                f"need to update kbcli")
    return None


def outlines(art) -> str | None:
    """The keys' outlines: offsets from 0 to the number of vertices, one more than the keys."""
    off = np.asarray(art.data["outlines"]["offsets"])
    n = len(np.asarray(art.data["features"]))
    n_vert = len(np.asarray(art.data["outlines"]["vertices"]))
    if len(off) != n + 1 or off[0] != 0 or off[-1] != n_vert or (np.diff(off) < 3).any():
        return (f"outlines/offsets must run from 0 to {n_vert} in {n + 1} steps of at least 3 "
                "vertices (one outline per key)")
    return None


def two_sounds(art) -> str | None:
    """A model must tell at least two sounds apart (besides silence) to be of any use."""
    if not learned(art):
        return None
    n = int(np.asarray(art.data["model"]["class_features"]).shape[0]) - 1
    if n < MIN_SOUNDS:
        return (f"the model knows {n} sound class(es) besides silence, fewer than the "
                f"{MIN_SOUNDS} needed "
                f"to find the keyboard: learn it again with a larger --budget")
    return None


def reliability(art) -> str | None:
    """A learned model of schema 2 carries its own estimate of how good it is."""
    if not learned(art):
        return None
    rel = art.attrs.get("reliability")
    if not isinstance(rel, dict):
        return "summary attribute 'reliability' is missing or not a table"
    for key in ("cv_error", "cv_log_loss", "cv_ece", "boundary_error"):
        if not TYPES["num"](rel.get(key)):
            return f"summary attribute reliability.{key} must be a number, got {rel.get(key)!r:.40}"
    if "expected_error" in rel and not TYPES["num"](rel["expected_error"]):  # (since kbcli 2026-12)
        return (f"summary attribute reliability.expected_error must be a number, got "
                f"{rel['expected_error']!r:.40}")
    if not TYPES["numdict"](rel.get("calibration", {})):
        return "summary attribute reliability.calibration must be a table of numbers"
    return None


def scene_params(art) -> str | None:
    """A scene's parameters fit its transform family (an angle in (-180, 180] if it rotates)."""
    from kbcli.core.instrument.transforms import FAMILIES

    fam = art.config["family"]
    if fam not in FAMILIES:
        return f"config family {fam!r} is not one of {', '.join(FAMILIES)}"
    family = FAMILIES.get(fam)
    p = art.config["params"]
    if len(p) != family.size or not all(math.isfinite(v) for v in p):
        return (f"config params must be {family.size} finite numbers "
                f"({', '.join(family.params)}) for a {fam} scene, got {p!r}")
    if family.rotates and not -180.0 < p[0] <= 180.0:
        return f"the scene's angle {p[0]:g} is outside (-180, 180] degrees: make it again with kbcli perturb"
    return None


def scene_agrees(art) -> str | None:
    """A scene's stored ``params`` dataset and its ``pose`` are the config's parameters (the world
    reads the config; a file where they disagree was edited by hand)."""
    want = np.asarray(art.config["params"], float)
    got = np.asarray(art.data.get("params", want), float).reshape(-1)
    if got.shape != want.shape or not np.array_equal(got, want):
        return (f"dataset 'params' {_short(got)} disagrees with config params {_short(want)}")
    pose = art.attrs.get("pose")
    if isinstance(pose, dict) and TYPES["numdict"](pose) and not np.array_equal(
            np.asarray(list(pose.values()), float), want):
        return f"summary attribute 'pose' {pose} disagrees with config params {_short(want)}"
    return None


def _short(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:g}" for x in np.asarray(v, float).reshape(-1)[:6]) + "]"


def truth_keys(art) -> str | None:
    """A ground truth names every parameter of the world's transform family."""
    from kbcli.core.instrument.transforms import FAMILIES, family_for

    truth = art.attrs.get("truth")
    if not truth:
        return None
    fam = art.attrs.get("world_family") or art.attrs.get("family") or "translation"
    if art.kind == "closed_loop":  # its truth names its family's parameters
        try:
            fam = family_for(truth).name
        except KbcliError as exc:
            return f"summary attribute 'truth': {exc}"
    if fam not in FAMILIES:
        return f"summary attribute world_family {fam!r} is not one of {', '.join(FAMILIES)}"
    missing = [k for k in FAMILIES.get(fam).params if k not in truth]
    if missing:
        return f"summary attribute 'truth' lacks {', '.join(missing)} of a {fam} move"
    return None


def arm(art) -> str | None:
    """The arm's geometry, when recorded: a base point and two link lengths."""
    geo = art.attrs.get("arm")
    if geo is None:
        return None
    for key in ("base", "link_lengths"):
        v = geo.get(key)
        if not (TYPES["nums"](v) and len(v) == 2 and all(math.isfinite(x) for x in v)):
            return f"summary attribute arm.{key} must be two finite numbers, got {v!r:.40}"
    if min(geo["link_lengths"]) <= 0:
        return "summary attribute arm.link_lengths must be > 0"
    return None


def eval_lists(art) -> str | None:
    """An evaluation's lists are not empty, its baseline is a strategy, each category a limit."""
    a = art.attrs
    for key in ("modes", "categories", "strategies"):
        if not a[key]:
            return f"summary attribute {key!r} is empty"
    if a["baseline"] not in a["strategies"]:
        return f"baseline {a['baseline']!r} is not among the strategies {a['strategies']}"
    cats = art.config["categories"]
    for c in a["categories"]:
        if not isinstance(cats.get(c), dict) or not TYPES["num"](cats[c].get("limit")):
            return f"config categories.{c}.limit is missing or not a number"
    return None


def eval_methods(art) -> str | None:
    """Each method of an evaluation (schema 2) has its lists and options."""
    table = art.attrs["methods"]
    for m in methods(art):
        own = table.get(m)
        if not isinstance(own, dict):
            return f"summary attribute methods.{m} is missing or not a table"
        for key in ("modes", "categories", "strategies"):
            if not TYPES["strs"](own.get(key)):
                return f"summary attribute methods.{m}.{key} must be a list of names"
        if not isinstance(own.get("options"), dict):
            return f"summary attribute methods.{m}.options must be a table"
    return None


def _quality_cell(m: str, r: str, cell: Any, bases: set[str]) -> str | None:
    """One summary cell: its numbers, and (a row compared with a baseline, not itself a
    baseline row) its advantage and p-value."""
    if not isinstance(cell, dict) or not TYPES["num"](cell.get("final_median")):
        return f"summary attribute summary.{m}.all.{r} is missing its numbers"
    if r not in bases and not (TYPES["num"](cell.get("advantage"))
                               and TYPES["num"](cell.get("pvalue"))):
        return f"summary attribute summary.{m}.all.{r} lacks advantage or pvalue"
    return None


def quality_lists(art) -> str | None:
    """A model-quality sweep has its baseline among its rows and every model's summary cells."""
    a = art.attrs
    if not a["rows"] or a["baseline"] not in a["rows"]:
        return f"baseline {a['baseline']!r} is not among the rows {a['rows']}"
    baselines = a.get("baselines") or {}
    if not isinstance(baselines, dict) or any(
            k not in a["rows"] or v not in a["rows"] for k, v in baselines.items()):
        return f"summary attribute baselines must map rows to rows {a['rows']}"
    bases = {a["baseline"], *baselines.values()}
    for m, info in a["models"].items():
        if not isinstance(info, dict) or not TYPES["num"](info.get("boundary_error")):
            return f"summary attribute models.{m}.boundary_error must be a number"
        per = a["summary"].get(m)
        if not isinstance(per, dict) or not isinstance(per.get("all"), dict):
            return f"summary attribute summary.{m} is missing or has no 'all' table"
        for r in a["rows"]:
            msg = _quality_cell(m, r, per["all"].get(r), bases)
            if msg:
                return msg
    return None
