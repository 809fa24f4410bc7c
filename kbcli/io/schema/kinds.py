"""The table of schemas, :data:`SCHEMAS`: kind -> schema version -> :class:`Schema` (how to extend
it: :mod:`kbcli.io.schema`). The arrays each model class stores are in one table,
:data:`MODEL_ARRAYS`.
"""

from __future__ import annotations

import kbcli.io.schema.rules as rules
from kbcli.io.schema.spec import FLAG, FLOAT, INT, NUM, TEXT, Dataset, Schema, extend

_KEYBOARD_CFG = {"keyboard": "dict"}
_KEYBOARD_DATA = (
    Dataset("features", FLOAT, ("K", 2)),
    Dataset("names", TEXT, ("K",)),
    Dataset("key_centres", FLOAT, ("K", 2)),
)

# -- model -----------------------------------------------------------------------------------------

#: What every learned model stores, whatever its class: (path, kinds, shape, index).
_MODEL_COMMON = (
    ("samples/actions", FLOAT, ("N", 2), None),
    ("samples/landed", FLOAT, ("N", 2), None),
    ("samples/perceived", FLOAT, ("N", "F"), None, True),
    ("curve/reaches", INT, ("C",), None),
    ("curve/accuracy", FLOAT, ("C",), None),
    ("model/class_features", FLOAT, ("M", "F"), None, True),
    ("model/actions", FLOAT, ("A", 2), None),
    ("model/labels", INT, ("A",), "M"),
)
#: The ``lines`` class's own arrays in model schema 1 (then the only class, uncalibrated).
_LINES_1 = (
    ("model/edges", INT, ("E", 2), "A"),
    ("model/edge_piece", INT, ("E",), None),
    ("model/piece_pair", INT, ("P", 2), "M"),
    ("model/piece_line", INT, ("P",), "L"),
    ("model/piece_sign", FLOAT, ("P",), None),
    ("model/lines", FLOAT, ("L", 3), None),
)
_SCALARS_1 = ("merge_angle", "merge_offset", "piece_reach", "reach_sd_fitted", "match_threshold")
_CALIBRATION = ("sd_scale", "noise_sd", "floor", "noise_tol")

#: Model class -> the arrays a learned model of that class stores (model schema 3), in one place.
MODEL_ARRAYS: dict[str, tuple[tuple, ...]] = {
    "lines": (*_LINES_1,
              *((f"model/{k}", FLOAT, (), None)
                for k in ("merge_angle", "merge_offset", "piece_reach", "min_sd", "max_sd",
                          "extrapolation", *_CALIBRATION))),
    "svc": (
        ("model/pairs", INT, ("Q", 2), "M"),
        ("model/n_support", INT, ("Q",), None),
        ("model/length_scale", FLOAT, (), None),
        ("model/C", FLOAT, (), None),
        ("model/local_radius", FLOAT, (), None),
    ),
}


def _learned_data(rows, when) -> tuple[Dataset, ...]:
    """Rows ``(path, kinds, shape, index[, nan])``: ``nan`` when NaN marks silence."""
    return tuple(Dataset(p, k, s, when=when, index=ix, nan=bool(nan))
                 for p, k, s, ix, *nan in rows)


_MODEL_1 = Schema(
    config={"strategy": "str", **_KEYBOARD_CFG},
    datasets=_learned_data((
        *_MODEL_COMMON, *_LINES_1,
        ("model/area", FLOAT, (4,), None),
        *((f"model/{k}", FLOAT, (), None) for k in _SCALARS_1),
        ("model/n_neighbors", INT, (), None),
        *((f"model/{k}", FLOAT, (), None) for k in ("min_sd", "max_sd", "extrapolation")),
    ), rules.learned),
    attrs={"accuracy?": "num?", "boundary_error_px?": "num?", "n_reaches?": "int?"},
    checks=(rules.keyboard, rules.two_sounds),
)
# model 2: calibrated (label noise, floor; a label-noise tolerance of the fit) and self-assessed
_MODEL_2 = Schema(
    datasets=(*_MODEL_1.datasets,
              *_learned_data(((f"model/{k}", FLOAT, (), None) for k in _CALIBRATION),
                             rules.learned)),
    attrs={**_MODEL_1.attrs, "reliability?": "dict?"},
    config=_MODEL_1.config,
    checks=(*_MODEL_1.checks, rules.reliability),
)
# model 3: a model class (config model_class), calibrated and self-assessed as in 2
_MODEL_3 = Schema(
    config={"strategy": "str", "model_class?": "str", **_KEYBOARD_CFG},
    datasets=(
        *_learned_data((
            *_MODEL_COMMON,
            ("model/area", FLOAT, (4,), None),
            ("model/reach_sd_fitted", FLOAT, (), None),
            ("model/match_threshold", FLOAT, (), None),
            ("model/n_neighbors", INT, (), None),
        ), rules.learned),
        *(d for name, rows in MODEL_ARRAYS.items()
          for d in _learned_data(rows, rules.of_class(name))),
    ),
    attrs={"accuracy?": "num?", "boundary_error_px?": "num?", "n_reaches?": "int?",
           "model_class?": "str", "reliability?": "dict?"},
    checks=(rules.keyboard, rules.two_sounds, rules.model_class, rules.reliability),
)

