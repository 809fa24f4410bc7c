"""Structural validation of artifacts on read: per kind and schema version, the datasets, summary
attributes and config entries that readers rely on, with their dtype kind and shape.

One table, :data:`SCHEMAS`, kind -> schema version -> :class:`Schema`. To extend it when you add a
dataset, add a :class:`Dataset` line to the kind's current schema; when you bump a kind's version
(:data:`kbcli.stages.artifact.SCHEMA_VERSIONS`), add a new entry and keep the old ones: a file is
checked against the schema of the highest version not above its own.

A dataset's ``shape`` names its axes: an int is a fixed length, a string a symbol shared by every
dataset of the artifact (``"T"``: all per-step arrays have the same length), ``"*"`` any length.
``index`` says the values index an axis (``index="M"``: every value in ``[0, M)``); ``upto`` allows
the axis length itself (``0 <= v <= T``). Paths may hold ``{name}`` placeholders expanded over a
list in the artifact's summary attributes (``{modes}`` over ``attrs["modes"]``).

:func:`validate` raises :class:`~kbcli.errors.ArtifactError` naming the first thing wrong:
"history.h5: dataset 'target' has 119 rows, expected 120 (as 'result')".
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kbcli.errors import ArtifactError, KbcliError

#: dtype kinds: f float, i/u integer, b bool, U text (a string dataset)
FLOAT, INT, BOOL, TEXT = "f", "iu", "b", "U"
NUM = "fiu"
FLAG = "biu"  # 0/1 results stored as bool or small integers

#: Fewest sound classes (besides silence) a learned model must tell apart: ``kbcli learn`` refuses to
#: write, and every reader refuses to load, a model with fewer (it cannot locate a moved keyboard).
MIN_SOUNDS = 2


@dataclass(frozen=True)
class Dataset:
    """A required (or optional) dataset.

    Parameters
    ----------
    path : str
        Slash path in the artifact, possibly with ``{placeholders}``.
    kinds : str
        Accepted numpy dtype kinds (``"f"``, ``"iu"``, ``"b"``, ``"U"``).
    shape : tuple of int or str
        Axis lengths or symbols; its length is the expected ``ndim``.
    optional : bool
        May be absent (checked when present).
    when : callable, optional
        ``when(artifact) -> bool``: required only for such artifacts (e.g. learned models).
    index, upto : str, optional
        The values are indices into an axis of that symbol (``[0, n)``) or steps (``[0, n]``).
    finite : bool
        No NaN or infinite value allowed (float datasets).
    """

    path: str
    kinds: str
    shape: tuple[int | str, ...] = ()
    optional: bool = False
    when: Callable[[Any], bool] | None = None
    index: str | None = None
    upto: str | None = None
    finite: bool = False


#: summary attribute types: "int", "num", "str", "bool", "list", "strs" (list of str), "dict",
#: "nums" (list of numbers), "numdict" (dict of numbers); a trailing "?" also allows null.
_TYPES: dict[str, Callable[[Any], bool]] = {
    "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "num": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    "str": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, bool),
    "list": lambda v: isinstance(v, list),
    "strs": lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
    "nums": lambda v: isinstance(v, list) and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in v),
    "dict": lambda v: isinstance(v, dict),
    "numdict": lambda v: isinstance(v, dict) and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in v.values()),
}
_WORDS = {"int": "a whole number", "num": "a number", "str": "text", "bool": "true or false",
          "list": "a list", "strs": "a list of names", "nums": "a list of numbers",
          "dict": "a table", "numdict": "a table of numbers"}


@dataclass(frozen=True)
class Schema:
    """What one schema version of a kind holds.

    Parameters
    ----------
    datasets : tuple of Dataset
    attrs : dict
        Summary attributes (``attrs`` JSON) and their types (see ``_TYPES``); a name ending in
        ``?`` may be absent (its type is checked when present).
    config : dict
        Config entries and their types; a dotted key reaches into a table (``"loop.adapt"``), a
        key ending in ``?`` may be absent.
    checks : tuple of callables
        ``check(artifact) -> str | None``: a message when a rule across entries fails.
    """

    datasets: tuple[Dataset, ...] = ()
    attrs: dict[str, str] = field(default_factory=dict)
    config: dict[str, str] = field(default_factory=dict)
    checks: tuple[Callable[[Any], str | None], ...] = ()


def _keyboard(art) -> str | None:
    """The artifact's keyboard config must build a keyboard (every stage rebuilds it)."""
    from kbcli.errors import KbcliError
    from kbcli.stages import keyboard as keyboard_stage

    try:
        keyboard_stage.load(art)
    except KbcliError as exc:
        return f"its keyboard config is invalid ({exc})"
    except (TypeError, ValueError, KeyError, AttributeError, OverflowError) as exc:
        return f"its keyboard config is malformed ({type(exc).__name__}: {exc})"
    return None


