"""Every command example in the docs runs, as a newcomer types it, on small settings.

Each ```sh block of the getting-started page, the tutorials and the concept pages is read; its
``kbcli`` and ``python`` lines run in order (a page's examples build on each other) in one temporary
folder holding ``data/``, ``examples/`` and a copy of ``pipelines/``. Each must exit 0 and write the
files it names (``-o``, ``--wav``, ``--transcript``). What is made smaller, and what is not run, is
listed here (SMALL, SMALL_CONFIGS, NOT_RUN, STDIN), never changed silently: the commands are the
docs' own.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from kbcli.cli import app

_spec = importlib.util.spec_from_file_location(
    "docs_hooks", Path(__file__).resolve().parent.parent / "tools" / "docs_hooks.py")
hooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hooks)

ROOT = Path(__file__).resolve().parent.parent
PAGES = sorted([ROOT / "docs" / "getting-started.md", *(ROOT / "docs" / "tutorials").glob("*.md"),
                *(ROOT / "docs" / "concepts").glob("*.md")])

#: Small settings, as substitutions on a command line: a 200-reach model knows every sound of the
#: default keyboard (the melody's notes among them) and learns in seconds (a learn that states no
#: budget gets 200 too, except the exact model, which makes no reach); one local process; a
#: coarser hypothesis grid for adapt (2 px, not 0.5: its likelihood tables take 1 s, not 11); a
#: shorter closed loop and animation; a robot that touches three times.
SMALL = [
    (r"--budget \d+", "--budget 200"),
    (r"^kbcli learn (?!.*--budget)(?!.*--strategy exact).*", r"\g<0> --budget 200"),
    (r"^kbcli adapt .*", r"\g<0> --resolution 2"),
    (r"--jobs \d+", "--jobs 1"),
    (r"^kbcli run .*", r"\g<0> --steps 300 --perturb-at 150"),
    (r"^kbcli animate .*", r"\g<0> --max-frames 20"),
    (r"^python examples/external_robot\.py", r"\g<0> --max-steps 3"),
]

#: Both evaluations shrunk: one experiment of a few touches at one displacement per category.
_ONE_SHORT_EXPERIMENT = [(r"^experiments = \d+", "experiments = 1"),
                         (r"^max_steps = \d+", "max_steps = 3"),
                         (r"^(displacements = \[\[[^\]]*\]).*", r"\1]")]


def _coarse_grid(table: str) -> tuple[str, str]:
    """The hypothesis grid at 2 px (not 0.5) in the TOML tables named ``table`` (a regex): each
    model's likelihood table takes 1 s, not 10, as for ``kbcli adapt`` above."""
    return (rf"^\[{table}\]$", "\\g<0>\nresolution = 2.0")


#: The pipeline configs, shrunk in the temporary copy of pipelines/ (a regex on each line): the
#: paper's evaluation in the ideal mode, the smallest model sweep.
SMALL_CONFIGS = {
    "paper.toml": [*_ONE_SHORT_EXPERIMENT, _coarse_grid("evaluate.methods.[^]]+"),
                   (r"^modes = .*", 'modes = ["ideal"]'),
                   (r"^play_notes = \d+", "play_notes = 10"),
                   (r"^kde_samples = \d+", "kde_samples = 500")],
    "model-quality.toml": [*_ONE_SHORT_EXPERIMENT, _coarse_grid("quality.adapt"),
                           (r"^budgets = .*", "budgets = [100]"),
                           (r"^explorations = .*", 'explorations = ["active"]'),
                           (r"^ideal = true", "ideal = false")],
}

#: Example lines not run here (a fragment of the line: why; each is tested elsewhere).
NOT_RUN = {
    "--scheduler tcp://HEAD": "needs a running Dask cluster (tests/test_evaluate.py starts one)",
    "--socket /tmp/kb.sock": "waits for a robot to connect (tests/test_serve.py connects one)",
    "examples/ppo_agent.py": "needs the rl extra (torch, Stable-Baselines3: never in make test) "
                             "and minutes of training",
}

#: What a command reads on stdin (a robot that says goodbye at once).
STDIN = {"kbcli serve": '{"op": "end"}\n'}

#: Options naming a file the command writes.
OUTPUTS = ("-o", "--output", "--wav", "--transcript", "--json")


def page_text(page: Path) -> str:
    """A page as the site shows it: ``<!-- tour -->`` is the README's tour (the README holds it)."""
    text = page.read_text()
    return text if page.name == "README.md" else text.replace("<!-- tour -->",
                                                              hooks.tour_markdown())


