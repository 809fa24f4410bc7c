"""Pipeline stages: one module per stage, each a function ``run(cfg, inputs, *, rng) -> Artifact``.

Stages do no file I/O: they take and return :class:`~kbcli.stages.artifact.Artifact` values, which
:mod:`kbcli.io` reads and writes.
"""