def _learned(art) -> bool:
    return art.config.get("strategy") != "exact"


def _model_class_of(art) -> str:
    return art.config.get("model_class", "lines")


def _lines(art) -> bool:
    return _learned(art) and _model_class_of(art) == "lines"


def _svc(art) -> bool:
    return _learned(art) and _model_class_of(art) == "svc"


def _model_class(art) -> str | None:
    """A learned model names a registered model class."""
    if not _learned(art):
        return None
    from kbcli.core.model_classes import MODEL_CLASSES

    name = _model_class_of(art)
    if name not in MODEL_CLASSES:
        return (f"config model_class {name!r} is not one of {', '.join(MODEL_CLASSES)}; you may "
                f"need to update kbcli")
    return None


def _outlines(art) -> str | None:
    """The keys' outlines: offsets from 0 to the number of vertices, one more than the keys."""
    off = np.asarray(art.data["outlines"]["offsets"])
    n_keys = len(np.asarray(art.data["features"]))
    n_vert = len(np.asarray(art.data["outlines"]["vertices"]))
    if len(off) != n_keys + 1 or off[0] != 0 or off[-1] != n_vert or (np.diff(off) < 3).any():
        return (f"outlines/offsets must run from 0 to {n_vert} in {n_keys + 1} steps of at least 3 "
                "vertices (one outline per key)")
    return None


def _two_sounds(art) -> str | None:
    """A model must tell at least two sounds apart (besides silence) to be of any use."""
    if not _learned(art):
        return None
    n = int(np.asarray(art.data["model"]["class_features"]).shape[0]) - 1
    if n < MIN_SOUNDS:
        return (f"the model knows {n} sound class(es) besides silence, fewer than the "
                f"{MIN_SOUNDS} needed "
                f"to find the keyboard: learn it again with a larger --budget")
    return None


def _scene_params(art) -> str | None:
    from kbcli.core.transforms import FAMILIES

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


def _eval_lists(art) -> str | None:
    a = art.attrs
    for key in ("modes", "categories", "strategies"):
        if not a[key]:
            return f"summary attribute {key!r} is empty"
    if a["baseline"] not in a["strategies"]:
        return f"baseline {a['baseline']!r} is not among the strategies {a['strategies']}"
    cats = art.config["categories"]
    for c in a["categories"]:
        if not isinstance(cats.get(c), dict) or not _TYPES["num"](cats[c].get("limit")):
            return f"config categories.{c}.limit is missing or not a number"
    return None


def _truth_keys(art) -> str | None:
    """A ground truth names every parameter of the world's transform family."""
    from kbcli.core.transforms import FAMILIES, family_for

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


def _arm(art) -> str | None:
    """The arm's geometry, when recorded: a base point and two link lengths."""
    geo = art.attrs.get("arm")
    if geo is None:
        return None
    for key in ("base", "link_lengths"):
        v = geo.get(key)
        if not (_TYPES["nums"](v) and len(v) == 2 and all(math.isfinite(x) for x in v)):
            return f"summary attribute arm.{key} must be two finite numbers, got {v!r:.40}"
    if min(geo["link_lengths"]) <= 0:
        return "summary attribute arm.link_lengths must be > 0"
    return None


def _has_posterior(art) -> bool:
    return "posterior" in art.data


_KEYBOARD_CFG = {"keyboard": "dict"}

