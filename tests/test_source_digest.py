"""A checkpoint's code fingerprint: a change to the code that makes numbers refuses a resume; a
change to code that only presents, judges or records them (tables, report, provenance) does not."""
import importlib
import sys

from kbcli.io.checkpoint import PRESENTATION_ONLY, source_digest


def _package(root, name):
    pkg = root / name
    for rel in ("__init__.py", "core/__init__.py", "core/model.py", "bench/__init__.py",
                "bench/tables.py", "cli/report.py", "cli/quality.py"):
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_text(f"# {rel}\n")
    return pkg


def test_only_the_code_that_makes_numbers_is_fingerprinted(tmp_path, monkeypatch):
    pkg = _package(tmp_path, "toypkg_digest")
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
    try:
        before = source_digest("toypkg_digest")
        (pkg / "bench" / "tables.py").write_text("TITLE = 'reworded'\n")
        (pkg / "cli" / "report.py").write_text("WIDTH = 80\n")
        assert source_digest("toypkg_digest") == before
        (pkg / "cli" / "quality.py").write_text("JOBS = 3\n")  # runs the sweep: counts
        after_cli = source_digest("toypkg_digest")
        assert after_cli != before
        (pkg / "core" / "model.py").write_text("SIGN = -1\n")
        assert source_digest("toypkg_digest") != after_cli
        assert source_digest("toypkg_digest", skip=()) != source_digest("toypkg_digest")
    finally:
        sys.modules.pop("toypkg_digest", None)


def test_every_skipped_path_exists_in_kbcli():
    from pathlib import Path

    import kbcli

    root = Path(kbcli.__file__).parent
    for rel in PRESENTATION_ONLY:
        assert (root / rel.rstrip("/")).exists(), rel
