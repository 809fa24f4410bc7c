"""kbcli's learning against an established active learner, side by side.

The peer is scikit-activeml's pool-based uncertainty sampling around scikit-learn classifiers
(:data:`PEERS`, an optional dependency: ``pip install -e '.[bench]'``). Both learn the same keyboard
from the same simulator and seeds and are scored alike (:mod:`kbcli.core.model.accuracy`) at the
same budgets; the peer is handed each touch's key and the list of all keys, which kbcli must
discover, and queries ``batch`` of ``pool`` uniform actions per refit after ``init`` random reaches.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from kbcli.bench.learn import bench_keyboard
from kbcli.core.config import Config, Count, Names, Positive, Whole
from kbcli.core.instrument.keyboard import Keyboard, match
from kbcli.core.model import accuracy as scoring
from kbcli.core.model.base import grid_points
from kbcli.core.model.classes import AUTO, fit_model
from kbcli.core.model.explore import Exploration, ExploreConfig
from kbcli.core.model.select import choose
from kbcli.core.registry import Registry
from kbcli.errors import ConfigError
from kbcli.sim import SimConfig, World, make_reacher


@dataclass(frozen=True)
class Peer:
    """A scikit-learn classifier and scikit-activeml's uncertainty measure for it."""

    make: Callable[[int], object]
    method: str


def _forest(seed: int):
    from sklearn.ensemble import RandomForestClassifier
    return RandomForestClassifier(n_estimators=100, random_state=seed, n_jobs=1)


def _extra(seed: int):
    from sklearn.ensemble import ExtraTreesClassifier
    return ExtraTreesClassifier(n_estimators=100, random_state=seed, n_jobs=1)


def _knn(seed: int):
    from sklearn.neighbors import KNeighborsClassifier
    return KNeighborsClassifier(n_neighbors=5, weights="distance")


def _parzen(seed: int):
    from skactiveml.classifier import ParzenWindowClassifier
    return ParzenWindowClassifier(metric="rbf", metric_dict={"gamma": 1 / (2 * 15.0 ** 2)})


#: The peer configurations (classifier + uncertainty measure), fixed hyper-parameters.
PEERS: Registry[Peer] = Registry("peer")
PEERS.register("forest-entropy", Peer(_forest, "entropy"),
               summary="random forest (100 trees), entropy sampling")
PEERS.register("extratrees-entropy", Peer(_extra, "entropy"),
               summary="extra trees (100 trees), entropy sampling")
PEERS.register("knn-margin", Peer(_knn, "margin_sampling"),
               summary="k-NN (k = 5, distance-weighted), margin sampling")
PEERS.register("parzen-entropy", Peer(_parzen, "entropy"),
               summary="Parzen window (RBF, 15 px), entropy sampling")


class PeerConfig(Config):
    """Settings of ``kbcli bench learn --peer`` (module docstring)."""

    what = "bench peer"
    layouts: Names = ("grid", "hex", "piano", "pads", "polygons")
    peers: Names = tuple(PEERS.names())
    seeds: Count = 5
    budgets: tuple[Whole, ...] = (150, 300, 800)
    seed: Whole = 0
    pool: Count = 4000
    init: Count = 10
    batch: Count = 10
    eval_step: Positive = 1.0


def _check(cfg: PeerConfig) -> None:
    for name in cfg.peers:
        PEERS.check(name)
    if any(b < cfg.init for b in cfg.budgets):
        raise ConfigError(f"bench peer: every budget must be at least init = {cfg.init}")


def _scores(predict: Callable[[np.ndarray], np.ndarray], kb: Keyboard, step: float
            ) -> tuple[float, float]:
    """Accuracy and boundary error (px) of a key predictor over the working area."""
    _, pts = grid_points(kb.area, step)
    flat = pts.reshape(-1, 2)
    pred = np.asarray(predict(flat)).reshape(pts.shape[:2])
    true = kb.key_at(flat).reshape(pts.shape[:2])
    return scoring.accuracy_from_maps(pred, true), scoring.boundary_error(pred, true, step)


def _keys_heard(kb: Keyboard, heard: np.ndarray) -> np.ndarray:
    """Key index of each heard feature row (-1: silence or no key)."""
    out = np.full(len(heard), -1, dtype=np.int64)
    sound = ~np.isnan(heard).all(axis=1)
    if sound.any():
        out[sound] = match(heard[sound], kb.features, kb.config.match_threshold)
    return out


