"""The Python API's file side: load a model or a keyboard from an artifact.

The objects a robot drives live in the numeric core and are exported lazily by :mod:`kbcli`
(``from kbcli import Adapter, Detector``); this module holds what needs the I/O layer (h5py), so
that the core stays free of it. :class:`Adapter` (``kbcli.Adapter``) is the core's
:class:`kbcli.core.adaptation.adapter.Adapter` whose :meth:`~Adapter.from_model` also takes a model file or
artifact (read with :func:`load_model`).
"""

from __future__ import annotations

import os

from kbcli.core.adaptation.adapter import Adapter as CoreAdapter
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.stages.artifact import Artifact


def _artifact(source: str | os.PathLike | Artifact, kind: str | tuple[str, ...]) -> Artifact:
    if isinstance(source, Artifact):
        kinds = (kind,) if isinstance(kind, str) else kind
        if source.kind not in kinds:
            from kbcli.errors import ArtifactError

            raise ArtifactError(f"{source.path or 'artifact'}: is a {source.kind} artifact, "
                                f"expected {' or '.join(kinds)}")
        return source
    from kbcli.io.artifact import read_artifact

    return read_artifact(source, kind)


def load_model(source: str | os.PathLike | Artifact):
    """The sound model stored in a model artifact (a file path or a loaded artifact).

    Raises
    ------
    ArtifactError
        A missing or unreadable file, or an artifact of another kind.
    """
    from kbcli.stages.models import load_model as _load

    return _load(_artifact(source, "model"))


def load_keyboard(source: str | os.PathLike | Artifact) -> Keyboard:
    """The keyboard of a keyboard, model, scene or run artifact (at its reference pose)."""
    from kbcli.stages import keyboard as keyboard_stage

    return keyboard_stage.load(_artifact(source, ("keyboard", "model", "scene", "run",
                                                  "closed_loop", "history")))


class Adapter(CoreAdapter):
    """The core's :class:`~kbcli.core.adaptation.adapter.Adapter`; :meth:`from_model` also reads a model
    artifact file (``.h5``, kind ``model``) or a loaded
    :class:`~kbcli.stages.artifact.Artifact`.

    Examples
    --------
    ::

        adapter = Adapter.from_model("data/default-model.h5", strategy="infogain", seed=0)
    """

    @staticmethod
    def load(model):
        """A model object as it is; a path or an artifact through :func:`load_model`."""
        return model if hasattr(model, "classify") else load_model(model)


__all__ = ["Adapter", "load_model", "load_keyboard"]
