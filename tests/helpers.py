"""Assertions shared by the test files (pytest puts tests/ on the import path)."""

from __future__ import annotations


def one_line_error(result, *fragments):
    """A CLI result that failed cleanly: exit 1, one ``kbcli: error:`` line holding every fragment,
    no traceback."""
    assert result.exit_code == 1, result.output
    lines = [ln for ln in result.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kbcli: error:"), result.output
    for f in fragments:
        assert f in lines[0], lines[0]
    assert "Traceback" not in result.output