SCHEMAS: dict[str, dict[int, Schema]] = {
    "keyboard": {1: Schema(
        checks=(_keyboard,),
        datasets=(
            Dataset("features", FLOAT, ("K", 2)),
            Dataset("names", TEXT, ("K",)),
            Dataset("key_centres", FLOAT, ("K", 2)),
        ),
    ), 2: Schema(  # any layout: the config names it, the keys' outlines are stored
        config={"layout": "str"},
        attrs={"layout": "str", "n_keys": "int"},
        checks=(_keyboard, _outlines),
        datasets=(
            Dataset("features", FLOAT, ("K", 2)),
            Dataset("names", TEXT, ("K",)),
            Dataset("key_centres", FLOAT, ("K", 2)),
            Dataset("outlines/vertices", FLOAT, ("V", 2), finite=True),
            Dataset("outlines/offsets", INT, ("*",), upto="V"),
        ),
    )},
    "model": {1: Schema(
        config={"strategy": "str", **_KEYBOARD_CFG},
        datasets=tuple(
            Dataset(p, k, s, when=_learned, index=ix) for p, k, s, ix in (
                ("samples/actions", FLOAT, ("N", 2), None),
                ("samples/landed", FLOAT, ("N", 2), None),
                ("samples/perceived", FLOAT, ("N", "F"), None),
                ("curve/reaches", INT, ("C",), None),
                ("curve/accuracy", FLOAT, ("C",), None),
                ("model/class_features", FLOAT, ("M", "F"), None),
                ("model/actions", FLOAT, ("A", 2), None),
                ("model/labels", INT, ("A",), "M"),
                ("model/edges", INT, ("E", 2), "A"),
                ("model/edge_piece", INT, ("E",), None),
                ("model/piece_pair", INT, ("P", 2), "M"),
                ("model/piece_line", INT, ("P",), "L"),
                ("model/piece_sign", FLOAT, ("P",), None),
                ("model/lines", FLOAT, ("L", 3), None),
                ("model/area", FLOAT, (4,), None),
                ("model/merge_angle", FLOAT, (), None),
                ("model/merge_offset", FLOAT, (), None),
                ("model/piece_reach", FLOAT, (), None),
                ("model/reach_sd_fitted", FLOAT, (), None),
                ("model/match_threshold", FLOAT, (), None),
                ("model/n_neighbors", INT, (), None),
                ("model/min_sd", FLOAT, (), None),
                ("model/max_sd", FLOAT, (), None),
                ("model/extrapolation", FLOAT, (), None),
            )
        ),
        attrs={"accuracy?": "num?", "boundary_error_px?": "num?", "n_reaches?": "int?"},
        checks=(_keyboard, _two_sounds),
    )},
    "scene": {1: Schema(
        config={"family": "str", "params": "nums", **_KEYBOARD_CFG},
        checks=(_keyboard, _scene_params),
    )},
    "history": {1: Schema(
        config=_KEYBOARD_CFG,
        attrs={"perturb_at": "int?", "steps": "int", "melody?": "str"},
        checks=(_keyboard,),
        datasets=(
            Dataset("action", FLOAT, ("T", 2)),
            Dataset("landed", FLOAT, ("T", 2)),
            Dataset("perceived", FLOAT, ("T", "F")),
            Dataset("target", INT, ("T",), index="M"),
            Dataset("cls", INT, ("T",)),
            Dataset("heard", INT, ("T",)),
            Dataset("result", FLAG, ("T",)),
            Dataset("perturbed", FLAG, ("T",)),
            Dataset("melody/midi", INT, ("M",)),
            Dataset("melody/durations", FLOAT, ("M",), finite=True),
            Dataset("melody/keys", INT, ("M",), index="K"),
        ),
    )},
    "detection": {1: Schema(
        config={"detector": "str", "threshold": "num"},
        datasets=(
            Dataset("score", FLOAT, ("T",)),
            Dataset("fired", FLAG, ("T",)),
            Dataset("firings", INT, ("F",), index="T"),
        ),
    )},
    "run": {1: Schema(
        attrs={"steps": "int", "truth?": "numdict?", "family?": "str", "stop_step?": "int?",
               "final_error_px?": "num?", "estimate?": "numdict?"},
        datasets=(
            Dataset("actions", FLOAT, ("T", 2)),
            Dataset("landed", FLOAT, ("T", 2)),
            Dataset("classes", INT, ("T",)),
            Dataset("errors", FLOAT, ("T",)),
            Dataset("angle_errors", FLOAT, ("T",), optional=True),
            Dataset("entropy", FLOAT, ("T",)),
            Dataset("means", FLOAT, ("T", "P")),
            Dataset("estimates", FLOAT, ("T", "P")),
            Dataset("dx", FLOAT, ("X",), finite=True),
            Dataset("dy", FLOAT, ("Y",), finite=True),
            Dataset("snapshot_steps", INT, ("S",), optional=True, upto="T"),
            Dataset("snapshots", NUM, ("S", "Y", "X"), optional=True),
            Dataset("snapshot_angles", FLOAT, ("S", "A"), optional=True),
            Dataset("timing/step_ms", FLOAT, ("T",), optional=True),
            Dataset("perceived", FLOAT, ("T", "F"), optional=True),
            Dataset("mass", FLOAT, ("T",), optional=True),
        ),
        config={"adapt?": "dict", "keyboard?": "dict"},
        checks=(_truth_keys, _arm),
    )},
    "closed_loop": {1: Schema(
        attrs={"perturbed_at": "int", "detected_at": "int?", "detection_delay": "int?",
               "success_before": "num?", "success_after_perturbation": "num?",
               "success_after_adaptation": "num?", "truth": "numdict", "correction?": "numdict?"},
        config={**_KEYBOARD_CFG, "loop?": "dict", "loop.adapt?": "dict", "loop.detector?": "dict"},
        checks=(_keyboard, _truth_keys, _arm),
        datasets=(
            Dataset("steps/phase", INT, ("T",)),
            Dataset("steps/result", FLAG, ("T",)),
            Dataset("steps/score", FLOAT, ("T",)),
            Dataset("steps/landed", FLOAT, ("T", 2)),
            Dataset("steps/action", FLOAT, ("T", 2), optional=True),
            Dataset("steps/perceived", FLOAT, ("T", "F")),
            Dataset("steps/correction", FLOAT, ("T", "E")),
        ),
    )},
    "evaluation": {1: Schema(
        attrs={"modes": "strs", "categories": "strs", "strategies": "strs", "baseline": "str",
               "max_steps": "int"},
        config={"categories": "dict", "experiments": "int"},
        datasets=(
            Dataset("thresholds", FLOAT, ("H",)),
            Dataset("experiments/params", FLOAT, ("N", "P")),
            Dataset("experiments/mode", TEXT, ("N",)),
            Dataset("experiments/category", TEXT, ("N",)),
            Dataset("experiments/strategy", TEXT, ("N",)),
            Dataset("experiments/play_adapted", FLOAT, ("N",), optional=True),
            Dataset("experiments/play_unadapted", FLOAT, ("N",), optional=True),
            Dataset("experiments/play_before", FLOAT, ("N",), optional=True),
            *(Dataset(f"curves/{{modes}}/{{categories}}/{{strategies}}/{k}", FLOAT, s)
              for k, s in (("rmse", ("T",)), ("q25", ("T",)), ("q75", ("T",)),
                           ("median_samples", ("H",)), ("reached", ("H",)))),
            Dataset("curves/{modes}/{categories}/{strategies}/samples_to_threshold", NUM,
                    ("*", "H")),
            *(Dataset(f"entropy/{{modes}}/{{strategies}}/{k}", FLOAT, ("T",))
              for k in ("mean", "q25", "q75")),
            Dataset("pvalues/{modes}/{categories}/{others}/pvalue", FLOAT, ("H",)),
            Dataset("pvalues/{modes}/{categories}/{others}/statistic", FLOAT, ("H",)),
            Dataset("examples/{modes}/{strategies}/row", INT, (), optional=True, index="N"),
            Dataset("examples/{modes}/{strategies}/snapshots", NUM, ("*", "*", "*"),
                    optional=True),
        ),
        checks=(_eval_lists,),
    )},
}


