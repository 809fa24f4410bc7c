"""Reading an evaluation artifact for the report: its methods, options and result trees.

Also the report's value types (:class:`Claim`, :class:`Figure`, :class:`Report`), its constants
and number formats, and :func:`upgrade`, which reads a schema-1 evaluation in the current layout.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kbcli.core.adaptation import stats
from kbcli.core.adaptation.config import SLOTS
from kbcli.core.options import flat_view
from kbcli.errors import ArtifactError
from kbcli.sim.modes import MODES
from kbcli.stages.artifact import Artifact

#: Steps at which the RMSE table is read (those beyond max_steps are dropped).
RMSE_STEPS = (1, 2, 3, 5, 10, 20, 40)
#: Playing success after adaptation may be this much below the measured before (share, 2 points).
RESTORED_MARGIN = 0.02
NOT_SIGNIFICANT = 0.01
#: Observations at which Fig. 6's claim (active's entropy falls quicker) is read.
ENTROPY_STEPS = (5, 10, 20)
#: Robot options shown first in the methods table (the rest follow alphabetically).
KEY_OPTIONS = ("posterior", "estimator", "model_blur", "kde_samples", "kde_bandwidth", "outlier",
               "resolution", "prior_halfwidth")
VERDICTS = ("agrees", "differs", "underpowered", "not measured")


@dataclass(frozen=True)
class Claim:
    """One claim of the paper, what the judged method measured, and the others beside it."""

    source: str
    paper: str
    method: str  # the method the verdict is about
    options: str  # its options that matter for the claim
    measured: str
    verdict: str  # one of VERDICTS
    beside: str = ""  # the other methods' measurements
    why: str = ""  # a measured explanation of a difference
    #: the claim under the plainest other reading of each unstated rule it rests on:
    #: ``(label, measured text, verdict)`` (:mod:`kbcli.stages.report.readings`)
    readings: tuple[tuple[str, str, str], ...] = ()
    mode: str = ""  # the mode the claim is judged in
    strategy: str = ""  # the compared strategy ('' : every strategy of the method)


@dataclass(frozen=True)
class Figure:
    name: str  # file name in the report folder
    title: str
    caption: str


@dataclass
class Report:
    """What ``kbcli report`` writes: the README text and the figures to draw."""

    readme: str
    claims: list[Claim]
    figures: list[Figure] = field(default_factory=list)


def exact_mode(modes) -> str | None:
    """The first of ``modes`` whose arm simulates no physics (the paper's Sect. IV-A and IV-B:
    the finger lands where it aims), None when none of them is such a mode."""
    return next((m for m in modes if m in MODES and not MODES.get(m).physics), None)


def physical_mode(modes) -> str | None:
    """The first of ``modes`` whose arm simulates its dynamics (the paper's Sect. IV-C), or None."""
    return next((m for m in modes if m in MODES and MODES.get(m).physics), None)


def fmt_p(p: float) -> str:
    return "1" if p >= 0.9995 else f"{p:.1e}"


def fmt_med(m: float) -> str:
    return "-" if np.isnan(m) else f"{m:g}"


def pct(v: float) -> str:
    return "n/a" if np.isnan(v) else f"{100 * v:.1f} %"


def check(art: Artifact) -> None:
    if art.kind != "evaluation":
        raise ArtifactError(f"{art.path or 'artifact'}: is a {art.kind} artifact, expected evaluation")
    for k in ("curves", "pvalues", "entropy", "experiments"):
        if k not in art.data:
            raise ArtifactError(f"{art.path or 'artifact'}: evaluation artifact without {k!r}")


# -- schema 1 (before named methods) --------------------------------------------------------------
def upgrade(art: Artifact) -> Artifact:
    """A schema-1 evaluation (one unnamed method, derived playing success) in the current layout.

    Its runs become method ``kbcli`` (judged; options: its ``adapt`` table over the adapt stage's
    defaults of the time, which it did not record); its p-values are the untied rank-sum test it
    stored (``min_pvalue`` computed from its run counts); its playing success was computed, not
    measured, so it is dropped (NaN).
    """
    if (art.schema_version or 1) >= 2 or "methods" in art.attrs:
        return traced(art)
    check(art)
    data = dict(art.data)
    name = "kbcli"
    exp = dict(data["experiments"])
    n = len(exp["mode"])
    exp["method"] = np.array([name] * n)
    for k in ("play_before", "play_unadapted", "play_adapted"):
        exp[k] = np.full(n, np.nan)
    data["experiments"] = exp
    pv = {}
    for m, by_c in data["pvalues"].items():
        pv[m] = {name: {}}
        for c, by_s in by_c.items():
            pv[m][name][c] = {}
            for s, entry in by_s.items():
                na = len(data["curves"][m][c][s]["samples_to_threshold"])
                nb = len(data["curves"][m][c][art.attrs["baseline"]]["samples_to_threshold"])
                pv[m][name][c][s] = {**entry,
                                     "min_pvalue": np.float64(stats.min_pvalue_unpaired(na, nb))}
    data["pvalues"] = pv
    data["curves"] = {m: {name: v} for m, v in data["curves"].items()}
    data["entropy"] = {m: {name: v} for m, v in data["entropy"].items()}
    data["examples"] = {m: {name: v} for m, v in data.get("examples", {}).items()}
    attrs = dict(art.attrs)
    attrs["methods"] = {name: {
        "strategies": list(attrs["strategies"]),
        "description": "the only method of a schema-1 evaluation (defaults of its kbcli version)",
        "modes": list(attrs["modes"]), "categories": list(attrs["categories"]),
        "options": {m: {s: {"robot": dict(art.config.get("adapt", {}))} for s in attrs["strategies"]}
                    for m in attrs["modes"]}}}
    attrs["judged"] = name
    attrs["method_order"] = [name]
    attrs.setdefault("play_notes", 0)
    return traced(Artifact(kind=art.kind, config=art.config, seed=art.seed, data=data,
                           attrs=attrs, inputs=art.inputs, schema_version=art.schema_version,
                           kbcli_version=art.kbcli_version, sha256=art.sha256, path=art.path))


class MissingData(ArtifactError, KeyError):
    """A dataset the report reads is not in the evaluation: one line naming the file and the
    dataset (a ``KeyError`` too, for the lookups that expect one)."""

    def __str__(self) -> str:
        return str(self.args[0])


class _Tree(dict):
    """An artifact's data group whose missing entries raise :class:`MissingData` naming the
    file and the dataset's path (``.get`` still returns its default)."""

    def __init__(self, d: dict, path: str, where: str) -> None:
        super().__init__((k, _Tree(v, f"{path}{k}/", where) if isinstance(v, dict) else v)
                         for k, v in d.items())
        self.path, self.where = path, where

    def __missing__(self, key):
        raise MissingData(f"{self.where}: the evaluation has no dataset '{self.path}{key}', which "
                          "the report reads (written by another kbcli version, or damaged)")


def traced(art: Artifact) -> Artifact:
    """``art`` with its data as :class:`_Tree` groups (a report on a damaged evaluation names
    what it lacks, in one line)."""
    if isinstance(art.data, _Tree):
        return art
    return Artifact(kind=art.kind, config=art.config, seed=art.seed,
                    data=_Tree(art.data, "", art.path or "the evaluation"), attrs=art.attrs,
                    inputs=art.inputs, schema_version=art.schema_version,
                    kbcli_version=art.kbcli_version, sha256=art.sha256, path=art.path)


# -- reading the artifact -------------------------------------------------------------------------
def method_names(art: Artifact) -> list[str]:
    """The methods in the config's order (``attrs["method_order"]``; artifacts without it, whose
    attributes were stored with sorted keys: the judged method first)."""
    names = list(art.attrs["methods"])
    order = art.attrs.get("method_order")
    if order:
        return [x for x in order if x in names]
    judged = art.attrs.get("judged")
    return ([judged] if judged in names else []) + [x for x in names if x != judged]


def methods_of(art: Artifact) -> dict:
    """Method name -> its resolved options, in :func:`method_names` order."""
    info = art.attrs["methods"]
    return {x: info[x] for x in method_names(art)}


def robot(art: Artifact, method: str) -> dict:
    """The robot options a method resolved to, in the flat layout (those of its first mode, each
    strategy's own options beside the shared ones; the per-experiment strategy dropped)."""
    opts = methods_of(art)[method]["options"]
    for by_s in opts.values():
        r: dict = {}
        for d in by_s.values():
            r.update(flat_view(d.get("robot", {}), SLOTS))
        r.pop("strategy", None)
        return r
    return {}


def readings(art: Artifact, method: str) -> list[tuple[str, str]]:
    """``(estimator, sfx)`` of each reading of a method's runs: its own estimator (``sfx`` empty),
    then the other ones, from the same runs (the records ending in ``sfx``)."""
    own = robot(art, method).get("estimator", "?")
    return [(own, "")] + [(e, f"_{e}") for e in ("ml", "mean") if e != own]


def short(art: Artifact, method: str) -> str:
    r = robot(art, method)
    parts = [f"{k} {r[k]}" for k in ("posterior", "estimator") if k in r]
    if "model_blur" in r:
        parts.append(f"model_blur {r['model_blur']}")
    return ", ".join(parts) + f"; {' / '.join(methods_of(art)[method]['strategies'])}"


def ordered(art: Artifact, key: str, mode: str):
    """``(method, category, strategy, value)`` of ``art.data[key][mode]`` (``curves`` or
    ``pvalues``) in the config's order of methods, categories and strategies (an artifact read
    back from HDF5 lists its groups alphabetically)."""
    tree = art.data[key].get(mode, {})
    for x, info in methods_of(art).items():
        for c in art.attrs["categories"]:
            by_s = tree.get(x, {}).get(c)
            if by_s is None:
                continue
            for s in info["strategies"]:
                if s in by_s:
                    yield x, c, s, by_s[s]


def cell(art: Artifact, mode: str, method: str, category: str):
    cur = art.data["curves"].get(mode, {}).get(method, {}).get(category)
    pv = art.data["pvalues"].get(mode, {}).get(method, {}).get(category)
    return cur, pv


def compared(art: Artifact, method: str) -> list[str]:
    """The non-baseline strategies of a method."""
    base = art.attrs["baseline"]
    return [s for s in methods_of(art)[method]["strategies"] if s != base]


def others(art: Artifact) -> list[str]:
    return [m for m in methods_of(art) if m != art.attrs["judged"]]


def played(art: Artifact, sel: np.ndarray, key: str) -> np.ndarray:
    v = np.asarray(art.data["experiments"][key], float)[sel]
    return v[~np.isnan(v)]


def prior_entropy(art: Artifact, method: str) -> float | None:
    """Entropy (nats) of a method's uniform prior over its hypothesis grid: the posterior entropy
    at t = 0, before any observation (None when its options do not say the grid)."""
    from kbcli.core.adaptation.grid import grid_bytes

    r = robot(art, method)
    try:
        cells, _ = grid_bytes(r.get("family", "translation"), float(r["prior_halfwidth"]),
                              float(r["resolution"]), float(r.get("max_angle", 0.0)),
                              float(r.get("angle_resolution", 1.0)))
    except (KeyError, TypeError, ValueError):
        return None
    return float(np.log(cells))
