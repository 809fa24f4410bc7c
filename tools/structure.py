"""Structure checks of the kbcli package: module and function sizes, import cycles and imports up
the layers (core <- sim <- stages <- io <- viz, envs, bench <- api, cli). Run as a script to print a
report; ``tests/test_structure.py`` asserts the targets."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "kbcli"

#: Layer rank of each subpackage; a module may import only its own rank or below.
LAYERS = {"errors": 0, "core": 1, "sim": 2, "stages": 3, "io": 4, "viz": 5,
          "envs": 5, "bench": 5, "api": 6, "cli": 7, "__init__": 0, "__main__": 8}
#: Within the core, the paper's ideas in their order: the instrument, the model learned of it,
#: the adaptation that uses the model, failure detection, and playing (which uses them all); the
#: shared helpers (config, registry) below them all. A sub-package may import only its own rank
#: or below.
CORE_LAYERS = {"config": 0.0, "registry": 0.0, "instrument": 0.1, "model": 0.2,
               "adaptation": 0.3, "detection": 0.3, "playing": 0.4}


def modules() -> dict[str, Path]:
    out = {}
    for p in sorted(ROOT.rglob("*.py")):
        rel = p.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def layer(mod: str) -> float:
    parts = mod.split(".")
    if len(parts) == 1:
        return 0
    rank = LAYERS.get(parts[1], 0)
    if parts[1] == "core" and len(parts) > 2:
        rank += CORE_LAYERS.get(parts[2], 0.0)
    return rank


def imports(mod: str, path: Path, known: set[str]) -> set[str]:
    """kbcli modules imported by ``mod`` anywhere in its body (functions included)."""
    tree = ast.parse(path.read_text())
    out: set[str] = set()
    pkg = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            names = [base] + [f"{base}.{a.name}" for a in node.names]
        for n in names:
            while n and n not in known:
                n = n.rpartition(".")[0]
            if n and n != mod and n.startswith("kbcli"):
                out.add(n)
    # a submodule's import of its own package's __init__ is not an edge we care about
    return {n for n in out if n != "kbcli"}


def graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {m: imports(m, p, known) for m, p in mods.items()}


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in g:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in g:
        if v not in index:
            visit(v)
    return out


def upward(g: dict[str, set[str]]) -> list[tuple[str, str]]:
    """(importer, imported) pairs that import up the layers (the lazy facade ``kbcli`` aside; a
    core sub-package's ``__init__`` names its modules in words only)."""
    return sorted((m, n) for m, ns in g.items() for n in ns
                  if m != "kbcli" and layer(n) > layer(m) + 1e-9)


def long_modules(limit: int = 400) -> list[tuple[str, int]]:
    return [(m, n) for m, p in modules().items() if (n := len(p.read_text().splitlines())) > limit]


def long_functions(limit: int = 60) -> list[tuple[str, str, int]]:
    out = []
    for m, p in modules().items():
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append((m, node.name, n))
    return out


#: The registries of interchangeable parts: code never compares a value with one of their names
#: (``x == "kde"``) outside the part and its registry; it asks the part (:func:`name_switches`).
PART_REGISTRIES = (
    ("kbcli.core.adaptation.strategies", "STRATEGIES"), ("kbcli.core.adaptation.posteriors", "POSTERIORS"),
    ("kbcli.core.instrument.transforms", "FAMILIES"), ("kbcli.core.adaptation.estimators", "ESTIMATORS"),
    ("kbcli.core.instrument.layouts", "LAYOUTS"), ("kbcli.core.model.classes", "MODEL_CLASSES"),
    ("kbcli.core.model.explore", "STRATEGIES"), ("kbcli.core.detection.detectors", "DETECTORS"),
    ("kbcli.sim.arms", "PRESETS"), ("kbcli.sim.modes", "MODES"))
#: Options whose values are words, not parts, though a part shares the word (``ml_ties = "random"``).
NOT_PARTS = ("ml_ties", "ties")


def part_names() -> set[str]:
    """Every registered name of :data:`PART_REGISTRIES` (imports kbcli)."""
    import importlib

    sys.path.insert(0, str(ROOT.parent))
    return {n for mod, reg in PART_REGISTRIES
            for n in getattr(importlib.import_module(mod), reg).names()}


def _strings(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        return [v for e in node.elts for v in _strings(e)]
    return []


def _names_an_option(node: ast.AST) -> bool:
    """Whether ``node`` reads an option of :data:`NOT_PARTS` (``cfg.ml_ties``, ``r["ml_ties"]``)."""
    if isinstance(node, ast.Attribute):
        return node.attr in NOT_PARTS
    if isinstance(node, ast.Subscript):
        return any(v in NOT_PARTS for v in _strings(node.slice))
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args:
        return node.func.attr == "get" and any(v in NOT_PARTS for v in _strings(node.args[0]))
    return False


def name_switches(names: set[str]) -> list[tuple[str, int, str]]:
    """``(module, line, source)`` of every comparison (``==``, ``!=``, ``in``, ``not in``) of a
    value with a registered part's name: code that branches on a part's name."""
    out = []
    for m, p in modules().items():
        src = p.read_text()
        for node in ast.walk(ast.parse(src)):
            if not isinstance(node, ast.Compare) or not all(
                    isinstance(o, ast.Eq | ast.NotEq | ast.In | ast.NotIn) for o in node.ops):
                continue
            sides = [node.left, *node.comparators]
            if any(_names_an_option(s) for s in sides):
                continue
            if any(v in names for s in sides for v in _strings(s)):
                out.append((m, node.lineno, ast.get_source_segment(src, node)))
    return out


def sizes() -> dict[str, int]:
    """Lines of every module."""
    return {m: len(p.read_text().splitlines()) for m, p in modules().items()}


def function_sizes() -> list[tuple[str, str, int]]:
    """``(module, function, lines)`` of every function."""
    return [(m, node.name, node.end_lineno - node.lineno + 1) for m, p in modules().items()
            for node in ast.walk(ast.parse(p.read_text()))
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)]


def max_complexity() -> int | None:
    """The largest McCabe complexity of a function (ruff's C901), None without ruff."""
    import shutil
    import subprocess

    ruff = Path(sys.executable).parent / "ruff"
    exe = str(ruff) if ruff.exists() else shutil.which("ruff")
    if exe is None:
        return None
    for limit in range(1, 40):
        r = subprocess.run([exe, "check", str(ROOT), "--select", "C901", "--config",
                            f"lint.mccabe.max-complexity={limit}", "--output-format", "concise"],
                           capture_output=True, text=True)
        if r.returncode == 0:
            return limit
    return None


def summary() -> dict[str, object]:
    """The shape in numbers: modules, median and largest module, longest function, complexity,
    name switches."""
    import statistics

    sz, fs = sizes(), function_sizes()
    big = max(sz.items(), key=lambda kv: kv[1])
    longest = max(fs, key=lambda t: t[2])
    return {"modules": len(sz), "lines": sum(sz.values()), "median module": statistics.median(sz.values()),
            "largest module": f"{big[0]} {big[1]}", "modules over 400": sum(n > 400 for n in sz.values()),
            "longest function": f"{longest[0]}.{longest[1]} {longest[2]}",
            "functions over 60": sum(n > 60 for *_, n in fs), "max complexity": max_complexity(),
            "name switches": len(name_switches(part_names()))}


if __name__ == "__main__":
    g = graph()
    for c in cycles(g):
        print("cycle:", " <-> ".join(c))
    for m, n in upward(g):
        print(f"up: {m} imports {n}")
    for m, n in long_modules():
        print(f"long module: {m} {n}")
    for m, f, n in long_functions():
        print(f"long function: {m}.{f} {n}")
    for m, line, src in name_switches(part_names()):
        print(f"name switch: {m}:{line} {src}")
    for k, v in summary().items():
        print(f"{k}: {v}")
