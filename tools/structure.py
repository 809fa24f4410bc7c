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


def modules() -> dict[str, Path]:
    out = {}
    for p in sorted(ROOT.rglob("*.py")):
        rel = p.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def layer(mod: str) -> int:
    parts = mod.split(".")
    if len(parts) == 1:
        return 0
    return LAYERS.get(parts[1], 0)


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
    """(importer, imported) pairs that import up the layers (the lazy facade ``kbcli`` aside)."""
    return sorted((m, n) for m, ns in g.items() for n in ns
                  if m != "kbcli" and layer(n) > layer(m))


def long_modules(limit: int = 500) -> list[tuple[str, int]]:
    return [(m, n) for m, p in modules().items() if (n := len(p.read_text().splitlines())) > limit]


def long_functions(limit: int = 80) -> list[tuple[str, str, int]]:
    out = []
    for m, p in modules().items():
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append((m, node.name, n))
    return out


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
