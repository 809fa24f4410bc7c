"""Structural validation of artifacts on read: per kind and schema version, the datasets, summary
attributes and config entries that readers rely on, with their dtype kind and shape.

One table, :data:`SCHEMAS` (:mod:`kbcli.io.schema.kinds`), kind -> schema version ->
:class:`Schema`. A new dataset is a :class:`Dataset` line in the kind's current schema; a new
version (:data:`kbcli.stages.artifact.SCHEMA_VERSIONS`) is a new entry beside the old ones: a file
is checked against the schema of the highest version not above its own. Shapes, indices and path
placeholders: :class:`Dataset`.

:func:`validate` raises :class:`~kbcli.errors.ArtifactError` naming the first thing wrong:
"history.h5: dataset 'target' has 119 rows, expected 120 (as 'result')".
"""

from kbcli.io.schema.check import problem, validate
from kbcli.io.schema.kinds import MODEL_ARRAYS, SCHEMAS, schema_for
from kbcli.io.schema.spec import MIN_SOUNDS, Dataset, Schema

__all__ = ["MIN_SOUNDS", "MODEL_ARRAYS", "SCHEMAS", "Dataset", "Schema", "problem", "schema_for",
           "validate"]
