"""Structural validation of artifacts on read: per kind and schema version, the datasets, summary
attributes and config entries that readers rely on, with their dtype kind and shape.

One table, :data:`SCHEMAS` (:mod:`kbcli.io.schema.kinds`), kind -> schema version ->
:class:`Schema`. To extend it when you add a dataset, add a :class:`Dataset` line to the kind's
current schema; when you bump a kind's version (:data:`kbcli.stages.artifact.SCHEMA_VERSIONS`), add
a new entry and keep the old ones: a file is checked against the schema of the highest version not
above its own.

A dataset's ``shape`` names its axes: an int is a fixed length, a string a symbol shared by every
dataset of the artifact (``"T"``: all per-step arrays have the same length), ``"*"`` any length.
``index`` says the values index an axis (``index="M"``: every value in ``[0, M)``); ``upto`` allows
the axis length itself (``0 <= v <= T``). Paths may hold ``{name}`` placeholders expanded over a
list in the artifact's summary attributes (``{modes}`` over ``attrs["modes"]``).

:func:`validate` raises :class:`~kbcli.errors.ArtifactError` naming the first thing wrong:
"history.h5: dataset 'target' has 119 rows, expected 120 (as 'result')".

Modules: :mod:`~kbcli.io.schema.spec` (the vocabulary), :mod:`~kbcli.io.schema.rules` (rules
across entries), :mod:`~kbcli.io.schema.kinds` (the table), :mod:`~kbcli.io.schema.check` (:func:`validate`).
"""

from kbcli.io.schema.check import problem, validate
from kbcli.io.schema.kinds import MODEL_ARRAYS, SCHEMAS, schema_for
from kbcli.io.schema.spec import MIN_SOUNDS, Dataset, Schema

__all__ = ["MIN_SOUNDS", "MODEL_ARRAYS", "SCHEMAS", "Dataset", "Schema", "problem", "schema_for",
           "validate"]
