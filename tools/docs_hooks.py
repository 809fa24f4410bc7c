"""MkDocs hook: pages are filled from their sources at build time, never typed by hand.

- ``<!-- cli-reference -->`` becomes the reference of every ``kbcli`` command and option, read from
  the Typer application itself (its command tree; Typer vendors Click, so the walk is by duck typing);
- ``<!-- results: NAME -->`` becomes the tables of ``benchmarks/results/NAME.json`` (see
  :func:`results_markdown`), with the command, date, machine and kbcli version that produced them;
  ``<!-- results: NAME | TITLE | TITLE -->`` only the tables whose title starts with a TITLE;
- ``<!-- serve-transcript -->`` becomes a real ``kbcli serve`` session with the default model;
- ``<!-- tour -->`` becomes the README's tour (between its ``<!-- tour -->`` and ``<!-- /tour -->``
  lines): one tour, kept in the README, shown in both places.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _command_tree():
    import typer

    from kbcli.cli import app

    return typer.main.get_command(app)


def _option_row(p, ctx) -> str:
    """One row: the option as ``--help`` shows it, and its help (default and range included)."""
    record = p.get_help_record(ctx)
    if record is None:
        return ""
    name, text = record
    if p.param_type_name == "argument":
        name = name.upper()
    return f"| `{name}` | {text.replace('|', chr(92) + '|')} |"


def _command_md(cmd, path: str, level: int) -> list[str]:
    out = [f"{'#' * level} `{path}`", ""]
    if cmd.help:
        out += [cmd.help.strip(), ""]
    with cmd.context_class(cmd, info_name=path) as ctx:
        usage = " ".join(cmd.collect_usage_pieces(ctx))
        rows = [r for p in cmd.params if not getattr(p, "hidden", False)
                if (r := _option_row(p, ctx))]
    out += ["```", f"{path} {usage}".rstrip(), "```", ""]
    if rows:
        out += ["| option | what |", "|---|---|", *rows, ""]
    if hasattr(cmd, "commands"):
        for name in sorted(cmd.commands):
            sub = cmd.commands[name]
            if not getattr(sub, "hidden", False):
                out += _command_md(sub, f"{path} {name}", min(level + 1, 4))
    return out


def cli_markdown() -> str:
    """The reference of every command, group by group, from the Typer app."""
    return "\n".join(_command_md(_command_tree(), "kbcli", 2))


#: A cell longer than this (characters) is a detail: in a table of three or more columns its
#: column leaves the table for a numbered list below it, one entry per row (a paragraph of
#: p-values squeezed into a narrow column made rows hundreds of pixels tall).
LONG_CELL = 60
#: The first column (the row's name) and the first long one stay in the table, cut to this many
#: characters.
NAME_CELL = 48


def _table(rows: list[dict], columns: list[str]) -> list[str]:
    """A Markdown table; with long cells (see :data:`LONG_CELL`), one short line per row (``#``,
    the row's name cut short, the short columns) and the details below it."""
    long = [c for c in columns if any(len(_text(r.get(c, ""))) > LONG_CELL for r in rows)]
    if len(columns) < 3 or not long:
        return _plain_table(rows, columns)
    # the row's name and the first long column, cut short, say which row it is
    lead = list(dict.fromkeys([columns[0], long[0]]))
    short = [c for c in columns if c not in long or c in lead]
    head = ["#", *short]
    out = ["| " + " | ".join(_cell(c) for c in head) + " |", "|" + "---|" * len(head)]
    for i, r in enumerate(rows, 1):
        cells = [str(i), *(_cell(_cut(_text(r.get(c, "")))) if c in lead else _cell(r.get(c, ""))
                           for c in short)]
        out.append("| " + " | ".join(cells) + " |")
    name = columns[0]
    out += ["", "Details:", ""]
    for i, r in enumerate(rows, 1):
        parts = [f"*{_escape(c)}:* {_escape(_text(r.get(c, '')))}" for c in long
                 if c != name and _text(r.get(c, ""))]
        label = f"**{_escape(_text(r.get(name, '')))}**"
        out.append(f"{i}. {label}" + (": " + "; ".join(parts) if parts else ""))
    return out


def _plain_table(rows: list[dict], columns: list[str]) -> list[str]:
    out = ["| " + " | ".join(_cell(c) for c in columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        out.append("| " + " | ".join(_cell(r.get(c, "")) for c in columns) + " |")
    return out


def _text(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _cut(text: str, n: int = NAME_CELL) -> str:
    """``text`` cut at a word to at most ``n`` characters, with an ellipsis when cut."""
    if len(text) <= n:
        return text
    head = text[: n - 1].rsplit(" ", 1)[0].rstrip(",;:")
    return head + "…"


def _cell(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return _escape(str(v)).replace("|", "\\|")


def _escape(text: str) -> str:
    """Measured text shown as it is: brackets and asterisks are not Markdown links or emphasis (a
    verdict in brackets, ``[differs]``, would be read as a cross-reference)."""
    return re.sub(r"([\[\]*])", r"\\\1", text)


#: How the result files of the long runs are made (the others: ``make results``).
MAKES = {"reproduce": "`make reproduce`, then `make results-reproduce`,",
         "model-quality": "`make model-quality`, then `make results-quality`,",
         "default-model": "`make results-default-model`"}


def results_markdown(name: str, root: Path = RESULTS, only: tuple[str, ...] = ()) -> str:
    """The tables of one result file (``{"command", "date", "machine", "kbcli_version", "tables":
    [{"title", "columns", "rows"}]}``) with where they came from; with ``only``, the tables whose
    title starts with one of those (in the file's order)."""
    path = root / f"{name}.json"
    if not path.exists():
        how = MAKES.get(name, "`make results` (or the command on this page)")
        return (f"!!! note \"No stored result\"\n    `benchmarks/results/{name}.json` is not there yet: "
                f"{how} makes it.\n")
    d = json.loads(path.read_text())
    tables = [t for t in d["tables"] if not only or t["title"].startswith(only)]
    if not tables:
        raise ValueError(f"benchmarks/results/{name}.json has no table titled {' or '.join(only)}")
    out = [f"Measured with `{d['command']}` on {d['date']}, kbcli {d['kbcli_version']}, "
           f"{d['machine']}{_load_note(d.get('load'))}.", ""]
    for t in tables:
        out += [f"**{_escape(t['title'])}**", ""] + _table(t["rows"], t["columns"]) + [""]
    return "\n".join(out)


def _load_note(load: dict | None) -> str:
    """", load average 6.8 (1 min) at the start, 6.5 at the end": wall times read beside it."""
    if not load or not load.get("start") or not load.get("end"):
        return ""
    return (f", load average {load['start'][0]:.1f} (1 min) at the start and "
            f"{load['end'][0]:.1f} at the end")


_RESULTS = re.compile(r"<!--\s*results:\s*([\w.-]+)((?:\s*\|[^|>]+)*)\s*-->")


def _results_marker(m: re.Match) -> str:
    only = tuple(t.strip() for t in m.group(2).split("|") if t.strip())
    return results_markdown(m.group(1), only=only)


def tour_markdown(readme: Path = ROOT / "README.md") -> str:
    """The README's tour: the text between its ``<!-- tour -->`` and ``<!-- /tour -->`` lines."""
    text = readme.read_text(encoding="utf-8")
    m = re.search(r"^<!-- tour -->\n(.*?)^<!-- /tour -->$", text, re.S | re.M)
    if m is None:
        raise ValueError(f"{readme}: no <!-- tour --> ... <!-- /tour --> section")
    return m.group(1).strip() + "\n"


def on_page_markdown(markdown: str, **_) -> str:
    if "<!-- tour -->" in markdown:
        markdown = markdown.replace("<!-- tour -->", tour_markdown())
    if "<!-- cli-reference -->" in markdown:
        markdown = markdown.replace("<!-- cli-reference -->", cli_markdown())
    if "<!-- serve-transcript -->" in markdown:
        markdown = markdown.replace("<!-- serve-transcript -->", serve_transcript())
    return _RESULTS.sub(_results_marker, markdown)


def _rounded(v):
    if isinstance(v, float):
        return round(v, 2)
    if isinstance(v, list):
        return [_rounded(x) for x in v]
    if isinstance(v, dict):
        return {k: _rounded(x) for k, x in v.items()}
    return v


def serve_transcript(steps: int = 2) -> str:
    """A real ``kbcli serve`` session of ``steps`` touches with the default model, driven by
    ``examples/external_robot.py`` (ideal mode), floats rounded to 2 decimals for reading."""
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "t.txt"
        subprocess.run([sys.executable, str(ROOT / "examples" / "external_robot.py"),
                        "--model", str(ROOT / "data" / "default-model.h5"), "--mode", "ideal",
                        "--max-steps", str(steps), "--transcript", str(log)],
                       check=True, capture_output=True, cwd=tmp)  # writes session.h5 there
        lines = log.read_text().splitlines()
    out = []
    for line in lines:
        who, _, msg = line.partition(" ")
        out += _wrapped(f"{who:5s} ", json.dumps(_rounded(json.loads(msg))))
    return "```\n" + "\n".join(out) + "\n```\n"


#: Width of a transcript line: the page's code block shows it whole, without scrolling.
TRANSCRIPT_WIDTH = 96


def _wrapped(prefix: str, msg: str) -> list[str]:
    """One message as lines of at most :data:`TRANSCRIPT_WIDTH` characters where the fields allow,
    cut only between two fields (a line a robot sends is one line; the page wraps it for
    reading)."""
    fields, depth, start = [], 0, 0
    for i, ch in enumerate(msg):  # cut after a comma at the object's own level
        depth += (ch in "[{") - (ch in "]}")
        if ch == "," and depth == 1:
            fields.append(msg[start:i + 1])
            start = i + 2
    fields.append(msg[start:])
    lines, line = [], prefix + fields[0]
    for f in fields[1:]:
        if len(line) + 1 + len(f) > TRANSCRIPT_WIDTH:
            lines.append(line)
            line = " " * (len(prefix) + 1) + f
        else:
            line += " " + f
    return [*lines, line]


#: The README's generated section: between these markers, the "What reproduces" table of
#: ``benchmarks/results/reproduce.json`` (``python tools/docs_hooks.py --readme`` rewrites it).
README_START = "<!-- what-reproduces: generated from benchmarks/results/reproduce.json by `python tools/docs_hooks.py --readme` -->"
README_END = "<!-- /what-reproduces -->"


def readme_section(root: Path = RESULTS) -> str:
    """The README's "What reproduces" section: the table of that title in ``reproduce.json``
    with the command and date that measured it (GitHub renders the README, not MkDocs: the
    table is written into the file, and a test checks that it is current)."""
    return results_markdown("reproduce", root, only=("What reproduces",))


def rewrite_readme(path: Path = ROOT / "README.md", root: Path = RESULTS) -> bool:
    """Replace the README's generated section with :func:`readme_section`; True if it changed."""
    text = path.read_text(encoding="utf-8")
    head, sep, rest = text.partition(README_START)
    _, sep2, tail = rest.partition(README_END)
    if not sep or not sep2:
        raise ValueError(f"{path} has no generated section ({README_START} ... {README_END})")
    new = f"{head}{README_START}\n\n{readme_section(root)}\n{README_END}{tail}"
    if new != text:
        path.write_text(new, encoding="utf-8")
    return new != text


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["--readme"]:
        print("README.md " + ("rewritten" if rewrite_readme() else "already current"))
    else:
        sys.exit("usage: python tools/docs_hooks.py --readme")