# -- keyboard, scene, history, detection -----------------------------------------------------------

_KEYBOARD_1 = Schema(checks=(rules.keyboard,), datasets=_KEYBOARD_DATA)
# keyboard 2: any layout: the config names it, the keys' outlines are stored
_KEYBOARD_2 = Schema(
    config={"layout": "str"},
    attrs={"layout": "str", "n_keys": "int"},
    checks=(rules.keyboard, rules.outlines),
    datasets=(
        *_KEYBOARD_DATA,
        Dataset("outlines/vertices", FLOAT, ("V", 2), finite=True),
        Dataset("outlines/offsets", INT, ("*",), upto="V"),
    ),
)
_SCENE_1 = Schema(
    config={"family": "str", "params": "nums", **_KEYBOARD_CFG},
    checks=(rules.keyboard, rules.scene_params, rules.scene_agrees),
    datasets=(
        Dataset("params", FLOAT, ("P",)),
        Dataset("key_centres", FLOAT, ("K", 2)),
    ),
)
_HISTORY_1 = Schema(
    config=_KEYBOARD_CFG,
    attrs={"perturb_at": "int?", "steps": "int", "melody?": "str"},
    checks=(rules.keyboard,),
    datasets=(
        Dataset("action", FLOAT, ("T", 2)),
        Dataset("landed", FLOAT, ("T", 2)),
        Dataset("perceived", FLOAT, ("T", "F"), nan=True),
        Dataset("target", INT, ("T",), index="M"),
        Dataset("cls", INT, ("T",)),
        Dataset("heard", INT, ("T",)),
        Dataset("result", FLAG, ("T",)),
        Dataset("perturbed", FLAG, ("T",)),
        Dataset("melody/midi", INT, ("M",)),
        Dataset("melody/durations", FLOAT, ("M",), finite=True),
        Dataset("melody/keys", INT, ("M",), index="K"),
    ),
)
_DETECTION_1 = Schema(
    config={"detector": "str", "threshold": "num"},
    datasets=(
        Dataset("score", FLOAT, ("T",), nan=True),
        Dataset("fired", FLAG, ("T",)),
        Dataset("firings", INT, ("F",), index="T"),
    ),
)
# detection 2: the detector holds its own options (``{"name": "cusum", "shift": 0.15}``)
_DETECTION_2 = Schema(config={"detector": "dict", "threshold": "num"},
                      datasets=_DETECTION_1.datasets)

# -- run, closed_loop ------------------------------------------------------------------------------

