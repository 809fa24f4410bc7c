"""The flags of the paper's method's parts, declared once for ``kbcli adapt`` and ``kbcli run``:
each refused where the method does not read it (:func:`kbcli.core.adaptation.config.refuse_inactive`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any

import typer

from kbcli.cli.options import with_flags
from kbcli.core.adaptation.config import option_default, option_names
from kbcli.core.adaptation.fields import MAX_CANDIDATES, MAX_KDE_SAMPLES


def _robot_option(name: str, kind: Any, help: str, default: str | None = None) -> Any:
    """``--NAME`` (dashes for underscores) of the adapter's option ``name`` (None: the config's),
    its help closed by the adapter's default."""
    flag = "--" + name.replace("_", "-")
    return Annotated[kind | None, typer.Option(flag, help=f"{help}.",
                                               show_default=str(default or option_default(name)))]


def robot_given(flags: Mapping[str, Any], table: Mapping[str, Any] | None = None,
                source: str = "") -> dict[str, str]:
    """The robot options a user set, each with how the message names it: the flags given (not
    None) as ``--flag``, the keys of a TOML ``[adapt]`` table (and of its ``robot`` table) as
    ``key`` (of ``source``) (:func:`kbcli.core.adaptation.config.refuse_inactive`)."""
    robot = set(option_names())
    table = dict(table or {})
    inner = table.pop("robot", None)
    keys = [*table, *(inner if isinstance(inner, Mapping) else ())]
    where = f" (in {source})" if source else ""
    given = {k: f"{k}{where}" for k in keys if k in robot}
    given.update({k: "--" + k.replace("_", "-") for k, v in flags.items()
                  if v is not None and k in robot})
    return given


KdeSamples = _robot_option("kde_samples", int, "kde posterior: actions drawn from p(action | "
                           "sound) per KDE term (N of Algorithm 2), a whole number >= 10, at most "
                           f"{MAX_KDE_SAMPLES}")
KdeDraw = _robot_option("kde_draw", str, "kde posterior: shared (each sound's samples drawn once, "
                        "reused by every touch) or fresh (Algorithm 2 as written: new samples for "
                        "every touch, from the run's seed)")
SimulateDraw = _robot_option("simulate_draw", str, "kde posterior with paper-active: the samples "
                             "of the simulated touches; shared (each sound's samples drawn once "
                             "per run, reused by every simulated touch: faster, not the paper's "
                             "text) or fresh (new samples for each)", default="as --kde-draw")
KdeSampler = _robot_option("kde_sampler", str, "What draws actions from p(action | sound) for "
                           "--kde-draw fresh, --random-actions model and paper-active's candidates: "
                           "model (the model's own rejection sampler: exact, ~250 ms per 10,000 "
                           "draws) or raster (the model's raster: a cell by p(sound | cell), then a "
                           "point in it; ~1 ms)")
KdeBeyond = _robot_option("kde_beyond", str, "kde posterior: the pad beyond the working area is "
                          "silent (silence's samples cover it as far as a hypothesis can move a "
                          "touch back) or unknown (no samples there: without a floor a silent "
                          "touch mapped there rules its hypothesis out)")
KdeFloor = _robot_option("kde_floor", float, "kde posterior: weight in [0, 1) of the uniform floor "
                         "mixed into each KDE term; 0: none (Eq. 7 as written: a displacement no "
                         "sample supports is ruled out)", default="0.001, the outlier rate")
MlTies = _robot_option("ml_ties", str, "Which of several equally probable cells is the maximum-"
                       "likelihood one (read by --estimator ml, active, paper-active and --stop-ml): "
                       "first (the lowest grid index: the prior box's corner on a flat posterior) "
                       "or random (uniformly among the tied cells, seeded: no positional bias)")
StopMl = _robot_option("stop_ml", float, "The paper's stopping rule: stop when the most probable "
                       "cell of the posterior holds at least this probability, > 0", default="off")
StopMass = _robot_option("stop_mass", float, "Our stopping rule: stop when this fraction (0-1) of "
                         "the posterior lies within 1 px of the estimate; 0: off (the paper's rule "
                         "alone)")
RandomActions = _robot_option("random_actions", str, "Where strategy random touches: area "
                              "(uniform over the working area) or model (a sound uniform over the "
                              "model's sounds, then an action from p(action | sound): the paper's "
                              "random selection of samples)")
Candidates = _robot_option("candidates", int, "Candidate actions per decision of active, "
                           "paper-active (sampled from the model) and infogain, a whole number "
                           f">= 1, at most {MAX_CANDIDATES}")
ActiveKeep = _robot_option("active_keep", int, "Most confusing candidates active and "
                           "paper-active keep and simulate, a whole number >= 1, at most "
                           f"{MAX_CANDIDATES}")


#: The Typer type of each flag of :data:`PAPER_FLAGS`.
_PAPER_TYPES = {"kde_samples": KdeSamples, "kde_draw": KdeDraw, "simulate_draw": SimulateDraw,
                "kde_sampler": KdeSampler, "kde_beyond": KdeBeyond,
                "kde_floor": KdeFloor, "ml_ties": MlTies, "stop_ml": StopMl,
                "stop_mass": StopMass, "random_actions": RandomActions,
                "candidates": Candidates, "active_keep": ActiveKeep}
#: The adapter options of the flags above (and those every adapting command has), by flag.
PAPER_FLAGS = tuple(_PAPER_TYPES)
#: Give a command the flags of :data:`PAPER_FLAGS`, as one dict in its parameter ``paper_flags``.
with_paper_flags = with_flags("paper_flags", _PAPER_TYPES)
