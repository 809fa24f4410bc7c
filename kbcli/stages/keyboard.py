"""Stage ``keyboard``: build the instrument artifact from a keyboard config (paper Fig. 2).

Schema 2 (any layout): the config (with its ``layout``), per-key ``features`` (pitch, tempo),
``names``, ``key_centres`` (a point inside each key) and the keys' outlines at the reference pose,
``outlines/vertices`` (all outlines' vertices, concatenated) and ``outlines/offsets`` (K + 1: key
k's vertices are rows ``offsets[k]:offsets[k + 1]``; a pad's outline is a 64-gon). Attrs: ``n_keys``,
``layout``, ``area`` and ``bounds``. Schema 1 artifacts (grid only, no ``layout``) still load.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.stages.artifact import Artifact


def run(cfg: KeyboardConfig) -> Artifact:
    """The keyboard artifact: config, per-key features, names, centres and outlines, and the
    working area."""
    kb = Keyboard(cfg)
    outlines = kb.key_outlines()
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in outlines])]).astype(np.int64)
    return Artifact(
        kind="keyboard",
        config=cfg.to_dict(),
        seed=None,
        data={
            "features": np.asarray(kb.features),
            "feature_names": np.array(["pitch", "tempo"]),
            "names": np.array(kb.names),
            "key_centres": kb.key_centres(),
            "outlines": {"vertices": np.vstack(outlines), "offsets": offsets},
        },
        attrs={"n_keys": kb.n_keys, "layout": cfg.layout.name, "area": list(kb.area),
               "bounds": list(kb.bounds)},
    )


def load(art: Artifact) -> Keyboard:
    """The :class:`Keyboard` described by a keyboard artifact (or any artifact whose config has a
    ``keyboard`` table)."""
    cfg = art.config if art.kind == "keyboard" else art.config["keyboard"]
    return Keyboard(KeyboardConfig.from_dict(cfg))