def _extend(base: Schema, *datasets: Dataset, **attrs: str) -> Schema:
    """A later version of a schema: ``base`` plus datasets and summary attributes."""
    return Schema(datasets=(*base.datasets, *datasets), attrs={**base.attrs, **attrs},
                  config=base.config, checks=base.checks)


# run 2: joint angles (dynamics mode), the arm and mode; sessions of kbcli serve have no truth
SCHEMAS["run"][2] = _extend(
    SCHEMAS["run"][1], Dataset("joint_angles", FLOAT, ("T", 2), optional=True),
    **{"mode?": "str?", "arm?": "dict?", "source?": "str?"})
# closed_loop 2: joint angles and the estimate per touch, the posterior after each adaptation touch
SCHEMAS["closed_loop"][2] = _extend(
    SCHEMAS["closed_loop"][1],
    Dataset("steps/joint_angles", FLOAT, ("T", 2), optional=True),
    Dataset("steps/estimate", FLOAT, ("T", "E"), optional=True),
    *(Dataset(p, k, s, when=_has_posterior, index=ix, finite=f) for p, k, s, ix, f in (
        ("posterior/dx", FLOAT, ("PX",), None, True),
        ("posterior/dy", FLOAT, ("PY",), None, True),
        ("posterior/log_translation", NUM, ("PT", "PY", "PX"), None, False),
        ("posterior/touch", INT, ("PT",), "T", False))),
    **{"mode?": "str?", "arm?": "dict?", "source?": "str?"})


