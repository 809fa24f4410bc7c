"""kbcli: where is my keyboard? Model-based active adaptation of a robot's action space.

A command-line pipeline reproducing Ribes et al., "Where is my keyboard? Model-based active
adaptation of action-space in a humanoid robot": a robot arm that learned where the notes of a
virtual keyboard are notices that the keyboard moved and recovers the displacement with few,
well-chosen touches.

The parts a robot drives from Python are exported here, imported on first use (``import kbcli``
stays light)::

    from kbcli import Adapter, Detector

    adapter = Adapter.from_model("model.h5", strategy="infogain", seed=0)
    action = adapter.suggest()                                  # where to touch
    adapter.observe(action, heard, felt_position=felt)           # what the robot heard and felt
    adapter.estimate(), adapter.posterior, adapter.entropy(), adapter.done()

    detector = Detector(detector="binomial")
    fired = detector.update("NO_MATCH")                          # or 1; "MATCH" / 0 for a success
"""

from __future__ import annotations

import importlib

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (import kbcli stays light)

__version__ = "0.1.0"

#: public name -> module that defines it (imported lazily by :func:`__getattr__`)
_EXPORTS = {
    "Adapter": "kbcli.api",
    "AdapterConfig": "kbcli.core.adaptation.config",
    "Detector": "kbcli.core.detection.detectors",
    "DetectorConfig": "kbcli.core.detection.detectors",
    "load_model": "kbcli.api",
    "load_keyboard": "kbcli.api",
}

__all__ = ["__version__", "Adapter", "AdapterConfig", "Detector", "DetectorConfig", "load_model",
           "load_keyboard"]

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from kbcli.api import Adapter, load_keyboard, load_model
    from kbcli.core.adaptation.config import AdapterConfig
    from kbcli.core.detection.detectors import Detector, DetectorConfig


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'kbcli' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
