"""The documentation site: generated from its sources, built strictly, its examples run.

The CLI reference is read from the Typer app, so it names every command; the results pages are
rendered from result files, so regenerating them from the same file gives the same page. Every
command example of the pages runs: tests/test_doc_examples.py."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import typer

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "tools" / "docs_hooks.py")
hooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hooks)


def _command_paths(cmd, path="kbcli"):
    yield path
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from _command_paths(sub, f"{path} {name}")


def test_cli_reference_names_every_command_and_option():
    from kbcli.cli import app

    text = hooks.cli_markdown()
    tree = typer.main.get_command(app)
    paths = list(_command_paths(tree))
    assert len(paths) > 20
    for p in paths:
        assert f"`{p}`" in text, p
    assert "`--max-steps <int range>`" in text or "--max-steps" in text
    assert "--posterior" in text and "--strategy" in text


def test_results_page_renders_a_result_file(tmp_path):
    d = {"command": "kbcli bench detect", "date": "2026-12-03", "machine": "2 cores",
         "kbcli_version": "0.1.0",
         "tables": [{"title": "delay", "columns": ["detector", "|delay|"],
                     "rows": [{"detector": "binomial", "|delay|": 12.25},
                              {"detector": "a|b", "|delay|": 3}]}]}
    (tmp_path / "detect.json").write_text(json.dumps(d))
    page = hooks.results_markdown("detect", tmp_path)
    assert "Measured with `kbcli bench detect` on 2026-12-03, kbcli 0.1.0, 2 cores." in page
    assert "| binomial | 12.25 |" in page and "| a\\|b | 3 |" in page
    assert "| detector | \\|delay\\| |" in page  # a header's bars escaped too
    assert hooks.results_markdown("detect", tmp_path) == page     # regenerates identically
    assert "not there yet" in hooks.results_markdown("missing", tmp_path)
    d["load"] = {"start": [6.83, 6.5, 6.1], "end": [4.25, 5.0, 6.0], "cores": 2}
    (tmp_path / "detect.json").write_text(json.dumps(d))
    assert ("2 cores, load average 6.8 (1 min) at the start and 4.2 at the end."
            in hooks.results_markdown("detect", tmp_path))


def test_markers_are_replaced(monkeypatch):
    monkeypatch.setattr(hooks, "cli_markdown", lambda: "CLI")
    monkeypatch.setattr(hooks, "results_markdown",
                        lambda name, only=(): f"R[{name}{''.join('/' + t for t in only)}]")
    out = hooks.on_page_markdown("a <!-- cli-reference --> b <!-- results: learn --> c "
                                 "<!-- results: reproduce | Verdicts | Wall time of each stage -->")
    assert out == "a CLI b R[learn] c R[reproduce/Verdicts/Wall time of each stage]"


def _markers():
    """Every ``<!-- results: NAME | TITLE ... -->`` of the documentation: (page, name, titles)."""
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for m in hooks._RESULTS.finditer(page.read_text()):
            yield page.relative_to(ROOT), m.group(1), tuple(
                t.strip() for t in m.group(2).split("|") if t.strip())


def test_every_results_marker_regenerates_identically_from_its_stored_file():
    """The results pages from the stored result files: each file has the keys the page shows, the
    tables a marker names exist, and rendering it again changes nothing."""
    markers = list(_markers())
    names = {name for _, name, _ in markers}
    assert {"reproduce", "model-quality", "learn", "learn-peer", "speed"} <= names
    for page, name, only in markers:
        path = hooks.RESULTS / f"{name}.json"
        if not path.exists():
            assert "not there yet" in hooks.results_markdown(name, only=only), (page, name)
            continue
        d = json.loads(path.read_text())
        assert {"command", "date", "machine", "kbcli_version", "tables"} <= set(d), path
        for t in d["tables"]:
            assert {"title", "columns", "rows"} <= set(t), path
            assert all(set(r) <= set(t["columns"]) for r in t["rows"]), (path, t["title"])
        md = hooks.results_markdown(name, only=only)
        assert md.startswith(f"Measured with `{d['command']}`"), (page, name)
        assert md == hooks.results_markdown(name, only=only), (page, name)
        for title in only:
            assert f"**{title}" in md, (page, name, title)


def test_a_marker_naming_a_missing_table_fails_the_build(tmp_path):
    d = {"command": "kbcli bench x", "date": "d", "machine": "m", "kbcli_version": "v",
         "tables": [{"title": "Verdicts", "columns": ["a"], "rows": [{"a": 1}]}]}
    (tmp_path / "x.json").write_text(json.dumps(d))
    assert "**Verdicts**" in hooks.results_markdown("x", tmp_path, only=("Verd",))
    with pytest.raises(ValueError, match="no table titled Timings"):
        hooks.results_markdown("x", tmp_path, only=("Timings",))


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site as ``make docs`` builds it (strictly), once for the tests that read it."""
    mk = Path(sys.executable).parent / "mkdocs"
    if shutil.which("mkdocs") is None and not mk.exists():
        pytest.skip("mkdocs is in the docs extra, which make test installs")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    r = subprocess.run([str(mk) if mk.exists() else "mkdocs", "build", "--strict", "--site-dir",
                        str(out)], cwd=ROOT, capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    return out


def test_the_site_builds_strictly(site):
    cli = (site / "reference" / "cli.html").read_text()
    assert "kbcli adapt" in cli and "kbcli bench detect" in cli
    broken = _broken_links(site)
    assert not broken, broken[:5]


def _broken_links(site: Path) -> list[tuple[str, str]]:
    """Every relative link and source of the built pages that does not name a file, as a browser
    opening them from disk (``file://``) resolves it: a link to a folder shows a directory listing
    there (issue 40). The 404 page is for a web server (its links start at the site's root)."""
    from urllib.parse import unquote, urlsplit

    bad, seen = [], 0
    for page in sorted(site.rglob("*.html")):
        if page.name == "404.html":
            continue
        for ref in re.findall(r'(?:href|src)="([^"]+)"', page.read_text(errors="replace")):
            u = urlsplit(ref)
            if u.scheme or u.netloc or not u.path:
                continue
            seen += 1
            if not (page.parent / unquote(u.path)).is_file():
                bad.append((str(page.relative_to(site)), ref))
    assert seen > 100  # the check saw the navigation
    return bad


def test_a_bench_command_writes_the_result_file_the_docs_render(tmp_path):
    from typer.testing import CliRunner

    from kbcli.cli import app

    out = tmp_path / "arm.json"
    r = CliRunner().invoke(app, ["bench", "--json", str(out), "arm", "--reaches", "20"])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    assert d["command"].startswith("kbcli") and d["kbcli_version"] and d["machine"]
    (table,) = d["tables"]
    assert table["columns"][0] == "preset" and len(table["rows"]) >= 3
    page = hooks.results_markdown("arm", tmp_path)
    assert table["rows"][0][table["columns"][2]] in page
    bad = CliRunner().invoke(app, ["bench", "--json", str(tmp_path / "arm.h5"), "arm"])
    assert bad.exit_code == 1 and "must end in .json" in bad.output
    assert not (tmp_path / "arm.h5").exists()


def test_the_robot_tutorial_states_the_protocols_limits(site):
    """Issue 40: serve's 64 KiB line limit was documented nowhere. The page's transcript (a real
    session, run by the build's hook) is readable without scrolling."""
    import html

    from kbcli.stages.serve import MAX_DIGITS, MAX_LINE

    page = (ROOT / "docs" / "tutorials" / "robot.md").read_text()
    assert f"{MAX_LINE // 1024} KiB" in page and f"({MAX_LINE} bytes" in page
    assert f"{MAX_DIGITS} digits" in page
    built = (site / "tutorials" / "robot.html").read_text()
    blocks = [html.unescape(re.sub(r"<[^>]+>", "", b))
              for b in re.findall(r"<pre[^>]*>(.*?)</pre>", built, re.S)]
    (transcript,) = [b for b in blocks if '"op": "observe"' in b]
    assert max(len(x) for x in transcript.splitlines()) <= hooks.TRANSCRIPT_WIDTH + 20
    assert "/tmp" not in transcript and '"file": "session.h5"' in transcript


def test_long_cells_leave_the_table_for_details_below_it():
    """Issue 40: the claims table squeezed paragraphs of p-values into a narrow column."""
    rows = [{"claim": "Sect. IV-B, Fig. 7", "says": "small displacements: active beats random, "
             "p < 1e-5 for RMSE thresholds up to 10 px", "verdict": "differs",
             "measured": "p < 1e-05 at 2 px (p=1.9e-06); " * 8}]
    md = "\n".join(hooks._table(rows, ["claim", "says", "verdict", "measured"]))
    table = [x for x in md.splitlines() if x.startswith("|")]
    assert table[0] == "| # | claim | says | verdict |"
    assert all(len(cell.strip()) <= hooks.NAME_CELL
               for x in table[2:] for cell in x.strip("|").split("|"))
    assert "Details:" in md and rows[0]["measured"].strip() in md and rows[0]["says"] in md
    short = "\n".join(hooks._table([{"a": "x", "b": "y", "c": "z"}], ["a", "b", "c"]))
    assert "Details" not in short and short.splitlines()[0] == "| a | b | c |"


def test_the_readme_says_what_reproduces_from_the_stored_result():
    """The README's "What reproduces" is the table of benchmarks/results/reproduce.json, written
    by ``python tools/docs_hooks.py --readme``: regenerating it changes nothing."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert hooks.README_START in text and hooks.README_END in text
    section = text.split(hooks.README_START)[1].split(hooks.README_END)[0]
    assert section.strip() == hooks.readme_section().strip(), \
        "README.md is stale: run python tools/docs_hooks.py --readme"
    assert "| claim |" in section


def test_rewriting_the_readme_replaces_only_its_generated_section(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    (results / "reproduce.json").write_text(json.dumps({
        "command": "kbcli bench verdicts e.h5", "date": "2026-12-07", "machine": "m",
        "kbcli_version": "0", "tables": [
            {"title": "What reproduces", "columns": ["claim", "verdict"],
             "rows": [{"claim": "small", "verdict": "agrees"}]},
            {"title": "Other", "columns": ["x"], "rows": [{"x": "1"}]}]}))
    readme = tmp_path / "README.md"
    readme.write_text(f"# title\n\nbefore\n\n{hooks.README_START}\nold table\n{hooks.README_END}\n"
                      "after\n", encoding="utf-8")
    assert hooks.rewrite_readme(readme, results) is True
    new = readme.read_text(encoding="utf-8")
    assert new.startswith("# title\n\nbefore\n\n") and new.endswith(f"{hooks.README_END}\nafter\n")
    assert "old table" not in new and "| small | agrees |" in new and "| 1 |" not in new
    assert hooks.rewrite_readme(readme, results) is False  # a second run changes nothing
    readme.write_text("no markers\n", encoding="utf-8")
    with pytest.raises(ValueError, match="no generated section"):
        hooks.rewrite_readme(readme, results)
