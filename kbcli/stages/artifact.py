"""The in-memory form of a stage output, independent of how it is stored.

An artifact carries its kind, the full config that made it, the seed, references to its input
artifacts (kind and sha256, recursively: the provenance chain), small metadata (``attrs``) and
arrays (``data``, nested dicts become HDF5 groups). :mod:`kbcli.io.artifact` writes it to HDF5.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kbcli import __version__

#: Current schema version of every artifact kind. Bump a kind's version when its layout changes.
SCHEMA_VERSIONS: dict[str, int] = {
    "keyboard": 2,
    "model": 3,
    "scene": 1,
    "history": 1,
    "detection": 2,  # 2: the detector holds its own options (1 still read)
    "run": 4,  # 2: joint_angles (dynamics mode), attrs arm and mode; serve sessions (no truth);
    #            3: the adapt config holds the robot's options under "robot" (2 still read);
    #            4: the robot's strategy and posterior hold their own options (3 still read)
    "closed_loop": 4,  # 2: steps/joint_angles, steps/estimate, the adaptation posteriors; 3, 4: as run
    "evaluation": 3,  # 2: named methods, measured playing success, tie-corrected tests; 3: as run 4
    "model_quality": 2,  # 2: as run 4
}


@dataclass
class Artifact:
    """One stage output: ``kind`` (one of :data:`SCHEMA_VERSIONS`), the full JSON-serialisable
    ``config`` of the stage that made it, its ``seed`` (None for deterministic stages), ``data``
    (arrays by name; a nested dict is a group), ``attrs`` (small JSON metadata), ``inputs`` (role
    -> :func:`ref`) and ``sha256`` of the file it was read from (None when made in memory)."""

    kind: str
    config: dict
    seed: int | None = None
    data: dict[str, Any] = field(default_factory=dict)
    attrs: dict[str, Any] = field(default_factory=dict)
    inputs: dict[str, dict] = field(default_factory=dict)
    schema_version: int | None = None
    kbcli_version: str = __version__
    sha256: str | None = None
    path: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in SCHEMA_VERSIONS:
            raise ValueError(f"unknown artifact kind {self.kind!r}; valid: {', '.join(SCHEMA_VERSIONS)}")
        if self.schema_version is None:
            self.schema_version = SCHEMA_VERSIONS[self.kind]

    def array(self, name: str) -> np.ndarray:
        """A dataset by slash path ('samples/actions')."""
        node: Any = self.data
        for part in name.split("/"):
            node = node[part]
        return np.asarray(node)


def ref(art: Artifact) -> dict:
    """A reference to an input artifact: kind, sha256, file name and its own inputs (the chain)."""
    import os

    return {
        "kind": art.kind,
        "sha256": art.sha256,
        "file": os.path.basename(art.path) if art.path else None,
        "inputs": art.inputs,
    }
