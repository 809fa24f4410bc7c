"""The records of one adaptation: :class:`Recorder` keeps each step and the posterior snapshots,
:func:`run_attrs` and :func:`run_data` make a ``run`` artifact's summary and datasets from them."""

from __future__ import annotations

import numpy as np

from kbcli.core.adaptation.adapter import Adapter
from kbcli.core.adaptation.config import AdapterConfig
from kbcli.core.adaptation.estimators import ESTIMATORS
from kbcli.core.adaptation.loop import Step
from kbcli.core.instrument import transforms

#: Per-step records of a ``run`` artifact, in the order :meth:`Recorder.add` takes them.
RECORDS = ("actions", "landed", "perceived", "classes", "estimates", "means", "errors", "ml_errors",
           "angle_errors", "entropy", "ml_prob", "mass", "stop", "step_ms")


class Recorder:
    """The per-step records and posterior snapshots of one adaptation: what a ``run`` artifact
    holds, whoever touched (the simulated world in :func:`experiment`, or a robot in another
    process through ``kbcli serve``). ``adapter`` is read after each step; the posterior is kept
    at ``snapshot_steps`` (0: the prior).
    """

    def __init__(self, adapter: Adapter, snapshot_steps=()) -> None:
        self.adapter = adapter
        self.snaps = {int(s) for s in snapshot_steps if int(s) >= 0}
        self.rec: dict[str, list] = {k: [] for k in RECORDS}
        self.joint_angles: list[np.ndarray] = []
        self.model_error: list[tuple[float, float]] = []
        self.snap_t: list[int] = []
        self.snap_log: list[np.ndarray] = []
        self.snap_ang: list[np.ndarray] = []
        if 0 in self.snaps:
            self.snapshot(0)

    def __len__(self) -> int:
        return len(self.rec["actions"])

    def snapshot(self, t: int) -> None:
        """Keep the current posterior as the one after step ``t``."""
        post = self.adapter.posterior
        self.snap_t.append(t)
        with np.errstate(divide="ignore"):
            self.snap_log.append(np.log(post.translation_marginal()).astype(np.float32))
        pa = post.marginals()[0]
        self.snap_ang.append(np.ones(1) if pa is None else pa)

    def add(self, st: Step, errors: tuple[float, float, float] = (np.nan, np.nan, np.nan),
            joint_angles: np.ndarray | None = None) -> None:
        """Record one step; ``errors`` = (px error of the estimate, of the ML cell, angle error
        in degrees) against the truth (NaN when it is unknown, as for a real robot)."""
        err, ml_err, aerr = errors
        for k, v in zip(RECORDS, (st.action, st.landed, st.perceived, st.cls, st.ml, st.mean, err,
                                  ml_err, aerr, st.entropy, st.ml_prob, st.mass, st.stop, st.ms),
                        strict=True):
            self.rec[k].append(v)
        if joint_angles is not None:
            self.joint_angles.append(np.asarray(joint_angles, float).reshape(2))
        robust = getattr(self.adapter, "robust", None)
        if robust is not None:
            self.model_error.append((robust.blur_mean(), robust.outlier_mean()))
        if st.t in self.snaps:
            self.snapshot(st.t)

    def arrays(self) -> dict[str, np.ndarray]:
        """The records as arrays, per step t = 1..T: ``actions`` (T, 2), ``landed`` (T, 2) where
        the robot felt it landed, ``perceived`` (T, D), ``classes`` (T,), ``estimates`` (T, P)
        maximum-likelihood cell, ``means`` (T, P) posterior mean, ``errors`` (T,) px error of the
        estimate (the robot's estimator) vs the truth, ``ml_errors`` (T,), ``angle_errors`` (T,)
        deg, ``entropy`` (T,) nats, ``ml_prob`` (T,), ``mass`` (T,), ``stop`` (T,) bool,
        ``step_ms`` (T,); ``joint_angles`` (T, 2) the arm's pose after each touch (dynamics mode);
        ``snapshot_steps`` (S,), ``snapshots`` (S, ny, nx) log translation marginals,
        ``snapshot_angles`` (S, A) angle marginals (rigid); ``dx``, ``dy``, ``angles`` grid
        axes; and what the posterior resolved from the model."""
        g = self.adapter.grid
        d = int(np.shape(self.adapter.model.class_features_)[1])
        out = {k: np.asarray(v) for k, v in self.rec.items()}
        for k, width in (("actions", 2), ("landed", 2), ("perceived", d),
                         ("estimates", g.n_params), ("means", g.n_params)):
            out[k] = np.asarray(out[k], float).reshape(-1, width)
        for k in ("errors", "ml_errors", "angle_errors", "entropy", "ml_prob", "mass", "step_ms"):
            out[k] = np.asarray(out[k], float)
        out["classes"] = out["classes"].astype(np.int64)
        out["stop"] = out["stop"].astype(bool)
        if self.joint_angles and len(self.joint_angles) == len(self):
            out["joint_angles"] = np.stack(self.joint_angles)
        if self.model_error and len(self.model_error) == len(self):
            me = np.asarray(self.model_error, float)
            out["blur_mean"], out["outlier_mean"] = me[:, 0], me[:, 1]
        out.update(dx=g.dx, dy=g.dy, angles=g.angles,
                   snapshot_steps=np.asarray(self.snap_t, np.int64))
        if self.snap_t:
            out["snapshots"] = np.stack(self.snap_log)
            out["snapshot_angles"] = np.stack(self.snap_ang)
        if self.adapter.kind.uses_samples:
            out["bandwidths"] = np.asarray(self.adapter.bandwidths, float)
        out["redundancy_radius"] = np.float64(getattr(self.adapter, "redundancy_radius", 0.0))
        rob = getattr(self.adapter, "robust", None)
        out["robust_blurs"] = (np.asarray(rob.nuisance.blurs, float) if rob is not None
                               else np.empty(0))
        out["robust_eta"] = np.float64(rob.eta if rob is not None else 1.0)
        return out