def _eval_methods(art) -> str | None:
    methods = art.attrs["methods"]
    for m in _methods(art):
        own = methods.get(m)
        if not isinstance(own, dict):
            return f"summary attribute methods.{m} is missing or not a table"
        for key in ("modes", "categories", "strategies"):
            if not _TYPES["strs"](own.get(key)):
                return f"summary attribute methods.{m}.{key} must be a list of names"
        if not isinstance(own.get("options"), dict):
            return f"summary attribute methods.{m}.options must be a table"
    return None


# evaluation 2: named methods (each with its own modes, categories and strategies), measured
# playing success, tie-corrected tests
SCHEMAS["evaluation"][2] = Schema(
    attrs={**SCHEMAS["evaluation"][1].attrs, "methods": "dict", "method_order?": "strs"},
    config=SCHEMAS["evaluation"][1].config,
    datasets=(
        *(d for d in SCHEMAS["evaluation"][1].datasets if "{" not in d.path),
        Dataset("experiments/method", TEXT, ("N",)),
        *(Dataset(f"curves/{{modes}}/{{method}}/{{categories}}/{{strategies}}/{k}", FLOAT, s)
          for k, s in (("rmse", ("T",)), ("q25", ("T",)), ("q75", ("T",)),
                       ("median_samples", ("H",)), ("reached", ("H",)))),
        Dataset("curves/{modes}/{method}/{categories}/{strategies}/samples_to_threshold", NUM,
                ("*", "H"), optional=True),
        *(Dataset(f"entropy/{{modes}}/{{method}}/{{strategies}}/{k}", FLOAT, ("T",))
          for k in ("mean", "q25", "q75")),
        Dataset("pvalues/{modes}/{method}/{categories}/{others}/pvalue", FLOAT, ("H",)),
        Dataset("pvalues/{modes}/{method}/{categories}/{others}/statistic", FLOAT, ("H",)),
        Dataset("pvalues/{modes}/{method}/{categories}/{others}/min_pvalue", FLOAT, (),
                optional=True),
        Dataset("examples/{modes}/{method}/{strategies}/row", INT, (), optional=True, index="N"),
        Dataset("examples/{modes}/{method}/{strategies}/snapshots", NUM, ("*", "*", "*"),
                optional=True),
    ),
    checks=(_eval_lists, _eval_methods),
)
# run 3, closed_loop 3: the adapt config nests the robot's options under "robot"
SCHEMAS["run"][3] = SCHEMAS["run"][2]
SCHEMAS["closed_loop"][3] = SCHEMAS["closed_loop"][2]


