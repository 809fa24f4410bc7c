"""Options shared by several commands, declared once: ``Annotated`` aliases (``seed: Seed = 0``)
or functions returning one (``seed_option("Seed of a --category draw.")``). The help of an option
naming a registered part lists the valid names (:func:`names_of`, :func:`describe_of`); a group of
options comes in as one dict through :func:`with_flags`.
"""

from __future__ import annotations

import functools
import inspect
import sys
import tomllib
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any

import typer

from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.posteriors import POSTERIORS
from kbcli.core.adaptation.strategies import STRATEGIES
from kbcli.core.detection.detectors import DETECTORS
from kbcli.core.instrument.layouts import LAYOUTS
from kbcli.core.instrument.transforms import FAMILIES
from kbcli.core.model.classes import MODEL_CLASSES, learned_classes
from kbcli.core.model.explore import STRATEGIES as EXPLORATIONS
from kbcli.errors import ConfigError
from kbcli.sim import MODES
from kbcli.sim.arms import PRESETS

#: The registry that describes each kind's parts.
_REGISTRIES = {"posterior": POSTERIORS, "estimator": ESTIMATORS, "family": FAMILIES,
               "layout": LAYOUTS, "model class": MODEL_CLASSES, "strategy": STRATEGIES,
               "exploration": EXPLORATIONS, "detector": DETECTORS, "arm": PRESETS, "mode": MODES}


#: Where a kind's names come from when not its whole registry: the model classes learned from
#: samples (``--model-class``; the exact model is not one).
_NAMES: dict[str, Callable[[], Iterable[str]]] = {"model class": learned_classes}


def names_of(kind: str) -> tuple[str, ...]:
    """The registered names of a kind of part (``"posterior"``, ``"layout"``, ...), in order."""
    return tuple(_NAMES[kind]() if kind in _NAMES else _REGISTRIES[kind])


def describe_of(kind: str) -> str:
    """``name: summary; ...`` of every registered part of ``kind`` (a name alone without one)."""
    reg = _REGISTRIES[kind]
    parts = []
    for name in names_of(kind):
        summary = reg.summary(name)
        parts.append(f"{name}: {summary}" if summary else name)
    return "; ".join(parts)


def one_of(kind: str, *extra: str, sep: str = "or") -> str:
    """``a, b or c``: the names of ``kind`` (then ``extra``), for a help text."""
    names = (*names_of(kind), *extra)
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} {sep} {names[-1]}"


_opt = typer.Option


# -- paths ------------------------------------------------------------------------------------------
def output_option(help: str) -> Any:
    """``-o/--output``: what the command writes."""
    return Annotated[Path, _opt("-o", "--output", help=help)]


def model_option(help: str = "Model artifact (.h5, kind 'model').", optional: bool = False,
                 **kw: Any) -> Any:
    """``--model``: a model artifact read."""
    return Annotated[Path | None if optional else Path, _opt("--model", help=help, **kw)]


def read_model(path: Path | None) -> tuple[Path, Any, Any, Any]:
    """The model artifact at ``path`` (None: the embedded default model): its path, the artifact,
    its fitted model and its keyboard."""
    from kbcli.io.artifact import read_artifact
    from kbcli.io.paths import default_model_path
    from kbcli.stages import keyboard as keyboard_stage
    from kbcli.stages.models import load_model

    path = default_model_path() if path is None else Path(path)
    art = read_artifact(path, "model")
    return path, art, load_model(art), keyboard_stage.load(art)


def keyboard_option(help: str = "Keyboard artifact (.h5) to learn.", optional: bool = False) -> Any:
    """``--keyboard``: a keyboard artifact read."""
    return Annotated[Path | None if optional else Path, _opt("--keyboard", help=help)]


def config_option(help: str, optional: bool = True) -> Any:
    """``--config``: a TOML file read."""
    return Annotated[Path | None if optional else Path, _opt("--config", help=help)]


# -- counts -----------------------------------------------------------------------------------------
#: Upper bounds of the benchmarks' counts that no stage config bounds (a typo such as 1e9 is refused).
MAX_SEEDS = 1000
MAX_REACHES = 100_000
MAX_STREAMS = 100_000
MAX_TUNE_ACTIONS = 10_000_000
MAX_HORIZON = 100_000
MAX_REPEATS = 100
MAX_TIMED_STEPS = 100_000


def at_most(text: str, bound: int) -> str:
    """A count option's help with its upper bound: ``Runs per row, at most 1000.``"""
    return f"{text.rstrip('.')}, at most {bound}."


def count_option(flag: str, text: str, bound: int, *decls: str, **kw: Any) -> Any:
    """A count option ``flag`` (and ``decls``) whose help ``text`` ends with its upper bound."""
    return Annotated[int, _opt(flag, *decls, help=at_most(text, bound), **kw)]


Categories = Annotated[list[str] | None, _opt(
    "--category", help="Displacement categories (repeat): small, medium, large.",
    show_default="all three")]


