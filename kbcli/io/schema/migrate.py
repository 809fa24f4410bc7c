"""The one migration of stored configs: the flat options of kbcli before parts owned their
options (the robot's, the detector's), read in the nested layout.

Until run 3, closed loop 3, evaluation 2 and model quality 1, an artifact recorded the adapter's
config flat (``{"posterior": "likelihood", "kde_samples": 10000, "candidates": 256, ...}``; schema
1 and 2 runs with the loop's options beside them). Read now, each such robot config has its parts'
options moved into the parts and the options the chosen parts do not take dropped: the same
numbers, the current layout (:func:`kbcli.core.options.route`, lenient). A detector config recorded
flat (detection 1, closed loop 4) is known by its shape and read the same way, wherever it is.
"""

from __future__ import annotations

from typing import Any

from kbcli.core.adaptation.config import SLOTS, AdapterConfig, option_names
from kbcli.core.detection.detectors.base import SLOTS as DETECTOR_SLOTS
from kbcli.core.detection.detectors.base import DetectorConfig
from kbcli.core.options import route

#: The first schema of each kind that records the robot's parts nested (older ones are migrated).
NESTED = {"run": 4, "closed_loop": 4, "evaluation": 3, "model_quality": 2}
#: The robot's parts that held options when a flat config was recorded (its estimator, a name,
#: is kept as it is).
FLAT_SLOTS = {k: SLOTS[k] for k in ("strategy", "posterior")}


def _flat_robot(v: Any) -> bool:
    return isinstance(v, dict) and isinstance(v.get("posterior"), str)


def nest(robot: dict) -> dict:
    """A flat recorded robot config in the nested layout."""
    return route(robot, FLAT_SLOTS, AdapterConfig.model_fields, strict=False)


def _flat_detector(v: Any) -> bool:
    return isinstance(v, dict) and isinstance(v.get("detector"), str)


def nest_detector(table: dict) -> dict:
    """A flat recorded detector config in the nested layout (other keys, such as a detection's
    ``perturb_at``, kept)."""
    return route(table, DETECTOR_SLOTS, DetectorConfig.model_fields, strict=False)


def _walk(tree: Any) -> Any:
    if isinstance(tree, list):
        return [_walk(v) for v in tree]
    if not isinstance(tree, dict):
        return tree
    out = {}
    for k, v in tree.items():
        if k == "robot" and _flat_robot(v):
            out[k] = nest(v)
        elif k == "detector" and _flat_detector(v):
            out[k] = nest_detector(v)
        elif k == "adapt" and _flat_robot(v) and "robot" not in v:  # schema 1-2 runs: all flat
            robot = {o: x for o, x in v.items() if o in option_names()}
            out[k] = {**{o: x for o, x in v.items() if o not in robot}, "robot": nest(robot)}
        else:
            out[k] = _walk(v)
    return out


def upgrade(art) -> Any:
    """``art`` with its config and attributes in the current layout (the artifact itself when its
    schema records it already)."""
    if art.kind == "detection" and _flat_detector(art.config):
        art.config = nest_detector(art.config)
    elif art.kind == "closed_loop" or art.schema_version < NESTED.get(art.kind, 0):
        art.config = _walk(art.config)
        art.attrs = _walk(art.attrs)
    return art