def examples(page: Path) -> list[str]:
    """The command lines of a page's ```sh blocks, in order (continuations joined, ``&&`` split,
    comments dropped); only ``kbcli``, ``python`` and ``mkdir`` lines."""
    lines = []
    for block in re.findall(r"```(?:sh|bash|console)\n(.*?)```", page_text(page), re.S):
        for line in block.replace("\\\n", " ").splitlines():
            tokens = shlex.split(re.sub(r"^\$ ", "", line.strip()), comments=True)
            while tokens:
                cut = tokens.index("&&") if "&&" in tokens else len(tokens)
                if tokens[0] in ("kbcli", "python", "mkdir"):
                    lines.append(shlex.join(tokens[:cut]))
                tokens = tokens[cut + 1:]
    return lines


def _small(line: str) -> str:
    for pattern, repl in SMALL:
        line = re.sub(pattern, repl, line)
    return line


def _workdir(tmp: Path) -> None:
    """The folder a newcomer runs the examples in: the clone's data and examples, and its pipelines
    on small settings."""
    for name in ("data", "examples"):
        (tmp / name).symlink_to(ROOT / name)
    shutil.copytree(ROOT / "pipelines", tmp / "pipelines")
    for name, subs in SMALL_CONFIGS.items():
        path = tmp / "pipelines" / name
        text = path.read_text()
        for pattern, repl in subs:
            text, n = re.subn(pattern, repl, text, flags=re.M)
            assert n, f"{name}: {pattern} matches nothing: update SMALL_CONFIGS"
        path.write_text(text)


def _outputs(argv: list[str]) -> list[str]:
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in OUTPUTS]


def _run(line: str, cwd: Path) -> None:
    argv = shlex.split(_small(line))
    if argv[0] == "mkdir":
        subprocess.run(argv, cwd=cwd, check=True)
        return
    stdin = next((s for k, s in STDIN.items() if line.startswith(k)), None)
    if argv[0] == "python":
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        r = subprocess.run([sys.executable, *argv[1:]], cwd=cwd, capture_output=True, text=True,
                           env=env, input=stdin, timeout=300)
        code, output = r.returncode, r.stdout + r.stderr
    else:
        old = Path.cwd()
        os.chdir(cwd)
        try:
            r = CliRunner().invoke(app, argv[1:], input=stdin)
        finally:
            os.chdir(old)
        code, output = r.exit_code, r.output
    assert code == 0, f"{line}\n{output[-3000:]}"
    for out in _outputs(argv):
        assert (cwd / out).exists(), f"{line}: wrote no {out}"


def test_the_tour_is_the_readmes_and_writes_only_into_its_scratch_folder():
    """Issue 40: README and getting-started showed two different tours, writing into the
    repository's root. Now the page includes the README's, and every file it writes is under
    out/tour/."""
    page = ROOT / "docs" / "getting-started.md"
    assert "<!-- tour -->" in page.read_text() and "kbcli learn" not in page.read_text()
    tour = [line for line in examples(page) if "out/tour" in line]
    readme = ROOT / "README.md"
    assert tour == [line for line in examples(readme) if "out/tour" in line]
    assert tour[0] == "mkdir -p out/tour" and len(tour) >= 10
    for line in tour[1:]:
        for out in _outputs(shlex.split(line)):
            assert out.startswith("out/tour/"), line


def test_the_pages_have_examples():
    found = {p.name: examples(p) for p in PAGES}
    assert len(found["getting-started.md"]) >= 7 and len(found["instrument.md"]) >= 10
    for fragment in NOT_RUN:
        assert any(fragment in line for lines in found.values() for line in lines), fragment


def _runnable(page: Path) -> list[str]:
    return [line for line in examples(page) if not any(f in line for f in NOT_RUN)]


@pytest.mark.parametrize("page", [p for p in PAGES if _runnable(p)], ids=lambda p: p.stem)
def test_every_example_of_a_page_runs(page, tmp_path):
    _workdir(tmp_path)
    for line in _runnable(page):
        _run(line, tmp_path)


def test_the_protocol_examples_name_a_sound_of_the_default_model():
    """The serve protocol's example reply ("class": 13, "sound": "A4 106 bpm") is what the default
    model answers, in `kbcli serve --help` and in the stage's docstring."""
    import kbcli.stages.serve as serve_stage
    from kbcli.core.instrument.notes import sound_name
    from kbcli.io.artifact import read_artifact

    features = read_artifact(ROOT / "data" / "default-model.h5", "model").data["model"]["class_features"]
    help_text = CliRunner().invoke(app, ["serve", "--help"], env={"COLUMNS": "200"}).output
    for text in (help_text, serve_stage.__doc__):
        pairs = re.findall(r'"class": (\d+), "sound": "([^"]+)"', text)
        assert pairs
        for cls, sound in pairs:
            assert sound_name(features[int(cls)]) == sound, (cls, sound)