def _reliability(art) -> str | None:
    """A learned model of schema 2 carries its own estimate of how good it is."""
    if not _learned(art):
        return None
    rel = art.attrs.get("reliability")
    if not isinstance(rel, dict):
        return "summary attribute 'reliability' is missing or not a table"
    for key in ("cv_error", "cv_log_loss", "cv_ece", "boundary_error"):
        if not _TYPES["num"](rel.get(key)):
            return f"summary attribute reliability.{key} must be a number, got {rel.get(key)!r:.40}"
    if "expected_error" in rel and not _TYPES["num"](rel["expected_error"]):  # (since kbcli 2026-12)
        return (f"summary attribute reliability.expected_error must be a number, got "
                f"{rel['expected_error']!r:.40}")
    if not _TYPES["numdict"](rel.get("calibration", {})):
        return "summary attribute reliability.calibration must be a table of numbers"
    return None


# model 2: calibrated (label noise, floor; a label-noise tolerance of the fit) and self-assessed
SCHEMAS["model"][2] = Schema(
    datasets=(*SCHEMAS["model"][1].datasets,
              *(Dataset(f"model/{k}", FLOAT, (), when=_learned)
                for k in ("sd_scale", "noise_sd", "floor", "noise_tol"))),
    attrs={**SCHEMAS["model"][1].attrs, "reliability?": "dict?"},
    config=SCHEMAS["model"][1].config,
    checks=(*SCHEMAS["model"][1].checks, _reliability),
)

# model 3: a model class (config model_class: lines or svc), calibrated and self-assessed as in 2
SCHEMAS["model"][3] = Schema(
    config={"strategy": "str", "model_class?": "str", **_KEYBOARD_CFG},
    datasets=tuple(
        Dataset(p, k, s, when=w, index=ix) for p, k, s, ix, w in (
            ("samples/actions", FLOAT, ("N", 2), None, _learned),
            ("samples/landed", FLOAT, ("N", 2), None, _learned),
            ("samples/perceived", FLOAT, ("N", "F"), None, _learned),
            ("curve/reaches", INT, ("C",), None, _learned),
            ("curve/accuracy", FLOAT, ("C",), None, _learned),
            ("model/class_features", FLOAT, ("M", "F"), None, _learned),
            ("model/actions", FLOAT, ("A", 2), None, _learned),
            ("model/labels", INT, ("A",), "M", _learned),
            ("model/area", FLOAT, (4,), None, _learned),
            ("model/reach_sd_fitted", FLOAT, (), None, _learned),
            ("model/match_threshold", FLOAT, (), None, _learned),
            ("model/n_neighbors", INT, (), None, _learned),
            ("model/edges", INT, ("E", 2), "A", _lines),
            ("model/edge_piece", INT, ("E",), None, _lines),
            ("model/piece_pair", INT, ("P", 2), "M", _lines),
            ("model/piece_line", INT, ("P",), "L", _lines),
            ("model/piece_sign", FLOAT, ("P",), None, _lines),
            ("model/lines", FLOAT, ("L", 3), None, _lines),
            ("model/merge_angle", FLOAT, (), None, _lines),
            ("model/merge_offset", FLOAT, (), None, _lines),
            ("model/piece_reach", FLOAT, (), None, _lines),
            ("model/min_sd", FLOAT, (), None, _lines),
            ("model/max_sd", FLOAT, (), None, _lines),
            ("model/extrapolation", FLOAT, (), None, _lines),
            *((f"model/{k}", FLOAT, (), None, _lines)
              for k in ("sd_scale", "noise_sd", "floor", "noise_tol")),
            ("model/pairs", INT, ("Q", 2), "M", _svc),
            ("model/n_support", INT, ("Q",), None, _svc),
            ("model/length_scale", FLOAT, (), None, _svc),
            ("model/C", FLOAT, (), None, _svc),
            ("model/local_radius", FLOAT, (), None, _svc),
        )
    ),
    attrs={"accuracy?": "num?", "boundary_error_px?": "num?", "n_reaches?": "int?",
           "model_class?": "str", "reliability?": "dict?"},
    checks=(_keyboard, _two_sounds, _model_class, _reliability),
)


