"""HDF5 artifacts: round trips, determinism, provenance, atomic writes, and bad files rejected."""

from __future__ import annotations

import os
import shutil
import subprocess
import time

import h5py
import numpy as np
import pytest

from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.errors import ArtifactError
from kbcli.io.artifact import describe, read_artifact, sha256_file, write_artifact
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.artifact import SCHEMA_VERSIONS, Artifact, ref


def _art(**kw):
    data = {"x": np.arange(5000.0), "grp": {"y": np.ones((3, 2), np.int32), "names": np.array(["a", "bé"])}}
    return Artifact(kind="keyboard", config={"a": 1, "b": [1.5, 2]}, seed=7, data=data, attrs={"n": 3}, **kw)


def test_round_trip_preserves_everything(tmp_path):
    art = _art()
    digest = write_artifact(art, tmp_path / "a.h5")
    back = read_artifact(tmp_path / "a.h5", "keyboard", validate=False)
    assert back.sha256 == digest == sha256_file(tmp_path / "a.h5")
    assert (back.kind, back.config, back.seed, back.attrs) == ("keyboard", art.config, 7, {"n": 3})
    assert back.schema_version == SCHEMA_VERSIONS["keyboard"]
    np.testing.assert_array_equal(back.data["x"], art.data["x"])
    np.testing.assert_array_equal(back.data["grp"]["y"], art.data["grp"]["y"])
    assert back.data["grp"]["y"].dtype == np.int32
    assert back.data["grp"]["names"].tolist() == ["a", "bé"]


def test_seed_zero_and_none_are_distinct(tmp_path):
    a = Artifact(kind="keyboard", config={}, seed=0)
    b = Artifact(kind="keyboard", config={}, seed=None)
    write_artifact(a, tmp_path / "a.h5")
    write_artifact(b, tmp_path / "b.h5")
    assert read_artifact(tmp_path / "a.h5", validate=False).seed == 0
    assert read_artifact(tmp_path / "b.h5", validate=False).seed is None


def test_same_inputs_give_identical_bytes(tmp_path):
    """No timestamps anywhere: two writes more than a second apart give the same bytes."""
    write_artifact(_art(), tmp_path / "a.h5")
    time.sleep(1.1)
    write_artifact(_art(), tmp_path / "b.h5")
    assert sha256_file(tmp_path / "a.h5") == sha256_file(tmp_path / "b.h5")


def test_file_mode_is_0644_and_no_temp_left(tmp_path):
    write_artifact(_art(), tmp_path / "a.h5")
    assert oct(os.stat(tmp_path / "a.h5").st_mode & 0o777) == "0o644"
    assert sorted(os.listdir(tmp_path)) == ["a.h5"]


def test_failed_write_leaves_nothing(tmp_path):
    bad = _art()
    bad.data["obj"] = np.array([object()], dtype=object)  # h5py cannot store this
    with pytest.raises(TypeError):
        write_artifact(bad, tmp_path / "a.h5")
    assert os.listdir(tmp_path) == []


def test_failed_write_keeps_previous_file(tmp_path):
    write_artifact(_art(), tmp_path / "a.h5")
    before = sha256_file(tmp_path / "a.h5")
    bad = _art()
    bad.data["obj"] = np.array([object()], dtype=object)
    with pytest.raises(TypeError):
        write_artifact(bad, tmp_path / "a.h5")
    assert sha256_file(tmp_path / "a.h5") == before
    assert os.listdir(tmp_path) == ["a.h5"]