_RUN_1 = Schema(
    attrs={"steps": "int", "truth?": "numdict?", "family?": "str", "stop_step?": "int?",
           "final_error_px?": "num?", "estimate?": "numdict?"},
    datasets=(
        Dataset("actions", FLOAT, ("T", 2)),
        Dataset("landed", FLOAT, ("T", 2), nan=True),  # NaN: the robot felt nothing (serve)
        Dataset("classes", INT, ("T",)),
        Dataset("errors", FLOAT, ("T",), nan=True),
        Dataset("angle_errors", FLOAT, ("T",), optional=True, nan=True),
        Dataset("entropy", FLOAT, ("T",)),
        Dataset("means", FLOAT, ("T", "P")),
        Dataset("estimates", FLOAT, ("T", "P")),
        Dataset("dx", FLOAT, ("X",), finite=True),
        Dataset("dy", FLOAT, ("Y",), finite=True),
        Dataset("snapshot_steps", INT, ("S",), optional=True, upto="T"),
        Dataset("snapshots", NUM, ("S", "Y", "X"), optional=True, finite=False),
        Dataset("snapshot_angles", FLOAT, ("S", "A"), optional=True),
        Dataset("timing/step_ms", FLOAT, ("T",), optional=True),
        Dataset("perceived", FLOAT, ("T", "F"), optional=True, nan=True),
        Dataset("mass", FLOAT, ("T",), optional=True),
    ),
    config={"adapt?": "dict", "keyboard?": "dict"},
    checks=(rules.truth_keys, rules.arm),
)
_CLOSED_LOOP_1 = Schema(
    attrs={"perturbed_at": "int", "detected_at": "int?", "detection_delay": "int?",
           "success_before": "num?", "success_after_perturbation": "num?",
           "success_after_adaptation": "num?", "truth": "numdict", "correction?": "numdict?"},
    config={**_KEYBOARD_CFG, "loop?": "dict", "loop.adapt?": "dict", "loop.detector?": "dict"},
    checks=(rules.keyboard, rules.truth_keys, rules.arm),
    datasets=(
        Dataset("steps/phase", INT, ("T",)),
        Dataset("steps/result", FLAG, ("T",)),
        Dataset("steps/score", FLOAT, ("T",), nan=True),
        Dataset("steps/landed", FLOAT, ("T", 2)),
        Dataset("steps/action", FLOAT, ("T", 2), optional=True),
        Dataset("steps/perceived", FLOAT, ("T", "F"), nan=True),
        Dataset("steps/correction", FLOAT, ("T", "E")),
    ),
)
_SESSION_ATTRS = {"mode?": "str?", "arm?": "dict?", "source?": "str?"}
# run 2: joint angles (dynamics mode), the arm and mode; sessions of kbcli serve have no truth
_RUN_2 = extend(_RUN_1, Dataset("joint_angles", FLOAT, ("T", 2), optional=True), **_SESSION_ATTRS)
# closed_loop 2: joint angles and the estimate per touch, the posterior after each adaptation touch
_CLOSED_LOOP_2 = extend(
    _CLOSED_LOOP_1,
    Dataset("steps/joint_angles", FLOAT, ("T", 2), optional=True),
    Dataset("steps/estimate", FLOAT, ("T", "E"), optional=True, nan=True),
    *(Dataset(p, k, s, when=rules.has_posterior, index=ix, finite=f) for p, k, s, ix, f in (
        ("posterior/dx", FLOAT, ("PX",), None, True),
        ("posterior/dy", FLOAT, ("PY",), None, True),
        ("posterior/log_translation", NUM, ("PT", "PY", "PX"), None, False),
        ("posterior/touch", INT, ("PT",), "T", False))),
    **_SESSION_ATTRS)

# -- evaluation, model_quality ---------------------------------------------------------------------


def _curves(prefix: str, optional_counts: bool) -> tuple[Dataset, ...]:
    """An evaluation's learning curves, entropies and tests; ``prefix`` places the method."""
    c, e, p = (f"curves/{{modes}}/{prefix}{{categories}}/{{strategies}}",
               f"entropy/{{modes}}/{prefix}{{strategies}}",
               f"pvalues/{{modes}}/{prefix}{{categories}}/{{others}}")
    return (
        *(Dataset(f"{c}/{k}", FLOAT, s, nan=True)
          for k, s in (("rmse", ("T",)), ("q25", ("T",)), ("q75", ("T",)),
                       ("median_samples", ("H",)), ("reached", ("H",)))),
        Dataset(f"{c}/samples_to_threshold", NUM, ("*", "H"), optional=optional_counts),
        # the report draws these too: when present, of the curves' length (T) or thresholds' (H)
        *(Dataset(f"{c}/{k}", FLOAT, ("T",), optional=True, nan=True)
          for k in ("mean", "median", "std", "rmse_ml", "rmse_mean", "entropy_mean",
                    "entropy_q25", "entropy_median", "entropy_q75")),
        Dataset(f"{c}/rmse_by_param", FLOAT, ("*", "T"), optional=True, nan=True),
        *(Dataset(f"{c}/{k}{sfx}", FLOAT, ("H",), optional=True, nan=True)
          for k in ("median_samples", "reached") for sfx in ("_ml", "_mean")),
        *(Dataset(f"{e}/{k}", FLOAT, ("T",), nan=True) for k in ("mean", "q25", "q75")),
        Dataset(f"{p}/pvalue", FLOAT, ("H",), nan=True),
        Dataset(f"{p}/statistic", FLOAT, ("H",), nan=True),
    )


