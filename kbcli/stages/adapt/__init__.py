"""Stage ``adapt``: recover a displaced keyboard's pose with few touches (paper Sect. III-D, III-E).

:func:`experiment` runs one adaptation of the robot's :class:`~kbcli.core.adaptation.loop.Adapter` against a
simulated :class:`~kbcli.sim.World` at a given true pose; :func:`run` does it for a model artifact
and a scene artifact and returns a ``run`` artifact. The scene is read only to build the world and
to score the estimates: the robot's side never sees it.

Per step the artifact stores the action, where the finger landed, the perceived features and class,
the estimates (posterior mean and maximum-likelihood cell), the error against the truth (px, and
degrees for rotations), the entropy (nats), the probability of the most probable cell, the mass
near the estimate, whether the stopping rule held, and the robot's time (``timing/step_ms``: the
only dataset that is not reproducible bit for bit, being wall-clock); plus posterior snapshots at
chosen steps (``snapshots``: the log of the translation marginal; and, rigid family,
``snapshot_angles``: the angle marginal). Schema 2 adds ``joint_angles``, the simulated arm's pose
after each touch in dynamics mode, and the arm's geometry and the mode in the attributes.

:class:`Recorder` and :func:`run_attrs` build the same artifact for a session with a robot in
another process (``kbcli serve``, :mod:`kbcli.stages.serve`): there the truth is unknown and the
errors are NaN (their summaries None).

The stage's config, :class:`AdaptConfig` (:mod:`.config`), holds the robot's :class:`~kbcli.core.adaptation.loop.AdapterConfig`
by composition (``AdaptConfig(robot=AdapterConfig(...), mode=..., reach_noise=...)``) beside the
simulated arm's and the loop's options; run artifacts of schema 2 store it nested
(``config["adapt"]["robot"]``), and the flat layout of schema 1 is still read.

:func:`play_success` measures the playing success around an adaptation by replaying the melody
with Algorithm 1 (:func:`kbcli.core.playing.play.replay`): before the displacement, after it without
adaptation, and after it with the final estimate as the correction (``experiment(play=...)``).
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