def test_provenance_chain_is_recorded(tmp_path):
    kb = keyboard_stage.run(KeyboardConfig())
    write_artifact(kb, tmp_path / "kb.h5")
    kb = read_artifact(tmp_path / "kb.h5")
    child = Artifact(kind="model", config={}, inputs={"keyboard": ref(kb)})
    write_artifact(child, tmp_path / "m.h5")
    child = read_artifact(tmp_path / "m.h5", validate=False)
    grandchild = Artifact(kind="scene", config={}, inputs={"model": ref(child)})
    write_artifact(grandchild, tmp_path / "s.h5")
    d = describe(tmp_path / "s.h5")
    assert d["inputs"]["model"]["sha256"] == sha256_file(tmp_path / "m.h5")
    assert d["inputs"]["model"]["inputs"]["keyboard"]["sha256"] == sha256_file(tmp_path / "kb.h5")
    with h5py.File(tmp_path / "s.h5") as f:
        assert f.attrs["input_sha256.model"] == sha256_file(tmp_path / "m.h5")


def test_missing_file(tmp_path):
    with pytest.raises(ArtifactError, match="no such file"):
        read_artifact(tmp_path / "nope.h5")


def test_not_hdf5(tmp_path):
    (tmp_path / "t.h5").write_text("hello")
    with pytest.raises(ArtifactError, match="not an HDF5 file"):
        read_artifact(tmp_path / "t.h5")


def test_truncated_file(tmp_path):
    write_artifact(_art(), tmp_path / "a.h5")
    data = (tmp_path / "a.h5").read_bytes()
    for cut in (len(data) // 2, len(data) - 100, 600):
        (tmp_path / "t.h5").write_bytes(data[:cut])
        assert h5py.is_hdf5(tmp_path / "t.h5")  # why a signature check alone is not enough
        with pytest.raises(ArtifactError, match="truncated or corrupt"):
            read_artifact(tmp_path / "t.h5")


def test_plain_hdf5_is_not_an_artifact(tmp_path):
    with h5py.File(tmp_path / "p.h5", "w") as f:
        f["x"] = [1, 2]
    with pytest.raises(ArtifactError, match="not a kbcli artifact"):
        read_artifact(tmp_path / "p.h5")


def test_wrong_kind(tmp_path):
    write_artifact(_art(), tmp_path / "a.h5")
    with pytest.raises(ArtifactError, match="is a keyboard artifact, expected model"):
        read_artifact(tmp_path / "a.h5", "model")


def test_newer_schema(tmp_path):
    write_artifact(_art(), tmp_path / "a.h5")
    with h5py.File(tmp_path / "a.h5", "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(ArtifactError, match="newer than this kbcli reads.*update kbcli"):
        read_artifact(tmp_path / "a.h5")


@pytest.mark.parametrize("version", [0, -1])
def test_schema_version_below_one_is_refused(tmp_path, version):
    write_artifact(_art(), tmp_path / "a.h5")
    with h5py.File(tmp_path / "a.h5", "a") as f:
        f.attrs["schema_version"] = version
    with pytest.raises(ArtifactError, match=f"a.h5: attribute 'schema_version' must be >= 1, got {version}"):
        read_artifact(tmp_path / "a.h5")


@pytest.mark.skipif(shutil.which("h5dump") is None, reason="h5dump (Debian hdf5-tools) is not installed; .ci/run installs it")
def test_standard_tools_read_the_file(tmp_path):
    write_artifact(_art(), tmp_path / "a.h5")
    dump = subprocess.run(["h5dump", "-A", str(tmp_path / "a.h5")], capture_output=True, text=True, check=True)
    for attr in ("kind", "schema_version", "kbcli_version", "config", "seed", "inputs"):
        assert f'ATTRIBUTE "{attr}"' in dump.stdout
    full = subprocess.run(["h5dump", str(tmp_path / "a.h5")], capture_output=True, text=True)
    assert full.returncode == 0 and "4999" in full.stdout  # the gzip-compressed dataset decodes


def test_unwritable_folder_is_a_clear_error(tmp_path):
    # /proc accepts no new files, even for root
    with pytest.raises(ArtifactError, match="cannot write"):
        write_artifact(_art(), "/proc/kbcli-test.h5")
    with pytest.raises(ArtifactError, match="does not exist"):
        write_artifact(_art(), tmp_path / "missing" / "a.h5")