def _examples(prefix: str) -> tuple[Dataset, ...]:
    x = f"examples/{{modes}}/{prefix}{{strategies}}"
    return (Dataset(f"{x}/row", INT, (), optional=True, index="N"),
            Dataset(f"{x}/snapshots", NUM, ("*", "*", "*"), optional=True, finite=False))


_EVAL_FLAT = (
    Dataset("thresholds", FLOAT, ("H",)),
    Dataset("experiments/params", FLOAT, ("N", "P")),
    Dataset("experiments/mode", TEXT, ("N",)),
    Dataset("experiments/category", TEXT, ("N",)),
    Dataset("experiments/strategy", TEXT, ("N",)),
    *(Dataset(f"experiments/play_{k}", FLOAT, ("N",), optional=True, nan=True)
      for k in ("adapted", "unadapted", "before")),
)
_EVALUATION_1 = Schema(
    attrs={"modes": "strs", "categories": "strs", "strategies": "strs", "baseline": "str",
           "max_steps": "int"},
    config={"categories": "dict", "experiments": "int"},
    datasets=(*_EVAL_FLAT, *_curves("", False), *_examples("")),
    checks=(rules.eval_lists,),
)
# evaluation 2: named methods (each with its own modes, categories and strategies), measured
# playing success, tie-corrected tests
_EVALUATION_2 = Schema(
    attrs={**_EVALUATION_1.attrs, "methods": "dict", "method_order?": "strs"},
    config=_EVALUATION_1.config,
    datasets=(
        *_EVAL_FLAT,
        Dataset("experiments/method", TEXT, ("N",)),
        *_curves("{method}/", True),
        Dataset("pvalues/{modes}/{method}/{categories}/{others}/min_pvalue", FLOAT, (),
                optional=True, nan=True),
        *_examples("{method}/"),
    ),
    checks=(rules.eval_lists, rules.eval_methods),
)
# model_quality 1: the model-quality sweep (kbcli quality)
_MODEL_QUALITY_1 = Schema(
    datasets=(
        Dataset("experiments/model", TEXT, ("N",)),
        Dataset("experiments/category", TEXT, ("N",)),
        Dataset("experiments/row", TEXT, ("N",)),
        Dataset("experiments/param_index", INT, ("N",)),
        Dataset("experiments/rep", INT, ("N",)),
        Dataset("experiments/errors", FLOAT, ("N", "T"), nan=True),
    ),
    attrs={"models": "dict", "summary": "dict", "rows": "strs", "baseline": "str",
           "max_steps": "int", "categories": "strs", "n_experiments": "int"},
    config={"mode": "str", "arm": "dict", "experiments": "int", "budgets": "nums",
            "explorations": "strs", "rows": "dict"},
    checks=(rules.quality_lists,),
)

SCHEMAS: dict[str, dict[int, Schema]] = {
    "keyboard": {1: _KEYBOARD_1, 2: _KEYBOARD_2},
    "model": {1: _MODEL_1, 2: _MODEL_2, 3: _MODEL_3},
    "scene": {1: _SCENE_1},
    "history": {1: _HISTORY_1},
    "detection": {1: _DETECTION_1, 2: _DETECTION_2},
    # run 3, closed_loop 3: the adapt config nests the robot's options under "robot"; run 4,
    # closed_loop 4, evaluation 3, model_quality 2: the robot's parts hold their own options
    # (older ones are migrated on read: :mod:`kbcli.io.schema.migrate`)
    "run": {1: _RUN_1, 2: _RUN_2, 3: _RUN_2, 4: _RUN_2},
    "closed_loop": {1: _CLOSED_LOOP_1, 2: _CLOSED_LOOP_2, 3: _CLOSED_LOOP_2, 4: _CLOSED_LOOP_2},
    "evaluation": {1: _EVALUATION_1, 2: _EVALUATION_2, 3: _EVALUATION_2},
    "model_quality": {1: _MODEL_QUALITY_1, 2: _MODEL_QUALITY_1},
}


def schema_for(kind: str, version: int) -> Schema | None:
    """The schema of the highest version of ``kind`` not above ``version`` (None if none)."""
    versions = [v for v in SCHEMAS.get(kind, {}) if v <= version]
    return SCHEMAS[kind][max(versions)] if versions else None
