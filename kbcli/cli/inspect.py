"""``kbcli inspect``: what an artifact is, where it came from, what it holds."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from kbcli.cli.app import command, out
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
    cfg = Table(title="config", show_header=True)
    cfg.add_column("key")
    cfg.add_column("value")
    for k, v in _flatten(d["config"]):
        cfg.add_row(k, json.dumps(v))
    out.print(cfg)
    if d["attrs"]:
        at = Table(title="summary", show_header=True)
        at.add_column("key")
        at.add_column("value")
        for k, v in _flatten(d["attrs"]):
            at.add_row(k, json.dumps(v) if not isinstance(v, str) else v)
        out.print(at)
    prov = Table(title="provenance (inputs, recursively)")
    prov.add_column("role")
    prov.add_column("kind")
    prov.add_column("file")
    prov.add_column("sha256")
    rows = list(provenance_chain(d["inputs"]))
    for depth, role, r in rows:
        prov.add_row("  " * depth + role, str(r.get("kind")), str(r.get("file")), str(r.get("sha256")))
    if not rows:
        prov.add_row("(none)", "", "", "")
    out.print(prov)
    ds = Table(title="datasets")
    ds.add_column("name")
    ds.add_column("shape")
    ds.add_column("dtype")
    for name, info in sorted(d["datasets"].items()):
        ds.add_row(name, " x ".join(map(str, info["shape"])) or "scalar", info["dtype"])
    out.print(ds)
    if d["problem"]:
        raise ArtifactError(f"{artifact}: {d['problem']}")


def _flatten(d: dict, prefix: str = ""):
    for k in sorted(d):
        v = d[k]
        if isinstance(v, dict) and v:
            yield from _flatten(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v
