"""Known-answer tests of the artifact schema's index bounds (issue 25: an off-by-one in the bound
check, accepting an index equal to the axis length, must fail a fast unit test).

An index into an axis of length n lies in [0, n - 1]; a step count (``upto``) in [0, n]. The
artifacts are built in memory, so the schema is checked without HDF5 or a keyboard.
"""

from __future__ import annotations

import numpy as np
import pytest

from kbcli.errors import ArtifactError
from kbcli.io.schema import problem, validate
from kbcli.io.schema.check import bound_error
from kbcli.stages.artifact import Artifact

T = 6  # steps of the detection


def _detection(firings) -> Artifact:
    """A detection over T steps that fired at ``firings`` (indices into the T steps)."""
    return Artifact(
        kind="detection", config={"detector": "cusum", "threshold": 1.0}, schema_version=1,
        data={"score": np.zeros(T), "fired": np.zeros(T, bool),
              "firings": np.asarray(firings, dtype=np.int64)})


def _run(snapshot_steps) -> Artifact:
    """A run of T steps with snapshots after ``snapshot_steps`` (steps, 0..T allowed)."""
    s = len(snapshot_steps)
    data = {k: np.zeros((T, 2)) for k in ("actions", "landed", "means", "estimates")}
    data |= {"classes": np.zeros(T, np.int64), "errors": np.zeros(T), "entropy": np.zeros(T),
             "dx": np.zeros(3), "dy": np.zeros(4),
             "snapshot_steps": np.asarray(snapshot_steps, dtype=np.int64),
             "snapshots": np.zeros((s, 4, 3))}
    return Artifact(kind="run", config={}, attrs={"steps": T}, schema_version=1, data=data)


def test_bound_error_known_answers():
    # an index into 5 rows: 4 is the last valid one, 5 is one past the end
    assert bound_error(np.array([0, 4]), 5, inclusive=False) is None
    assert bound_error(np.array([0, 5]), 5, inclusive=False) == 4
    assert bound_error(np.array([-1]), 5, inclusive=False) == 4
    # steps of a run of 5: 5 (after the last step) is allowed, 6 is not
    assert bound_error(np.array([0, 5]), 5, inclusive=True) is None
    assert bound_error(np.array([6]), 5, inclusive=True) == 5
    assert bound_error(np.array([], dtype=int), 0, inclusive=False) is None


def test_an_index_of_the_last_row_is_accepted():
    assert problem(_detection([0, T - 1])) is None
    validate(_detection([T - 1]), "d.h5")


def test_an_index_equal_to_the_axis_length_is_refused():
    msg = problem(_detection([1, T]))
    assert msg == f"dataset 'firings' holds values outside [0, {T - 1}]"
    with pytest.raises(ArtifactError, match=r"^d\.h5: detection artifact: dataset 'firings'"):
        validate(_detection([T]), "d.h5")


def test_a_negative_index_is_refused():
    assert problem(_detection([-1])) == f"dataset 'firings' holds values outside [0, {T - 1}]"


def test_a_step_equal_to_the_axis_length_is_accepted_one_more_is_not():
    assert problem(_run([0, T])) is None
    assert problem(_run([0, T + 1])) == f"dataset 'snapshot_steps' holds values outside [0, {T}]"
