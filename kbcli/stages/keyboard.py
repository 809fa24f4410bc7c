"""Stage ``keyboard``: build the instrument artifact from a keyboard config (paper Fig. 2)."""

from __future__ import annotations

import numpy as np

from kbcli.core.keyboard import Keyboard, KeyboardConfig
from kbcli.stages.artifact import Artifact


def run(cfg: KeyboardConfig) -> Artifact:
    """The keyboard artifact: config, per-key features, names and centres, and the working area."""
    kb = Keyboard(cfg)
    return Artifact(
        kind="keyboard",
        config=cfg.to_dict(),
        seed=None,
        data={
            "features": np.asarray(kb.features),
            "feature_names": np.array(["pitch", "tempo"]),
            "names": np.array(kb.names),
            "key_centres": kb.key_centres(),
        },
        attrs={"n_keys": kb.n_keys, "area": list(kb.area), "bounds": list(kb.bounds)},
    )


def load(art: Artifact) -> Keyboard:
    """The :class:`Keyboard` described by a keyboard artifact (or any artifact whose config has a
    ``keyboard`` table)."""
    cfg = art.config if art.kind == "keyboard" else art.config["keyboard"]
    return Keyboard(KeyboardConfig.from_dict(cfg))
