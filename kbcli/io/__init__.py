"""Artifact files: HDF5 (h5py) at the edge of the pipeline."""

from kbcli.io.artifact import read_artifact, write_artifact

__all__ = ["read_artifact", "write_artifact"]