def comma_list(text: str, option: str, what: str = "whole numbers separated by commas",
               kind: type = int) -> tuple:
    """The values of ``option``'s comma-separated ``text`` (each a ``kind``, empty items
    skipped); any other text is refused in one line saying ``what`` the option takes."""
    try:
        return tuple(kind(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise ConfigError(f"{option} must be {what}, got {text!r}") from None


def check_counts(*counts: tuple[str, int | None, int]) -> None:
    """Refuse, in one line, a count outside ``[1, bound]``: ``(option, value, bound)`` each (a
    None value: not given)."""
    for option, value, bound in counts:
        if value is not None and not 1 <= value <= bound:
            raise ConfigError(f"{option} must be a whole number in [1, {bound}], got {value}")


# -- seeds and workers ------------------------------------------------------------------------------
def seed_option(help: str = "Seed of the robot's and the world's randomness.") -> Any:
    """``--seed``: the seed of a command's random draws (a whole number >= 0)."""
    return Annotated[int, _opt("--seed", min=0, help=help)]


Seed = seed_option()
def cap_workers(value: int, option: str = "--jobs") -> int:
    """More workers than cores only run slower: cap ``option`` at the core count, with a note."""
    from kbcli.io.processes import cap_jobs

    jobs, note = cap_jobs(value, option)
    if note is not None:
        sys.stderr.write(f"kbcli: {note}\n")
    return jobs


def _cap_jobs(value: int) -> int:
    return cap_workers(value)


Jobs = Annotated[int, _opt("--jobs", "-j", callback=_cap_jobs,
                           help="Local worker processes (joblib/loky); at most the number of "
                           "cores this process may use (more is capped, with a note).")]
Scheduler = Annotated[str | None, _opt(
    "--scheduler", help="Run on a Dask cluster: address of its scheduler, tcp://HOST:PORT.")]


# -- the robot's adaptation -------------------------------------------------------------------------
def _shown(default: str | None) -> str | bool:
    """What the help shows as ``[default: ...]``: ``default`` (an option whose value a config may
    fill, so the parameter's own default is None), else the parameter's default."""
    return default if default else True


def strategy_option(default: str | None = None) -> Any:
    """``--strategy``: one adaptation strategy (None: the config's, named in ``default``)."""
    return Annotated[str | None, _opt(
        "--strategy", help=f"Adaptation strategy: {one_of('strategy')}.",
        show_default=_shown(default))]


def strategies_option(default: str, kind: str = "strategy") -> Any:
    """``--strategy`` repeated: the strategies (``kind``: or the explorations) a benchmark runs."""
    return Annotated[list[str] | None, _opt(
        "--strategy", help=f"Strategies to run (repeat): {one_of(kind)}.", show_default=default)]


def posterior_option(default: str | None = None) -> Any:
    """``--posterior``: the posterior kind."""
    return Annotated[str | None, _opt(
        "--posterior", help=f"Posterior. {describe_of('posterior')}.", show_default=_shown(default))]


def estimator_option(default: str = "mean") -> Any:
    """``--estimator``: which point of the posterior the robot acts on (None: the config's)."""
    return Annotated[str | None, _opt(
        "--estimator", help=f"Estimate of the displacement the robot acts on. "
        f"{describe_of('estimator')}.", show_default=_shown(default))]


def family_option(default: str | None = None, help: str = "Transform family the robot estimates"
                  ) -> Any:
    """``--family``: the transform family."""
    return Annotated[str | None, _opt(
        "--family", help=f"{help}. {describe_of('family')}.", show_default=_shown(default))]


def mode_option(default: str | None = None, help: str = "Reaching", note: str = "") -> Any:
    """``--mode``: the simulator's mode (``note``: what the modes mean to the command)."""
    return Annotated[str | None, _opt(
        "--mode", help=f"{help}: {one_of('mode')}{f' ({note})' if note else ''}.",
        show_default=_shown(default))]


def arm_option(default: str | None = None, optional: bool = False, files: bool = True) -> Any:
    """``--arm``: an arm preset (or, with ``files``, a TOML file with an ``[arm]`` table)."""
    names = names_of("arm")
    if files:
        described = ", ".join(f"{n} ({s})" if (s := _REGISTRIES["arm"].summary(n)) else n
                              for n in names)
        text = (f"Arm preset: {described}; or a TOML file with an [arm] table (preset = NAME plus "
                "fields)")
    else:
        text = f"Arm preset ({', '.join(names)})"
    return Annotated[str | None if optional else str, _opt("--arm", help=text + ".",
                                                           show_default=_shown(default))]


def reach_noise_option(default: str | None = None) -> Any:
    """``--reach-noise`` (None: the config's, named in ``default``), the same words in every
    command."""
    return Annotated[float | None if default else float, _opt(
        "--reach-noise", help="Extra landing scatter of the arm (standard deviation, px) on top of "
        "the arm preset's own errors; in dynamics mode, motor noise.", show_default=_shown(default))]


ReachNoise = reach_noise_option()

ModelBlur = Annotated[float | None, _opt(
    "--model-blur", help="Override: fix the blur (px, 0-50) of the model's key edges. Not given, "
    "the robust posterior learns it from the touches (translation: it weighs 0, 1, 2.5 and 5 px "
    "and twice a weak model's own boundary error; rigid: 0 px; recorded in the run as "
    "robust_blurs); the plain (robust = false) and kde posteriors soften a learned model's map by "
    "1 px, the exact one's by 0.", show_default="learned from the touches")]
Repair = Annotated[bool | None, _opt(
    "--repair/--no-repair", help="Adapt with the model repaired by the touches: a joint belief over "
    "the shift and the model's map (each hypothesis scored by the map its own touches repaired, "
    "the model's local uncertainty), infogain planning with its posterior over the shift; "
    "translation family, likelihood posterior. Needed by --model-out.",
    show_default="--no-repair")]
ModelOut = Annotated[Path | None, _opt(
    "--model-out", help="Also write the model repaired by this run's adaptation touches (kind "
    "'model', recording its parent's sha256 and the touches it absorbed; never the input model's "
    "path): the robot's next run can start from it. Needs --repair.")]
Resolution = Annotated[float | None, _opt(
    "--resolution", help="Hypothesis grid step, px.", show_default="0.5")]
PriorHalfwidth = Annotated[float | None, _opt(
    "--prior-halfwidth", help="Half-width of the prior box of dx and dy, px (the robot expects a "
    "move within +-this).", show_default="45")]


Replicates = Annotated[int, _opt(
    "--replicates", min=0, max=10000,
    help="Bootstrap replicates (at the paper's 50 runs per parametrization) of each claim that "
         "differs, to state how likely the paper's verdict is if the effect is ours; 0: none.")]


def with_flags(group: str, flags: Mapping[str, Any]) -> Callable[[Callable], Callable]:
    """Give a command the options ``flags`` (parameter name to its Typer type; each None when
    not given), declared once.

    The command declares a parameter ``group`` where the options go in its ``--help``; it receives
    them there as one dict (parameter name to value).
    """
    def deco(fn: Callable[..., Any]) -> Callable[..., Any]:
        sig = inspect.signature(fn, eval_str=True)
        params = []
        for p in sig.parameters.values():
            params += [p] if p.name != group else [
                inspect.Parameter(name, p.kind, default=None, annotation=kind)
                for name, kind in flags.items()]

        @functools.wraps(fn)
        def wrapper(**kwargs: Any) -> Any:
            given = {name: kwargs.pop(name, None) for name in flags}
            return fn(**kwargs, **{group: given})

        wrapper.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
        return wrapper

    return deco


def max_steps_option(help: str, optional: bool = True, **kw: Any) -> Any:
    """``--max-steps/-T``: touches at most."""
    return Annotated[int | None if optional else int, _opt("--max-steps", "-T", help=help, **kw)]


# -- parts named in benchmarks and stages -----------------------------------------------------------
def layout_option(help: str, many: bool = False, **kw: Any) -> Any:
    """``--layout``: a layout (or, with ``many``, several); the help lists the registered ones."""
    kind = list[str] | None if many else str | None
    return Annotated[kind, _opt("--layout", help=help.format(layouts=", ".join(names_of("layout")),
                                                             described=describe_of("layout")), **kw)]


def model_class_option(help: str, many: bool = False, **kw: Any) -> Any:
    """``--model-class`` (or, with ``many``, repeated): ``{classes}`` in ``help`` lists the
    registered model classes."""
    kind = list[str] | None if many else str
    return Annotated[kind, _opt("--model-class",
                                help=help.format(classes=", ".join(names_of("model class"))),
                                **kw)]


ModelOption = Annotated[list[str] | None, _opt(
    "--model-option", metavar="KEY=VALUE", help="An option of the model class (repeat), e.g. "
    "n_estimators=200 with forest; one the class does not take, or any with auto, is refused.")]


def key_values(items: list[str] | None, option: str) -> dict[str, Any]:
    """The ``KEY=VALUE`` items of a repeated ``option``, each value read as a TOML value
    (``200``, ``2.5``, ``true``; any other text as it is)."""
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, text = (v.strip() for v in item.partition("="))
        if not sep or not key:
            raise ConfigError(f"{option} must be KEY=VALUE, got {item!r}")
        try:
            out[key] = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = text
    return out


def detector_option(default_note: str = "binomial: Eq. 4-6 with the upper tail of Eq. 6") -> Any:
    """``--detector``: one of the registered detectors."""
    return Annotated[str, _opt(
        "--detector", help=f"Failure detector: {', '.join(names_of('detector'))} ({default_note}).")]


Figure = output_option("Figure to write: .png, .pdf or .svg (the suffix picks the format).")