def peer_run(cfg: PeerConfig, kb: Keyboard, name: str, seed: np.random.SeedSequence
             ) -> dict[int, tuple[float, float]]:
    """One peer learner up to the largest budget: {budget: (accuracy, boundary error)}."""
    from skactiveml.classifier import SklearnClassifier
    from skactiveml.pool import UncertaintySampling
    from skactiveml.utils import MISSING_LABEL

    peer = PEERS.get(name)
    rng = np.random.default_rng(seed)
    world = World(kb, make_reacher(SimConfig(mode="ideal")))
    x0, y0, x1, y1 = kb.area
    pool = rng.uniform((x0, y0), (x1, y1), size=(cfg.pool, 2))
    y = np.full(cfg.pool, MISSING_LABEL)
    classes = np.arange(-1, len(kb.features))
    state = int(rng.integers(2 ** 31))
    clf = SklearnClassifier(peer.make(state), classes=classes, random_state=state)
    qs = UncertaintySampling(method=peer.method, random_state=state)

    def label(idx: np.ndarray) -> None:
        _, heard = world.touch(pool[idx], rng)
        y[idx] = _keys_heard(kb, heard)

    label(rng.choice(cfg.pool, cfg.init, replace=False))
    out, n = {}, cfg.init
    with warnings.catch_warnings():  # scikit-learn's notes on few labelled samples per class
        warnings.simplefilter("ignore", UserWarning)
        for budget in sorted(cfg.budgets):
            while n < budget:
                k = min(cfg.batch, budget - n)
                clf.fit(pool, y)
                label(np.atleast_1d(qs.query(pool, y, clf, fit_clf=False, batch_size=k)))
                n += k
            clf.fit(pool, y)
            out[budget] = _scores(clf.predict, kb, cfg.eval_step)
    return out


def kbcli_run(cfg: PeerConfig, kb: Keyboard, seed: np.random.SeedSequence
              ) -> dict[int, tuple[float, float]]:
    """kbcli's default learner (``kbcli learn``: active exploration, ``--model-class auto``), scored
    at each budget with the class chosen by cross-validation on the samples so far
    (:func:`kbcli.core.model.select.choose`), without the learn stage's calibration."""
    rng = np.random.default_rng(seed)
    world = World(kb, make_reacher(SimConfig(mode="ideal")))
    ex = Exploration(ExploreConfig(budget=max(cfg.budgets), model_class=AUTO), world.touch,
                     kb.area, kb.config.match_threshold, rng)
    pick = np.random.default_rng(np.random.SeedSequence(seed.entropy,
                                                        spawn_key=(*seed.spawn_key, 10)))
    out: dict[int, tuple[float, float]] = {}
    for step in ex:
        for b in [b for b in cfg.budgets if b not in out and step.n_reaches >= b]:
            sel = choose(ex.landed, ex.perceived, match_threshold=kb.config.match_threshold,
                         area=kb.area, rng=pick, explored_with=ex.explored_with)
            model = fit_model(sel.chosen, ex.landed, ex.perceived,
                              match_threshold=kb.config.match_threshold, area=kb.area,
                              targets=ex.targets)
            pred, true = scoring.key_maps(model, kb, cfg.eval_step)
            out[b] = (scoring.accuracy_from_maps(pred, true),
                      scoring.boundary_error(pred, true, cfg.eval_step), sel.chosen)
    return out


def _one(cfg: PeerConfig, layout: str, who: str, i: int, seed: np.random.SeedSequence
         ) -> tuple[str, str, int, dict[int, tuple[float, float]]]:
    from kbcli.io.runner import no_leak_restarts

    no_leak_restarts()  # in a worker: its caches grow past loky's 300 MB "leak" and restarts
    kb = bench_keyboard(layout)
    got = kbcli_run(cfg, kb, seed) if who == "kbcli" else peer_run(cfg, kb, who, seed)
    return layout, who, i, got


def runs(cfg: PeerConfig, jobs: int = 1
         ) -> Iterator[tuple[str, str, int, dict[int, tuple[float, float]]]]:
    """(layout, learner, seed index, scores) for kbcli and every peer, seed by seed, in that
    order whatever ``jobs`` (local worker processes, joblib: each run is seeded by its own
    index, so the numbers do not depend on how many run at once)."""
    _check(cfg)
    seeds = np.random.SeedSequence(cfg.seed).spawn(cfg.seeds)
    tasks = [(layout, who, i, s) for layout in cfg.layouts for i, s in enumerate(seeds)
             for who in ("kbcli", *cfg.peers)]
    if jobs <= 1:
        for t in tasks:
            yield _one(cfg, *t)
        return
    from joblib import Parallel, delayed

    yield from Parallel(n_jobs=jobs, return_as="generator")(delayed(_one)(cfg, *t) for t in tasks)


