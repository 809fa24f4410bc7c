"""Stage ``adapt``: recover a displaced keyboard's pose with few touches (paper Sect. III-D, III-E).

:func:`experiment` runs one adaptation of the robot's :class:`~kbcli.core.adaptation.loop.Adapter`
against a simulated :class:`~kbcli.sim.World` at a given true pose; :func:`run` does it for a model
artifact and a scene artifact and returns a ``run`` artifact. The scene is read only to build the
world and to score the estimates: the robot's side never sees it.

Per step the artifact stores the action, the landing, the perceived features and class, the
estimates, the error against the truth, the entropy, the most probable cell's probability, the
mass near the estimate, the stopping rule and the robot's time (``timing/step_ms``, the only
dataset that is not reproducible bit for bit); plus posterior snapshots (``snapshots``, and for the
rigid family ``snapshot_angles``) and, in dynamics mode, ``joint_angles`` (schema 2).
:class:`Recorder` and :func:`run_attrs` build the same artifact for ``kbcli serve``, where the
truth is unknown and the errors are NaN.

:class:`AdaptConfig` (:mod:`.config`) holds the robot's
:class:`~kbcli.core.adaptation.loop.AdapterConfig` as ``robot`` beside the simulated arm's and the
loop's options (stored nested; schema 1's flat layout is still read). :func:`play_success`
measures the playing success around an adaptation (:func:`kbcli.core.playing.play.replay`).
"""

from __future__ import annotations

from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.stages.adapt.config import (
    DEFAULT_SNAPSHOTS,
    FEEDBACKS,
    LOOP_FIELDS,
    AdaptConfig,
    PlayCheck,
)
from kbcli.stages.adapt.loop import (
    build_shared_samples,
    build_shared_table,
    estimate_errors,
    experiment,
    play_success,
)
from kbcli.stages.adapt.record import (
    RECORDS,
    Recorder,
    end_angles,
    run_attrs,
    run_data,
    steps_below,
)
from kbcli.stages.adapt.stage import check_inputs, run

__all__ = ["AdaptConfig", "PlayCheck", "play_success", "experiment", "run", "check_inputs",
           "steps_below", "build_shared_table", "build_shared_samples", "estimate_errors",
           "LOOP_FIELDS", "Recorder", "run_attrs", "run_data", "RECORDS", "POSTERIORS", "FEEDBACKS",
           "DEFAULT_SNAPSHOTS", "end_angles"]