def end_angles(reacher) -> np.ndarray | None:
    """(n, 2) joint angles the reacher ended its last reaches in (dynamics mode), else None."""
    ang = getattr(reacher, "last_end_angles", None)
    return None if ang is None else np.asarray(ang, float).reshape(-1, 2)

def steps_below(errors: np.ndarray, threshold: float) -> int | None:
    """First step (1-based) with ``errors < threshold``; None if never."""
    hit = np.flatnonzero(np.asarray(errors) < threshold)
    return int(hit[0] + 1) if len(hit) else None

def run_attrs(res: dict[str, np.ndarray], acfg: AdapterConfig, *, truth: np.ndarray | None = None,
              world_family: str | None = None) -> dict:
    """The summary of a ``run`` artifact from its records (:meth:`Recorder.arrays`).

    Without a ``truth`` (a real robot, ``kbcli serve``) the errors are unknown: ``truth``,
    ``final_error_px``, ``final_angle_error_deg`` and ``steps_to_1px`` are None. A run of no step
    has no estimate.
    """
    names = transforms.FAMILIES.get(acfg.family).params
    errors = np.asarray(res["errors"], float)
    n = int(len(errors))
    known = truth is not None and n > 0
    reach1 = None
    if known:
        angle_ok = res["angle_errors"] < 0.5
        reach1 = steps_below(np.where(angle_ok, errors, np.inf), 1.0)
    stop_at = np.flatnonzero(res["stop"])
    final = None
    if n:
        final = ESTIMATORS.get(acfg.estimator.name).final(res)
    wf = world_family or acfg.family
    return {
        "strategy": acfg.strategy.name,
        "posterior": acfg.posterior.name,
        "family": acfg.family,
        "world_family": wf if truth is not None else None,
        "steps": n,
        "final_error_px": float(errors[-1]) if known else None,
        "final_angle_error_deg": float(res["angle_errors"][-1]) if known else None,
        "steps_to_1px": reach1,
        "stop_step": int(stop_at[0] + 1) if len(stop_at) else None,
        "final_entropy": float(res["entropy"][-1]) if n else None,
        "estimate": None if final is None else
        {k: float(v) for k, v in zip(names, final, strict=True)},
        "truth": None if truth is None else transforms.FAMILIES.get(wf).as_dict(truth),
        "grid_cells": acfg.grid_cells,
        "median_step_ms": float(np.median(res["step_ms"])) if n else None,
        # resolved from the model's own reliability when the config leaves it None
        "redundancy_radius": float(res["redundancy_radius"]) if "redundancy_radius" in res else None,
        # the boundary blurs the robust posterior weighed (widened for a weak model; [] if plain)
        "robust_blurs": ([float(v) for v in res["robust_blurs"]] if "robust_blurs" in res
                         else None),
        # the learning rate the robust posterior tempered each touch with (1: untempered)
        "robust_eta": float(res["robust_eta"]) if "robust_eta" in res else None,
    }


def run_data(res: dict[str, np.ndarray]) -> dict:
    """The datasets of a ``run`` artifact: the records, with the wall-clock times in ``timing/``."""
    data = {k: v for k, v in res.items()
            if k not in ("step_ms", "redundancy_radius", "robust_blurs", "robust_eta")}
    data["timing"] = {"step_ms": res["step_ms"]}
    return data