def summarize(cfg: PeerConfig, results: list[tuple]) -> list[dict]:
    """Per layout, learner and budget: the median accuracy and boundary error over the seeds."""
    rows = []
    keys = dict.fromkeys((layout, who) for layout, who, _, _ in results)
    for layout, who in keys:
        got = [r for lay, w, _, r in results if (lay, w) == (layout, who)]
        for b in sorted(cfg.budgets):
            row = {"layout": layout, "learner": who, "budget": b, "runs": len(got),
                   "accuracy": float(np.median([g[b][0] for g in got])),
                   "boundary_error": float(np.median([g[b][1] for g in got]))}
            chosen = [g[b][2] for g in got if len(g[b]) > 2]
            if chosen:  # kbcli's auto: the classes it chose, how often
                row["classes"] = ", ".join(f"{c} x{chosen.count(c)}" for c in
                                           sorted(set(chosen), key=chosen.index))
            rows.append(row)
    return rows


def verdicts(rows: list[dict]) -> list[dict]:
    """Per layout and budget: kbcli against the best peer on each score (higher accuracy, lower
    boundary error), and whether kbcli is at or above it on both."""
    out = []
    cells = dict.fromkeys((r["layout"], r["budget"]) for r in rows)
    for layout, b in cells:
        here = [r for r in rows if (r["layout"], r["budget"]) == (layout, b)]
        ours = next((r for r in here if r["learner"] == "kbcli"), None)
        peers = [r for r in here if r["learner"] != "kbcli"]
        if ours is None or not peers:
            continue
        best_acc = max(peers, key=lambda r: r["accuracy"])
        best_be = min(peers, key=lambda r: r["boundary_error"])
        out.append({"layout": layout, "budget": b,
                    "kbcli_accuracy": ours["accuracy"], "peer_accuracy": best_acc["accuracy"],
                    "peer_accuracy_by": best_acc["learner"],
                    "kbcli_boundary_error": ours["boundary_error"],
                    "peer_boundary_error": best_be["boundary_error"],
                    "peer_boundary_by": best_be["learner"],
                    "kbcli_wins": bool(ours["accuracy"] >= best_acc["accuracy"]
                                       and ours["boundary_error"] <= best_be["boundary_error"])})
    return out


def tables(cfg: PeerConfig, rows: list[dict]) -> list[dict]:
    """The two tables ``kbcli bench learn --peer`` prints and writes (``{"title", "columns",
    "rows"}``, rows of plain values): every learner's medians, and the per-layout verdicts."""
    learners = [{"layout": r["layout"], "budget": r["budget"], "learner": r["learner"],
                 "accuracy %": round(100 * r["accuracy"], 2),
                 "boundary error px": round(r["boundary_error"], 3),
                 "kbcli classes": r.get("classes", "")}
                for r in sorted(rows, key=lambda r: (cfg.layouts.index(r["layout"])
                                                     if r["layout"] in cfg.layouts else 0,
                                                     r["budget"], r["learner"] != "kbcli"))]
    verdict = [{"layout": v["layout"], "budget": v["budget"],
                "kbcli accuracy %": round(100 * v["kbcli_accuracy"], 2),
                "best peer accuracy %": round(100 * v["peer_accuracy"], 2),
                "accuracy by": v["peer_accuracy_by"],
                "kbcli boundary px": round(v["kbcli_boundary_error"], 3),
                "best peer boundary px": round(v["peer_boundary_error"], 3),
                "boundary by": v["peer_boundary_by"],
                "verdict": "kbcli at or above" if v["kbcli_wins"] else
                ("accuracy only" if v["kbcli_accuracy"] >= v["peer_accuracy"] else
                 "boundary only" if v["kbcli_boundary_error"] <= v["peer_boundary_error"]
                 else "peer better")} for v in verdicts(rows)]
    head = (f"{cfg.seeds} seeds, medians, ideal mode, scored on a {cfg.eval_step:g} px grid")
    return [
        {"title": f"kbcli (auto, active) and scikit-activeml peers: {head}",
         "columns": list(learners[0]) if learners else [], "rows": learners},
        {"title": "verdict per layout and budget: kbcli against the best peer on each score",
         "columns": list(verdict[0]) if verdict else [], "rows": verdict},
    ]


__all__ = ["PEERS", "Peer", "PeerConfig", "peer_run", "kbcli_run", "runs", "summarize", "verdicts",
           "tables"]
