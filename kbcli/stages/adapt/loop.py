"""One adaptation against a simulated world (:func:`experiment`), and the playing success measured
around it by replaying the melody with Algorithm 1 (:func:`play_success`)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.loop import adapt
from kbcli.core.adaptation.posteriors.kde.samples import ActionSamples
from kbcli.core.adaptation.setup import build_samples, build_table
from kbcli.core.instrument import transforms
from kbcli.core.instrument.keyboard import Keyboard
from kbcli.core.instrument.melody import parse_melody
from kbcli.core.model.table import LikelihoodTable
from kbcli.core.playing.play import MATCH, replay
from kbcli.sim import SimConfig, World, make_reacher
from kbcli.stages.adapt.config import AdaptConfig, PlayCheck
from kbcli.stages.adapt.record import Recorder, end_angles

#: The replays of :func:`play_success`, in the order their generators are spawned.
PLAY_RUNS = ("before", "unadapted", "adapted")


def play_success(model, keyboard: Keyboard, sim: SimConfig, family: str, truth: np.ndarray,
                 estimate: np.ndarray | None, check: PlayCheck, *, rng: np.random.Generator,
                 pool: ActionSamples | None = None) -> dict[str, float]:
    """Success rates (MATCH share) of ``check.notes`` touches of Algorithm 1 with the model's
    actions and the arm of ``sim``: ``before`` (keyboard at its reference pose), ``unadapted``
    (at ``truth``, no correction) and ``adapted`` (at ``truth``, actions corrected by
    ``estimate``); NaN for what was not measured. Each replay has its own child of ``rng``, by
    name (``PLAY_RUNS``), whichever others run. ``pool``: per-class draws of p(action | sound)
    to resample instead of calling ``model.sample_actions`` (see :func:`kbcli.core.playing.play.replay`).
    """
    melody = parse_melody(check.melody, keyboard)
    n = len(transforms.FAMILIES.get(family).params)
    out = {"before": math.nan, "unadapted": math.nan, "adapted": math.nan}
    runs = []
    if check.reference:
        runs += [("before", np.zeros(n), None), ("unadapted", truth, None)]
    if estimate is not None:
        runs.append(("adapted", truth, np.asarray(estimate, float)))
    # one generator per replay by name, never by count: a replay's touches do not depend on
    # which others are measured
    gens = dict(zip(PLAY_RUNS, rng.spawn(len(PLAY_RUNS)), strict=True))
    for name, pose, corr in runs:
        r = gens[name]
        world = World(keyboard, make_reacher(sim), np.asarray(pose, float), family)

        def touch(actions: np.ndarray, world=world, r=r) -> tuple[np.ndarray, np.ndarray]:
            return world.touch(actions, r)

        hist = replay(model, melody, touch, rng=r, n_notes=check.notes, correction=corr,
                      family=family, sampler=None if pool is None else pool.draw)
        out[name] = float(np.mean(hist == MATCH))
    return out

def estimate_errors(est: np.ndarray, truth: np.ndarray, robot_family: str,
                    world_family: str) -> tuple[float, float]:
    """Translation error (px) and angle error (deg) of an estimate against the truth."""
    t_err = float(np.hypot(*(est[-2:] - truth[-2:])))
    a_est = transforms.FAMILIES.get(robot_family).angle(est)
    a_true = transforms.FAMILIES.get(world_family).angle(truth)
    return t_err, abs(transforms.wrap_degrees(a_est - a_true))

def experiment(cfg: AdaptConfig, model, keyboard: Keyboard, true_params: np.ndarray, *,
               rng: np.random.Generator, world_family: str | None = None,
               table: LikelihoodTable | None = None,
               snapshot_steps: tuple[int, ...] = (), samples: ActionSamples | None = None,
               play: PlayCheck | None = None, play_pool: ActionSamples | None = None,
               reference_rng: np.random.Generator | None = None,
               on_step: Callable[[int], None] | None = None,
               timings: dict[str, float] | None = None,
               keep: dict | None = None) -> dict[str, np.ndarray]:
    """One adaptation against a world whose keyboard sits at ``true_params``.

    ``true_params`` (P,) is in ``world_family`` parameters (default: ``cfg.robot.family``);
    ``rng`` is split into the robot's and the world's generators; the posterior is kept at
    ``snapshot_steps`` (0: the prior). ``table`` and ``samples`` (the model raster and the ``kde``
    posterior's per-class samples) may be shared across experiments; default: made per run.
    With ``play``, also measures the playing success (``play_before``, ``play_unadapted``,
    ``play_adapted``, NaN when not measured), from a third child of ``rng``, resampling
    ``play_pool`` (default: the model samples). ``on_step(step)`` is called after each
    observation; ``timings`` receives ``setup_ms`` (the adapter's set-up, which ``step_ms`` leaves
    out); ``keep`` receives ``adapter`` (its state after the last touch).

    Returns the records per step t = 1..T (:meth:`~kbcli.stages.adapt.record.Recorder.arrays`;
    fewer than ``max_steps`` when ``cfg.stop`` ends early), with, world side, ``true_landed`` (T, 2)
    and ``truth_logratio`` (T,): the log of the posterior at the truth over its maximum.
    """
    world_family = cfg.robot.family if world_family is None else world_family
    truth = np.asarray(true_params, float)
    robot_rng, world_rng = rng.spawn(2)
    adapter = _prepared(cfg, model, robot_rng, table, samples, timings, keep)
    touch = _Touches(World(keyboard, make_reacher(cfg.sim_config()), truth, world_family),
                     world_rng)
    out = _run(cfg, adapter, touch, truth, world_family, snapshot_steps, on_step)
    if play is not None:
        res = _play_after(cfg, model, keyboard, truth, world_family, out, play,
                          rng=rng.spawn(1)[0], pool=play_pool, reference_rng=reference_rng)
        out.update({f"play_{k}": np.float64(v) for k, v in res.items()})
    return out


def _run(cfg: AdaptConfig, adapter: Adapter, touch: _Touches, truth: np.ndarray,
         world_family: str, snapshot_steps: tuple[int, ...],
         on_step: Callable[[int], None] | None) -> dict[str, np.ndarray]:
    """Adapt for ``cfg.max_steps`` touches (or to the stop): the records :func:`experiment`
    returns."""
    rec = Recorder(adapter, [s for s in snapshot_steps if 0 <= int(s) <= cfg.max_steps])
    truth_robot = _as_family(truth, world_family, cfg.robot.family)
    ratios = []
    for st in adapt(adapter, touch, cfg.max_steps, use_landed=cfg.feedback == "landed",
                    stop=cfg.stop):
        err, aerr = estimate_errors(st.estimate, truth, cfg.robot.family, world_family)
        ml_err, _ = estimate_errors(st.ml, truth, cfg.robot.family, world_family)
        rec.add(st, (err, ml_err, aerr), touch.pose())
        ratios.append(adapter.posterior.log_ratio_at(truth_robot))
        if on_step is not None:
            on_step(st.t)
    return {**rec.arrays(), "truth_logratio": np.asarray(ratios, float),
            "true_landed": np.asarray(touch.true_landed, float).reshape(-1, 2)}


def _prepared(cfg: AdaptConfig, model, rng: np.random.Generator, table, samples,
              timings: dict[str, float] | None, keep: dict | None = None) -> Adapter:
    """The robot's adapter, prepared for its first touch; its set-up time in ``timings``, itself
    in ``keep`` (``adapter``)."""
    t0 = time.perf_counter()
    adapter = Adapter(model, cfg.adapter_config(), rng=rng, table=table, samples=samples).prepare()
    if timings is not None:
        timings["setup_ms"] = 1e3 * (time.perf_counter() - t0)
    if keep is not None:
        keep["adapter"] = adapter
    return adapter


class _Touches:
    """The world's side of one adaptation, called with each action: touches the world and keeps
    where the finger truly landed (``true_landed``) and the arm's pose after each touch
    (dynamics mode)."""

    def __init__(self, world: World, rng: np.random.Generator) -> None:
        self.world, self.rng = world, rng
        self.true_landed: list[np.ndarray] = []
        self.poses: list[np.ndarray] = []

    def __call__(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        felt, heard = self.world.touch(action[None, :], self.rng)
        self.true_landed.append(self.world.last_landed[0])
        ang = end_angles(self.world.reacher)
        if ang is not None and len(ang):
            self.poses.append(ang[-1])
        return felt[0], heard[0]

    def pose(self) -> np.ndarray | None:
        """The arm's pose after the last touch (None: not simulated)."""
        return self.poses[-1] if self.poses else None


def _play_after(cfg: AdaptConfig, model, keyboard: Keyboard, truth: np.ndarray,
                world_family: str, out: dict[str, np.ndarray], play: PlayCheck, *,
                rng: np.random.Generator, pool: ActionSamples | None,
                reference_rng: np.random.Generator | None = None) -> dict[str, float]:
    """:func:`play_success` around an adaptation whose records are ``out``, corrected by its final
    estimate in the world's parameters. The reference replays (``play.reference``), which do not
    depend on the adaptation, draw from ``reference_rng`` when given (so they measure the same
    whichever experiment runs them), else from children of ``rng``, as the adapted replay."""
    final = ESTIMATORS.get(cfg.robot.estimator.name).final(out)
    if world_family != cfg.robot.family:  # correct in the world's parameters
        final = _as_family(final, cfg.robot.family, world_family)
    sim = cfg.sim_config()
    if reference_rng is None or not play.reference:
        return play_success(model, keyboard, sim, world_family, truth, final, play, rng=rng,
                            pool=pool)
    adapted = PlayCheck(melody=play.melody, notes=play.notes, reference=False)
    res = play_success(model, keyboard, sim, world_family, truth, final, adapted, rng=rng,
                       pool=pool)
    ref = play_success(model, keyboard, sim, world_family, truth, None, play, rng=reference_rng,
                       pool=pool)
    return {**res, "before": ref["before"], "unadapted": ref["unadapted"]}


def _as_family(est: np.ndarray, family: str, world_family: str) -> np.ndarray:
    """An estimate in ``family`` parameters as ``world_family`` parameters (angle 0 added or
    dropped)."""
    est = np.asarray(est, float)
    if family == world_family:
        return est
    fam = transforms.FAMILIES.get(family)
    return transforms.FAMILIES.get(world_family).compose(fam.angle(est), fam.shift(est))

def build_shared_table(cfg: AdaptConfig, model) -> LikelihoodTable:
    """The model raster for ``cfg`` (to share across many :func:`experiment` calls)."""
    return build_table(model, cfg.adapter_config())


def build_shared_samples(cfg: AdaptConfig, model, seed,
                         table: LikelihoodTable | None = None) -> ActionSamples | None:
    """The ``kde`` posterior's per-class samples for ``cfg`` (None for other posteriors), drawn
    from ``seed`` once per class, to share across many :func:`experiment` calls (``table``: the
    model raster for ``cfg``, built when needed and not given)."""
    if not cfg.robot.kind.uses_samples:
        return None
    return build_samples(model, cfg.adapter_config(), seed, table=table)
