"""Build and load model artifacts (kind ``model``), whatever made them.

A model artifact's config always holds a ``keyboard`` table (the instrument it models) and a
``strategy``: ``exact`` (the keyboard's own geometry) or the exploration strategy that learned it;
a learned one also its ``model_class`` (:mod:`kbcli.core.model.classes`; absent in schema 1
artifacts, which are all ``lines``). The model is rebuilt from plain arrays by its class's
``from_arrays``: kbcli never unpickles a file.
"""

from __future__ import annotations

from kbcli.core.model.base import SoundModel
from kbcli.core.model.classes import EXACT, MODEL_CLASSES, model_class_of
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import Artifact, ref


def exact_artifact(kb_art: Artifact) -> Artifact:
    """A model artifact for the ``exact`` model of a keyboard artifact."""
    return Artifact(
        kind="model",
        config={"strategy": EXACT, "keyboard": kb_art.config},
        seed=None,
        inputs={"keyboard": ref(kb_art)},
        attrs={"strategy": EXACT},
    )


def load_model(art: Artifact) -> SoundModel:
    """The model (:class:`~kbcli.core.model.base.SoundModel`) stored in a model artifact: its
    class's ``load`` (:data:`~kbcli.core.model.classes.MODEL_CLASSES`)."""
    kb = keyboard_stage.load(art)
    mc = MODEL_CLASSES.get(model_class_of(art.config))
    if not mc.learned:
        return mc.load(None, kb)
    model = mc.load(art.data["model"])
    rel = art.attrs.get("reliability")
    #: the model's own estimate of its quality (model schema 2; None before)
    model.reliability_ = dict(rel) if isinstance(rel, dict) else None
    return model