def _quality_lists(art) -> str | None:
    a = art.attrs
    if not a["rows"] or a["baseline"] not in a["rows"]:
        return f"baseline {a['baseline']!r} is not among the rows {a['rows']}"
    for m, info in a["models"].items():
        if not isinstance(info, dict) or not _TYPES["num"](info.get("boundary_error")):
            return f"summary attribute models.{m}.boundary_error must be a number"
        per = a["summary"].get(m)
        if not isinstance(per, dict) or not isinstance(per.get("all"), dict):
            return f"summary attribute summary.{m} is missing or has no 'all' table"
        for r in a["rows"]:
            cell = per["all"].get(r)
            if not isinstance(cell, dict) or not _TYPES["num"](cell.get("final_median")):
                return f"summary attribute summary.{m}.all.{r} is missing its numbers"
            if r != a["baseline"] and not (_TYPES["num"](cell.get("advantage"))
                                           and _TYPES["num"](cell.get("pvalue"))):
                return f"summary attribute summary.{m}.all.{r} lacks advantage or pvalue"
    return None


# model_quality 1: the model-quality sweep (kbcli quality)
SCHEMAS["model_quality"] = {1: Schema(
    datasets=(
        Dataset("experiments/model", TEXT, ("N",)),
        Dataset("experiments/category", TEXT, ("N",)),
        Dataset("experiments/row", TEXT, ("N",)),
        Dataset("experiments/param_index", INT, ("N",)),
        Dataset("experiments/rep", INT, ("N",)),
        Dataset("experiments/errors", FLOAT, ("N", "T")),
    ),
    attrs={"models": "dict", "summary": "dict", "rows": "strs", "baseline": "str",
           "max_steps": "int", "categories": "strs", "n_experiments": "int"},
    config={"mode": "str", "arm": "dict", "experiments": "int", "budgets": "nums",
            "explorations": "strs", "rows": "dict"},
    checks=(_quality_lists,),
)}


def schema_for(kind: str, version: int) -> Schema | None:
    """The schema of the highest version of ``kind`` not above ``version`` (None if none)."""
    versions = [v for v in SCHEMAS.get(kind, {}) if v <= version]
    return SCHEMAS[kind][max(versions)] if versions else None


def _typed(value: Any, spec: str) -> bool:
    if spec.endswith("?"):
        return value is None or _TYPES[spec[:-1]](value)
    return _TYPES[spec](value)


def _lookup(tree: dict, dotted: str, sep: str = ".") -> tuple[bool, Any]:
    """(found, value) of a ``sep``-separated path in nested dicts."""
    node: Any = tree
    for part in dotted.split(sep):
        if not isinstance(node, dict) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _node(data: dict, path: str) -> tuple[bool, Any]:
    return _lookup(data, path, "/")


_PLACEHOLDER = re.compile(r"\{(\w+)\}")


def _methods(art) -> list[str]:
    a = art.attrs
    order = a.get("method_order")
    return [str(m) for m in (order if isinstance(order, list) else a.get("methods") or [])]


def _expand(path: str, art) -> list[str]:
    """Every path a ``{placeholder}`` path stands for. ``{method}`` runs over the evaluation's
    methods, and the lists after it (modes, categories, strategies) are that method's own."""
    if "{method}" in path:
        out = []
        for m in _methods(art):
            own = (art.attrs.get("methods") or {}).get(m)
            sub = dict(art.attrs, **(own if isinstance(own, dict) else {}))
            view = type("View", (), {"attrs": sub})()
            out += _expand(path.replace("{method}", m), view)
        return out
    names = _PLACEHOLDER.findall(path)
    if not names:
        return [path]
    lists = []
    for n in names:
        if n == "others":
            vals = [s for s in art.attrs.get("strategies", []) if s != art.attrs.get("baseline")]
        else:
            vals = art.attrs.get(n, [])
        lists.append([str(v) for v in vals] if isinstance(vals, list) else [])
    out = []
    for combo in itertools.product(*lists):
        p = path
        for n, v in zip(names, combo, strict=True):
            p = p.replace("{" + n + "}", v, 1)
        out.append(p)
    return out


