"""``kbcli inspect``: what an artifact is, where it came from, what it holds."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from kbcli.cli.app import command, out
from kbcli.cli.show import table
from kbcli.core.adaptation.config import SLOTS, option_names, shown
from kbcli.core.options import flat_view
from kbcli.errors import ArtifactError
from kbcli.io.artifact import describe, provenance_chain


@command(name="inspect")
def inspect_cmd(
    artifact: Annotated[Path, typer.Argument(help="Any kbcli artifact (.h5).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON for scripts instead of tables.")] = False,
) -> None:
    """Print an artifact's kind, schema, config, provenance chain (with full sha256 hashes) and
    dataset shapes; and, for a damaged file, what does not match its kind's schema (then exit 1).
    """
    d = describe(artifact)
    if as_json:
        print(json.dumps(d, indent=2, sort_keys=True))
        if d["problem"]:
            raise ArtifactError(f"{artifact}: {d['problem']}")
        return
    t = Table(title=f"{artifact}", show_header=False)
    for key in ("kind", "schema_version", "kbcli_version", "seed", "sha256"):
        t.add_row(key, str(d[key]))
    out.print(t)
    cfg = table("config", ("key", "value"), left=2, title_justify="center")
    hidden: list[str] = []
    for k, v in _flatten(d["config"], hidden=hidden):
        cfg.add_row(k, json.dumps(v))
    out.print(cfg)
    _print_summary(d, hidden)
    if hidden:
        out.print(f"{len(hidden)} robot options the method does not read (its posterior, "
                  "estimator, family, strategy and stopping rules) are not shown; --json prints "
                  "every recorded one")
    prov = table("provenance (inputs, recursively)", ("role", "kind", "file", "sha256"), left=4,
                 title_justify="center")
    rows = list(provenance_chain(d["inputs"]))
    for depth, role, r in rows:
        prov.add_row("  " * depth + role, str(r.get("kind")), str(r.get("file")), str(r.get("sha256")))
    if not rows:
        prov.add_row("(none)", "", "", "")
    out.print(prov)
    ds = table("datasets", ("name", "shape", "dtype"), left=3, title_justify="center")
    for name, info in sorted(d["datasets"].items()):
        ds.add_row(name, " x ".join(map(str, info["shape"])) or "scalar", info["dtype"])
    out.print(ds)
    if d["problem"]:
        raise ArtifactError(f"{artifact}: {d['problem']}")


def _print_summary(d: dict, hidden: list) -> None:
    """The summary attributes (the options the method does not read added to ``hidden``), and a
    repaired model's lineage apart."""
    if d["attrs"]:
        at = table("summary", ("key", "value"), left=2, title_justify="center")
        attrs = {k: v for k, v in d["attrs"].items() if k != "lineage"}
        for k, v in _flatten(_unread_resolved(d["config"], attrs, hidden), hidden=hidden):
            at.add_row(k, json.dumps(v) if not isinstance(v, str) else v)
        out.print(at)
    if d["attrs"].get("lineage"):
        _print_lineage(d["attrs"]["lineage"])


def _print_lineage(lineage: list) -> None:
    """A repaired model's generations (``kbcli adapt/run --repair --model-out``), oldest first."""
    t = table("lineage (repaired by adaptations; the parent of each generation)",
              ("gen", "source", "parent", "parent sha256", "absorbed", "skipped", "shifts (dx, dy)"),
              left=7, title_justify="center")
    for i, g in enumerate(lineage, 1):
        shifts = "; ".join(f"{s[0]:+.2f}, {s[1]:+.2f}" for s in g.get("shifts", []))
        t.add_row(str(i), str(g.get("source")), str(g.get("parent_file")),
                  str(g.get("parent_sha256")), str(g.get("absorbed")), str(g.get("skipped")),
                  shifts or "-")
    out.print(t)


def _robot_of(tree: dict) -> dict | None:
    """The first robot config (a ``robot`` table with a posterior) in a nested dict."""
    for k, v in tree.items():
        if k == "robot" and isinstance(v, dict) and "posterior" in v:
            return v
        found = _robot_of(v) if isinstance(v, dict) else None
        if found is not None:
            return found
    return None


def _unread_resolved(config: dict, attrs: dict, hidden: list) -> dict:
    """``attrs`` without the options a run resolved from the model (the robust posterior's radius,
    blurs and learning rate) when its method does not read them: a run's summary (its config's
    robot), an evaluation's ``methods.NAME.from_model`` (that method's robot); added to ``hidden``."""
    def drop(d: dict, robot: dict | None, strategies, prefix: str) -> dict:
        if robot is None:
            return d
        read, options = shown(robot, strategies), option_names()
        out = {k: v for k, v in d.items() if k not in options or k in read}
        hidden.extend(f"{prefix}{k}" for k in d if k not in out)
        return out

    attrs = drop(attrs, _robot_of(config), None, "")
    methods = attrs.get("methods")
    if isinstance(methods, dict):
        attrs = {**attrs, "methods": {
            x: {**m, "from_model": drop(m["from_model"], _robot_of(m), m.get("strategies"),
                                        f"methods.{x}.from_model.")}
            if isinstance(m, dict) and isinstance(m.get("from_model"), dict) else m
            for x, m in methods.items()}}
    return attrs


def _flatten(d: dict, prefix: str = "", hidden: list | None = None):
    """``(dotted key, value)`` of a nested dict; a robot config (``...robot``) gives only the options
    its method reads (:func:`kbcli.core.adaptation.config.shown`), the others' keys added to
    ``hidden``."""
    for k in sorted(d):
        v = d[k]
        if k == "robot" and isinstance(v, dict) and "posterior" in v:
            kept = shown(v)
            if hidden is not None:
                hidden += [f"{prefix}{k}.{o}" for o in flat_view(v, SLOTS) if o not in kept]
            v = kept
        if isinstance(v, dict) and v:
            yield from _flatten(v, f"{prefix}{k}.", hidden)
        else:
            yield f"{prefix}{k}", v