def _kind_of(arr: np.ndarray) -> str:
    k = arr.dtype.kind
    return "U" if k in "USO" else k


def validate(art, where: str = "") -> None:
    """Check an artifact read from disk against its kind's schema.

    Parameters
    ----------
    art : Artifact
    where : str
        The file name, for the message.

    Raises
    ------
    ArtifactError
        Naming the first missing or malformed entry.
    """
    pre = f"{where}: " if where else ""
    schema = schema_for(art.kind, int(art.schema_version or 1))
    if schema is None:
        return

    def fail(msg: str) -> None:
        raise ArtifactError(f"{pre}{art.kind} artifact: {msg}")

    for key, spec in schema.config.items():
        optional = key.endswith("?")
        key = key.rstrip("?")
        ok, value = _lookup(art.config, key)
        if not ok and optional:
            continue
        if not ok:
            fail(f"config entry {key!r} is missing")
        if not _typed(value, spec):
            fail(f"config entry {key!r} must be {_WORDS[spec.rstrip('?')]}, got {value!r:.60}")
    for key, spec in schema.attrs.items():
        if key.endswith("?"):
            key = key[:-1]
            if key not in art.attrs:
                continue
        if key not in art.attrs:
            fail(f"summary attribute {key!r} is missing")
        if not _typed(art.attrs[key], spec):
            fail(f"summary attribute {key!r} must be {_WORDS[spec.rstrip('?')]}"
                 f"{' or null' if spec.endswith('?') else ''}, got {art.attrs[key]!r:.60}")
    dims: dict[str, tuple[int, str]] = {}
    checks: list[tuple[Dataset, str, np.ndarray]] = []
    for ds in schema.datasets:
        if ds.when is not None and not ds.when(art):
            continue
        for path in _expand(ds.path, art):
            found, node = _node(art.data, path)
            if not found:
                if ds.optional:
                    continue
                fail(f"dataset {path!r} is missing")
            if isinstance(node, dict):
                fail(f"{path!r} is a group, expected a dataset")
            arr = np.asarray(node)
            if _kind_of(arr) not in ds.kinds:
                want = {"f": "floats", "iu": "integers", "b": "booleans", "U": "text",
                        "fiu": "numbers", "biu": "0/1 flags"}.get(ds.kinds, ds.kinds)
                fail(f"dataset {path!r} holds {arr.dtype}, expected {want}")
            if arr.ndim != len(ds.shape):
                fail(f"dataset {path!r} has {arr.ndim} dimension(s), expected {len(ds.shape)}")
            for axis, (n, want) in enumerate(zip(arr.shape, ds.shape, strict=True)):
                if isinstance(want, int):
                    if n != want:
                        fail(f"dataset {path!r} has length {n} along axis {axis}, expected {want}")
                elif want != "*":
                    if want in dims and dims[want][0] != n:
                        fail(f"dataset {path!r} has length {n} along axis {axis}, expected "
                             f"{dims[want][0]} (as {dims[want][1]!r})")
                    dims.setdefault(want, (n, path))
            checks.append((ds, path, arr))
    for ds, path, arr in checks:
        if ds.finite and arr.size and not np.all(np.isfinite(arr)):
            fail(f"dataset {path!r} holds NaN or infinite values")
        for sym, inclusive in ((ds.index, False), (ds.upto, True)):
            if sym is None or not arr.size:
                continue
            n = dims.get(sym, (None,))[0]
            if n is None and sym == "K":
                n = _keys(art)
            if n is None:
                continue
            hi = n if inclusive else n - 1
            if arr.min() < 0 or arr.max() > hi:
                fail(f"dataset {path!r} holds values outside [0, {hi}]")
    for check in schema.checks:
        try:
            msg = check(art)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            msg = f"inconsistent entries ({type(exc).__name__}: {exc})"
        if msg:
            fail(msg)


def _keys(art) -> int | None:
    """Number of keys of the artifact's keyboard (from its config), if it can be built."""
    try:
        from kbcli.stages import keyboard as keyboard_stage

        return keyboard_stage.load(art).n_keys
    except Exception:  # noqa: BLE001 - a broken keyboard config is reported by its own reader
        return None
