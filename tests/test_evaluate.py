"""The evaluation protocol, its statistics and its execution engine (issue 6).

The engine's guarantees (serial == local processes == Dask bit for bit; resume == uninterrupted;
a checkpoint from another config refused) are tested with ``fake_experiment``, a small deterministic
test double of the adapt stage's ``experiment`` injected by name, and once with the real one.
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from helpers import one_line_error as _one_line_error
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.cli import app
from kbcli.core.adaptation import stats
from kbcli.core.instrument.keyboard import Keyboard, KeyboardConfig
from kbcli.errors import ConfigError, KbcliError
from kbcli.io.artifact import read_artifact, sha256_file, write_artifact
from kbcli.io.checkpoint import Checkpoint, source_digest
from kbcli.io.runner import Job, execute
from kbcli.stages import evaluate as stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact

FAKE = "test_evaluate:fake_experiment"


def fake_experiment(cfg, model, keyboard, true_params, *, rng, table=None, snapshot_steps=(),
                    play=None, **_):
    """A deterministic stand-in for ``kbcli.stages.adapt.experiment``: the error shrinks with the
    step, faster for non-random strategies, with seeded noise; playing success grows as the final
    error shrinks. Its wall time per step is real (and must stay out of the artifact)."""
    t0 = time.perf_counter()
    steps = getattr(cfg, "max_steps", 12)
    strategy = getattr(cfg, "strategy", "random")
    rate = 0.25 if strategy == "random" else 0.6
    t = np.arange(steps)
    noise = rng.normal(size=(steps, 2))
    est = np.asarray(true_params)[None] + (12 * np.exp(-rate * t))[:, None] * noise
    errors = np.hypot(*(est - true_params).T)
    out = {
        "actions": rng.uniform(200, 600, size=(steps, 2)),
        "classes": rng.integers(0, 33, size=steps),
        "estimates": est,
        "errors": errors,
        "angle_errors": np.zeros(steps),
        "entropy": 8.0 - 0.3 * t * (1 + rate),
        "snapshots": rng.random((3, 5, 5)),
        "snapshot_steps": np.array([1, 2, 3]),
    }
    if play is not None:
        out["play_adapted"] = float(np.clip(1 - errors[-1] / 50, 0, 1))
        if play.reference:
            out["play_before"] = 0.99
            out["play_unadapted"] = float(np.clip(1 - np.hypot(*true_params) / 50, 0, 1))
    out["step_ms"] = np.full(steps, (time.perf_counter() - t0) * 1e3 / steps)
    return out


def small_config(**kw) -> stage.EvaluateConfig:
    """A small protocol with one method ``m`` (``strategies=`` sets its strategies)."""
    strategies = kw.pop("strategies", ["random", "active"])
    d = {
        "seed": 7,
        "experiments": 3,
        "methods": {"m": {"strategies": strategies}},
        "judged": "m",
        "modes": ["ideal"],
        "max_steps": 6,
        "thresholds": [10.0, 4.0, 1.0],
        "categories": {
            "small": {"limit": 10.0, "displacements": [[3.0, 4.0], [-6.0, 0.0]]},
            "large": {"limit": 40.0, "displacements": [[20.0, -25.0]]},
        },
    }
    if "adapt" in kw:  # the layout before named methods
        del d["methods"], d["judged"]
        d["strategies"] = strategies
    d.update(kw)
    return stage.EvaluateConfig.from_dict(d)


def test_the_layout_before_methods_is_one_method():
    cfg = small_config(adapt={"posterior": "kde"})
    assert [m.name for m in cfg.methods] == ["kbcli"] and cfg.judged == "kbcli"
    assert stage.adapt_config(cfg, "kbcli", "active", "ideal").robot.posterior.name == "kde"


@pytest.fixture
def model_path(tmp_path):
    kb = keyboard_stage.run(KeyboardConfig())
    write_artifact(kb, tmp_path / "kb.h5")
    path = tmp_path / "model.h5"
    write_artifact(exact_artifact(read_artifact(tmp_path / "kb.h5")), path)
    return path


@pytest.fixture(scope="module")
def cluster():
    """A 2-worker Dask LocalCluster on loopback, shared by this module's tests."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as c:
        yield c.scheduler_address


@pytest.fixture
def fake(monkeypatch):
    monkeypatch.setattr(stage, "EXPERIMENT", FAKE)


def write_config(path, **kw):
    cfg = small_config(**kw)
    lines = ["[evaluate]"]
    body = cfg.to_dict()
    cats = body.pop("categories")
    methods = body.pop("methods")
    noise = body.pop("reach_noise")
    arms = body.pop("arm")
    for k, v in body.items():
        lines.append(f"{k} = {json.dumps(v)}")
    lines += ["[evaluate.reach_noise]"] + [f"{m} = {v}" for m, v in noise.items()]
    lines += ["[evaluate.arm]"] + [f'{m} = "{a["preset"]}"' for m, a in arms.items()]
    for name, m in methods.items():
        lines += [f"[evaluate.methods.{name}]"] + [f"{k} = {json.dumps(v)}" for k, v in m.items()]
    for name, c in cats.items():
        lines += [f"[evaluate.categories.{name}]", f"limit = {c['limit']}",
                  f"displacements = {json.dumps(c['displacements'])}"]
    path.write_text("\n".join(lines) + "\n")
    return path


# -- statistics -----------------------------------------------------------------------------------
def test_rmse_and_samples_to_threshold_known_answers():
    e = np.array([[5.0, 3.0, 0.5], [5.0, 1.0, 2.0]])
    np.testing.assert_allclose(stats.rmse_curve(e), [5.0, np.sqrt(5.0), np.sqrt(2.125)])
    counts = stats.samples_to_threshold(e, np.array([4.0, 1.5, 0.1]))
    np.testing.assert_array_equal(counts, [[2, 3, 4], [2, 2, 4]])  # 4 = never (T + 1)
    np.testing.assert_allclose(stats.reached(counts, 3), [1.0, 1.0, 0.0])
    med = stats.median_samples(counts, 3)
    assert med[0] == 2 and med[1] == 2.5 and np.isnan(med[2])


def test_mannwhitney_direction_ties_and_tie_correction():
    a = np.array([[1], [2], [2], [3]] * 5)
    b = a + 5
    eff, p = stats.mannwhitney_pvalues(a, b)
    assert eff[0] == -0.5 and p[0] < 1e-3  # every run of a is faster than every run of b
    eff, p = stats.mannwhitney_pvalues(a, a)
    assert eff[0] == 0 and p[0] == pytest.approx(1.0)
    _, p = stats.mannwhitney_pvalues(np.full((6, 1), 41), np.full((6, 1), 41))  # nobody got there
    assert p[0] == 1.0
    # heavy ties (runs capped at T + 1): the tie-corrected variance is smaller, so p is smaller
    # than the untied rank-sum test's, and equals the textbook tie-corrected z
    from scipy import stats as sps

    x = np.array([3, 5, 41, 41, 41, 41, 41, 41] * 3, float)
    y = np.array([2, 3, 4, 5, 6, 41, 41, 41] * 3, float)
    _, p = stats.mannwhitney_pvalues(y[:, None], x[:, None])
    assert p[0] < sps.ranksums(y, x).pvalue
    n, m = len(y), len(x)
    r = sps.rankdata(np.concatenate([y, x]))
    u = r[:n].sum() - n * (n + 1) / 2
    _, t = np.unique(np.concatenate([y, x]), return_counts=True)
    var = n * m / 12 * ((n + m + 1) - (t**3 - t).sum() / ((n + m) * (n + m - 1)))
    z = (abs(u - n * m / 2) - 0.5) / np.sqrt(var)
    assert p[0] == pytest.approx(2 * sps.norm.sf(z), rel=1e-9)


def test_signed_rank_paired_known_answer():
    a = np.arange(1.0, 11.0)[:, None]
    b = a + np.arange(1.0, 11.0)[:, None]  # every pair: a faster, by distinct amounts
    eff, p = stats.signed_rank_pvalues(a, b)
    assert eff[0] == -1.0 and p[0] == pytest.approx(2 / 2**10)  # exact: the most extreme case
    assert p[0] == pytest.approx(stats.min_pvalue_paired(10))
    # the same numbers unpaired: the pairing is what makes them so significant
    _, pu = stats.mannwhitney_pvalues(a, b)
    assert pu[0] > 10 * p[0]
    eff, p = stats.signed_rank_pvalues(a, a)  # no nonzero difference
    assert eff[0] == 0 and p[0] == 1.0
    with pytest.raises(ValueError, match="same shape"):
        stats.signed_rank_pvalues(a, b[:5])


def test_smallest_attainable_pvalue():
    from math import comb

    assert stats.min_pvalue_unpaired(4, 4) == pytest.approx(2 / comb(8, 4))
    assert stats.min_pvalue_unpaired(200, 200) == pytest.approx(2 / comb(400, 200), rel=1e-9)
    assert stats.min_pvalue_unpaired(1000, 1000) == 0.0  # underflows: far below any bound
    assert stats.min_pvalue_paired(1) == 1.0 and stats.min_pvalue_paired(3) == 0.25
    # no test on 4 + 4 runs can reach p < 0.01, and the exact test does reach the bound
    from scipy import stats as sps

    exact = sps.mannwhitneyu([1, 2, 3, 4], [5, 6, 7, 8], method="exact").pvalue
    assert exact == pytest.approx(stats.min_pvalue_unpaired(4, 4))


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(1, 8), st.integers(0, 2**31 - 1))
def test_curve_invariants(n, steps, seed):
    rng = np.random.default_rng(seed)
    e = rng.exponential(3.0, size=(n, steps))
    cur = stats.curves(e, rng.integers(0, 2, size=n))
    assert np.all(cur["q25"] <= cur["median"]) and np.all(cur["median"] <= cur["q75"])
    assert np.all(cur["rmse"] >= cur["mean"] - 1e-12)  # quadratic mean >= arithmetic mean
    counts = stats.samples_to_threshold(e, np.array([5.0, 1.0]))
    assert counts.min() >= 1 and counts.max() <= steps + 1
    assert np.all(counts[:, 0] <= counts[:, 1])  # a looser threshold is reached no later
    hit = counts <= steps
    rows, cols = np.nonzero(hit)
    thr = np.array([5.0, 1.0])
    assert np.all(e[rows, counts[rows, cols] - 1] < thr[cols])


@pytest.mark.parametrize("truth", [(7.3, -3.1), (-13.7, 9.45), (0.37, 21.9)])
def test_playing_success_is_measured_by_replaying_the_melody(truth):
    """Algorithm 1 replayed on displacements that are not multiples of any grid spacing (0.5 px
    grid, 50 px keys): exact before and with the true correction; the analytic share otherwise."""
    from kbcli.core.model.base import ExactModel
    from kbcli.sim import SimConfig
    from kbcli.stages.adapt import PlayCheck, play_success

    kb = Keyboard(KeyboardConfig())
    model = ExactModel(kb)
    truth = np.asarray(truth)
    check = PlayCheck(notes=3000)
    rng = np.random.default_rng(4)
    got = play_success(model, kb, SimConfig(), "translation", truth, truth, check, rng=rng)
    assert got["before"] == 1.0 and got["adapted"] == 1.0
    # actions uniform over a 50 px key land on it with probability (1 - |dx|/50)(1 - |dy|/50)
    share = np.prod(np.clip(1 - np.abs(truth) / 50, 0, 1))
    assert abs(got["unadapted"] - share) < 0.03
    off = truth + np.array([0.37, -1.13])  # an estimate 1.2 px off
    near = play_success(model, kb, SimConfig(), "translation", truth, off,
                        PlayCheck(notes=3000, reference=False), rng=rng)
    assert np.isnan(near["before"]) and np.isnan(near["unadapted"])
    assert abs(near["adapted"] - (1 - 0.37 / 50) * (1 - 1.13 / 50)) < 0.01


def test_replay_follows_algorithm_1():
    """MATCH moves on to the next note, NO_MATCH restarts from note 0: with note D always missed,
    the melody A D E D A plays A, D(miss), A, D(miss), ... so every second touch fails."""
    from kbcli.core.instrument.melody import parse_melody
    from kbcli.core.model.base import ExactModel
    from kbcli.core.playing.play import MATCH, NO_MATCH, note_classes, replay

    kb = Keyboard(KeyboardConfig())
    model = ExactModel(kb)
    mel = parse_melody("A:1 D:1 E:0.5 D:2 A:1", kb)
    d_cls = int(note_classes(model, mel)[1])

    def touch(actions):
        heard = kb.perceive(actions, None, "translation", rng=np.random.default_rng(0))
        cls = model.classify(heard)
        heard[cls == d_cls] = np.nan  # D never sounds
        return actions, heard

    hist = replay(model, mel, touch, rng=np.random.default_rng(1), n_notes=40, chunk=7)
    assert hist.tolist() == [MATCH, NO_MATCH] * 20


# -- config and plan ------------------------------------------------------------------------------
def test_paper_config_parses_and_plans():
    from kbcli.io.config import load_toml

    cfg = stage.EvaluateConfig.from_dict(load_toml("pipelines/paper.toml", "evaluate"))
    assert cfg.experiments == 50 and [c.name for c in cfg.categories] == ["small", "medium", "large"]
    assert [c.limit for c in cfg.categories] == [10.0, 20.0, 40.0]
    assert [m.name for m in cfg.methods] == ["paper", "paper-v1", "kbcli", "paper-likelihood"]
    assert cfg.judged == "paper"
    paper = stage.adapt_config(cfg, "paper", "paper-active", "ideal")
    assert (paper.robot.posterior.name, paper.robot.estimator.name) == ("kde", "ml")
    assert (paper.robot.posterior.kde_draw, paper.robot.posterior.kde_floor,
            paper.robot.ml_ties) == \
        ("fresh", 0.0, "random")
    v1 = stage.adapt_config(cfg, "paper-v1", "active", "ideal")
    assert (v1.robot.posterior.kde_draw, v1.robot.posterior.eps(v1.robot.outlier),
            v1.robot.ml_ties) == ("shared", 1e-3, "first")
    ours = stage.adapt_config(cfg, "kbcli", "infogain", "dynamics")
    from kbcli.core.adaptation.config import AdapterConfig

    # kbcli is the adapter's defaults: what they are, it is
    assert ours.robot == AdapterConfig(strategy="infogain")
    tasks = stage.plan(cfg.with_overrides(experiments=2))
    # ideal: paper 2 + paper-v1 2 + kbcli 3 strategies (+ the ablation's 2 on the 4 large
    # displacements); dynamics: the same without the ablation
    assert len(tasks) == 2 * (12 * (7 + 7) + 4 * 2)
    # paper-v1 is seeded as the old `paper` was
    v1_task = next(t for t in tasks if t.method == "paper-v1" and t.strategy == "active")
    assert v1_task.spawn_key[3] == stage.planning._key("paper")
    resolved = stage.resolved_methods(cfg)
    assert resolved["paper"]["options"]["ideal"]["paper-active"]["robot"]["posterior"][
        "kde_samples"] == 10000
    assert resolved["paper-likelihood"]["modes"] == ["ideal"]
    # options left to the model are resolved with it: a model that rates its boundaries 4 px off
    # gets a 16 px spot radius and a blur grid up to 8 px on the robust posterior, none on the KDE
    from kbcli.core.model.base import ExactModel

    weak = ExactModel(Keyboard(KeyboardConfig()))
    weak.reliability_ = {"boundary_error": 4.0}
    by_model = stage.resolved_methods(cfg, weak)
    assert by_model["kbcli"]["from_model"] == {"redundancy_radius": 16.0,
                                               "robust_blurs": [0.0, 1.0, 2.5, 5.0, 8.0],
                                               "robust_eta": 0.141}  # (1.5 / 4)^2
    assert by_model["paper"]["from_model"] == {"redundancy_radius": 0.0, "robust_blurs": [],
                                               "robust_eta": 1.0}
    assert resolved["kbcli"]["from_model"] == {}
    assert cfg == stage.EvaluateConfig.from_dict(cfg.to_dict())
    import pickle

    assert pickle.loads(pickle.dumps(cfg)) == cfg


def test_seeds_do_not_depend_on_selected_modes():
    both = stage.plan(small_config(modes=["ideal", "dynamics"]))
    ideal = stage.plan(small_config(modes=["ideal"]))
    dyn = stage.plan(small_config(modes=["dynamics"]))
    key = lambda t: (t.mode, t.category, t.param_index, t.method, t.strategy, t.rep)  # noqa: E731
    seeds = {key(t): t.seed.generate_state(4).tolist() for t in both}
    for t in ideal + dyn:
        assert t.seed.generate_state(4).tolist() == seeds[key(t)]
    assert len({str(s) for s in seeds.values()}) == len(both)  # all distinct
    assert sum(t.example for t in both) == 2 * 2  # one per mode and strategy
    # ... nor on the methods selected
    two = small_config(methods={"m": {"strategies": ["random", "active"]},
                                "n": {"strategies": ["random"], "posterior": "kde"}})
    assert len(stage.plan(two)) == len(ideal) + len(ideal) // 2
    for t in stage.plan(two):
        if t.method == "m":
            assert t.seed.generate_state(4).tolist() == seeds[key(t)]
    # the reference replays (before, unadapted): once per mode, parametrization and repetition
    refs = [t for t in stage.plan(two) if t.play_reference]
    assert len(refs) == 3 * 3 and all(t.method == "m" and t.strategy == "random" for t in refs)


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ({"bogus": 1}, "unknown evaluate option 'bogus'"),
        ({"strategies": ["random", "psychic"]}, "unknown strategy 'psychic'"),
        ({"experiments": 0}, "evaluate.experiments must be a whole number in [1, 10000], got 0"),
        ({"modes": ["telepathy"]}, "unknown mode 'telepathy'"),
        ({"baseline": "infogain"}, "baseline 'infogain' must be one of"),
        ({"thresholds": [-1.0]}, "thresholds"),
        ({"categories": {"small": {"limit": 10.0, "displacements": [[30.0, 0.0]]}}}, "beyond"),
        ({"categories": {"small": {"limit": 10.0, "displacements": [[1.0]]}}}, "parameters"),
        ({"categories": {"small": {"limit": 10.0, "shifts": [[1.0, 1.0]]}}}, "unknown: shifts"),
        ({"adapt": {"strategy": "active"}}, "set per experiment"),
        ({"methods": {"m": {"strategies": ["random"], "mode": "ideal"}}}, "set per experiment"),
        ({"methods": {"m": {"strategies": ["active"]}}}, "baseline 'random' must be one of"),
        ({"methods": {"m": {"strategies": ["random"], "posterior": "particles"}}},
         "unknown posterior 'particles'"),
        ({"methods": {"m": {"posterior": "kde"}}}, "methods.m needs strategies"),
        ({"judged": "nobody"}, "judged 'nobody' must name a method"),
        ({"categories": {"medium": {"displacements": [[3.0, 4.0]]}}}, "lower bound of 10"),
        ({"categories": {"small": {"limit": 12.0, "displacements": [[3.0, 4.0]]}}},
         "size category small"),
        ({"example": "huge"}, "example 'huge' must name a category"),
    ],
)
def test_bad_config_rejected(change, fragment):
    with pytest.raises(ConfigError, match=None) as exc:
        small_config(**change)
    assert fragment in str(exc.value)
    assert "\n" not in str(exc.value)


# -- the engine -----------------------------------------------------------------------------------
def _job(cfg, model_art):
    tasks = stage.plan(cfg)
    ctx = stage.context(cfg, model_art, FAKE)
    return Job(setup="kbcli.stages.evaluate:setup", run="kbcli.stages.evaluate:run_experiment",
               context=ctx, context_key=stage.context_key(ctx), tasks=tuple(tasks)), tasks


def _same(a: dict, b: dict) -> bool:
    keys = stage.STEP_KEYS + stage.PLAY_KEYS
    return a.keys() == b.keys() and all(
        np.array_equal(a[i][k], b[i][k], equal_nan=True) for i in a for k in keys
    )


def test_real_experiment_identical_across_backends(model_path, cluster):
    """The adapt stage's experiment itself (both modes: the pymunk arm too) gives bit-identical
    results serially, on 2 local processes (loky) and on a 2-worker Dask LocalCluster."""
    cfg = small_config(methods={"kbcli": {"strategies": ["random", "active", "infogain"]},
                                "paper": {"strategies": ["random"], "posterior": "kde",
                                          "estimator": "ml", "kde_samples": 500}},
                       judged="paper", modes=["ideal", "dynamics"], play_notes=20,
                       experiments=1, max_steps=4,
                       categories={"small": {"limit": 10.0, "displacements": [[3.0, -4.0]]},
                                   "large": {"limit": 40.0, "displacements": [[-20.0, 25.0]]}},
                       snapshot_steps=[1, 3])
    art = read_artifact(model_path)
    tasks = stage.plan(cfg)
    ctx = stage.context(cfg, art)
    job = Job(setup="kbcli.stages.evaluate:setup", run="kbcli.stages.evaluate:run_experiment",
              context=ctx, context_key=stage.context_key(ctx), tasks=tuple(tasks))
    serial = dict(execute(job, range(len(tasks))))
    assert len(serial) == 16
    assert _same(serial, dict(execute(job, range(len(tasks)), jobs=2)))
    assert _same(serial, dict(execute(job, range(len(tasks)), scheduler=cluster)))
    assert not _same(serial, {i: {**r, "errors": r["errors"] + 1} for i, r in serial.items()})
    ex = [serial[t.row]["extra"] for t in tasks if t.example]
    assert len(ex) == 8 and all(e["snapshots"].shape[0] == 2 for e in ex)
    for t in tasks:
        r = serial[t.row]
        assert 0 <= r["play_adapted"] <= 1
        assert np.isfinite(r["play_before"]) == t.play_reference
    assert all(np.isfinite(r["errors"]).all() and r["errors"].shape == (4,) for r in serial.values())


def test_unreachable_scheduler_fails_fast(model_path):
    job, tasks = _job(small_config(), read_artifact(model_path))
    t0 = time.monotonic()
    with pytest.raises(KbcliError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:9"):
        list(execute(job, range(len(tasks)), scheduler="tcp://127.0.0.1:9"))
    assert time.monotonic() - t0 < 30  # the connect timeout is 5 s; generous bound for a loaded box
    with pytest.raises(ConfigError, match="tcp://HOST:PORT"):
        execute(job, [0], scheduler="127.0.0.1")


def test_checkpoint_round_trip_and_mismatch(tmp_path):
    ck = Checkpoint(tmp_path / "o.h5.ckpt", {"a": 1, "b": [1, 2]}, every=2)
    assert ck.load(resume=True) == {}
    ck.add(3, {"x": np.arange(3.0), "extra": {"s": np.array(["hi"]), "z": np.int64(4)}})
    assert not ck.exists()  # nothing written before `every`
    ck.add(0, {"x": np.zeros(2)})
    ck.add(5, {"x": np.ones(1)})
    ck.flush()
    assert sorted(p.name for p in ck.folder.iterdir()) == ["meta.json", "part-000001.h5",
                                                          "part-000002.h5"]
    again = Checkpoint(tmp_path / "o.h5.ckpt", {"b": (1, 2), "a": 1})
    got = again.load(resume=True)
    assert sorted(got) == [0, 3, 5]
    np.testing.assert_array_equal(got[3]["x"], np.arange(3.0))
    assert got[3]["extra"]["s"].tolist() == ["hi"] and got[3]["extra"]["z"] == 4
    with pytest.raises(KbcliError, match="pass --resume"):
        again.load(resume=False)
    with pytest.raises(KbcliError, match=r"different config \(a differ\)"):
        Checkpoint(tmp_path / "o.h5.ckpt", {"a": 2, "b": [1, 2]}).load(resume=True)
    again.remove()
    assert not ck.folder.exists()


# -- the CLI --------------------------------------------------------------------------------------
def test_cli_serial_jobs_resume_identical(runner, tmp_path, model_path, fake, monkeypatch):
    """The artifact is byte-identical whatever the backend, and after an interrupted run resumed."""
    conf = write_config(tmp_path / "e.toml")
    base = ["evaluate", "--config", str(conf), "--model", str(model_path)]
    r = runner.invoke(app, base + ["-o", str(tmp_path / "serial.h5")])
    assert r.exit_code == 0, r.output
    assert "evaluation summary" in r.output
    r = runner.invoke(app, base + ["-o", str(tmp_path / "jobs.h5"), "--jobs", "2"])
    assert r.exit_code == 0, r.output
    digest = sha256_file(tmp_path / "serial.h5")
    assert sha256_file(tmp_path / "jobs.h5") == digest

    # interrupt after 7 experiments: the checkpoint keeps what was flushed (every 3)
    calls = {"n": 0}
    real = stage.run_experiment

    def interrupting(state, task):
        calls["n"] += 1
        if calls["n"] > 7:
            raise KeyboardInterrupt
        return real(state, task)

    monkeypatch.setattr(stage, "run_experiment", interrupting)
    out = tmp_path / "resumed.h5"
    r = runner.invoke(app, base + ["-o", str(out), "--checkpoint-every", "3"])
    assert r.exit_code == 130 and "--resume" in r.output
    assert not out.exists()
    ckpt = tmp_path / "resumed.h5.ckpt"
    assert len(list(ckpt.glob("part-*.h5"))) == 3  # 3 + 3 + the 1 flushed on interrupt
    r = runner.invoke(app, base + ["-o", str(out)])  # no --resume: refuse, keep the checkpoint
    _one_line_error(r, "pass --resume")
    monkeypatch.setattr(stage, "run_experiment", real)
    r = runner.invoke(app, base + ["-o", str(out), "--resume"])
    assert r.exit_code == 0, r.output
    assert "7 of 18 experiments already done" in r.output
    assert sha256_file(out) == digest
    assert not ckpt.exists()


def test_cli_refuses_checkpoint_of_other_config(runner, tmp_path, model_path, fake):
    out = tmp_path / "e.h5"
    ck = Checkpoint(Checkpoint.beside(out), {**stage.fingerprint(
        small_config(seed=99), read_artifact(model_path), FAKE), "source_code": source_digest()})
    ck.start()
    conf = write_config(tmp_path / "e.toml")
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(out), "--resume"])
    _one_line_error(r, "different config", "evaluate.seed")
    assert not out.exists() and ck.exists()


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--experiments", "0"], "evaluate.experiments must be a whole number in [1, 10000], got 0"),
        (["--mode", "dynamics"], "not in the config's modes"),
        (["--jobs", "0"], "--jobs must be >= 1"),
        (["--scheduler", "tcp://127.0.0.1:9"], "cannot reach the Dask scheduler"),
        (["--scheduler", "localhost"], "tcp://HOST:PORT"),
    ],
)
def test_cli_bad_input(runner, tmp_path, model_path, fake, monkeypatch, extra, fragment):
    import kbcli.io.runner

    monkeypatch.setattr(kbcli.io.runner, "CONNECT_TIMEOUT_S", 1.0)
    conf = write_config(tmp_path / "e.toml")
    out = tmp_path / "e.h5"
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(out), *extra])
    _one_line_error(r, fragment)
    assert not out.exists() and not Checkpoint.beside(out).exists()


def test_cli_defaults_to_the_embedded_model(runner, tmp_path, fake, monkeypatch):
    """Without --model, evaluate adapts with data/default-model.h5 (as the README says)."""
    from pathlib import Path

    conf = write_config(tmp_path / "e.toml", experiments=1)
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    out = tmp_path / "e.h5"
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "-o", str(out)])
    assert r.exit_code == 0, r.output
    art = read_artifact(out, "evaluation")
    assert art.inputs["model"]["file"] == "default-model.h5"
    assert art.inputs["model"]["sha256"] == sha256_file(Path("data/default-model.h5"))


def test_cli_bad_config_file(runner, tmp_path, model_path):
    conf = tmp_path / "bad.toml"
    conf.write_text("[evaluate]\nstrategies = ['random', 'psychic']\n")
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(tmp_path / "e.h5")])
    _one_line_error(r, "unknown strategy 'psychic'")
    conf.write_text("[evaluate]\nexperimentz = 3\n")
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(tmp_path / "e.h5")])
    _one_line_error(r, "unknown evaluate option 'experimentz'")
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(conf),
                            "-o", str(tmp_path / "e.h5")])
    assert r.exit_code == 1
    assert not (tmp_path / "e.h5").exists()


def test_artifact_layout(tmp_path, model_path, fake):
    cfg = small_config()
    art = stage.run(cfg, read_artifact(model_path), FAKE)
    n = len(stage.plan(cfg))
    assert art.kind == "evaluation" and art.seed == 7
    assert art.array("steps/errors").shape == (n, 6)
    assert art.array("steps/estimates").shape == (n, 6, 2)
    assert art.array("experiments/strategy").tolist().count("active") == n // 2
    assert set(art.array("experiments/method").tolist()) == {"m"}
    cur = art.data["curves"]["ideal"]["m"]["small"]["active"]
    assert cur["rmse"].shape == (6,) and cur["rmse_by_param"].shape == (2, 6)
    assert cur["samples_to_threshold"].shape == (2 * 3, 3)
    pv = art.data["pvalues"]["ideal"]["m"]["small"]["active"]
    p = pv["pvalue"]
    assert p.shape == (3,) and np.all((p >= 0) & (p <= 1))
    assert pv["min_pvalue"] == pytest.approx(2 / 924)  # 6 runs each: 2 / C(12, 6)
    assert "random" not in art.data["pvalues"]["ideal"]["m"]["small"]
    # before / unadapted measured once per (parametrization, repetition), shared by its rows
    exp = art.data["experiments"]
    assert np.isfinite(exp["play_before"]).all() and np.isfinite(exp["play_adapted"]).all()
    for k in ("play_before", "play_unadapted"):
        for i, j in ((0, 3), (1, 4)):  # random rep i and active rep i of the first displacement
            assert exp["param_index"][i] == exp["param_index"][j] and exp["rep"][i] == exp["rep"][j]
            assert exp[k][i] == exp[k][j]
    assert art.attrs["methods"]["m"]["options"]["ideal"]["active"]["robot"]["strategy"][
        "name"] == "active"
    ex = art.data["examples"]["ideal"]["m"]["active"]
    assert ex["snapshots"].shape == (3, 5, 5) and art.array("experiments/category")[ex["row"]] == "small"
    assert "step_ms" not in art.data["steps"]
    write_artifact(art, tmp_path / "a.h5")
    back = read_artifact(tmp_path / "a.h5", "evaluation")
    np.testing.assert_array_equal(back.array("curves/ideal/m/small/active/rmse"), cur["rmse"])
    np.testing.assert_array_equal(back.array("steps/errors"), art.array("steps/errors"))
    assert back.config == cfg.to_dict()


def test_a_top_level_arm_table_is_refused_not_ignored(runner, tmp_path, model_path):
    conf = write_config(tmp_path / "e.toml")
    conf.write_text(conf.read_text() + '\n[arm]\npreset = "servo"\n')
    out = tmp_path / "e.h5"
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(out)])
    _one_line_error(r, "remove it", "[evaluate.arm]")
    assert not out.exists() and not Checkpoint.beside(out).exists()


# -- options a method's parts do not read (issue 26) ----------------------------------------------
@pytest.mark.parametrize(
    ("method", "fragments"),
    [
        ({"posterior": "kde", "robust_eta": 0.5},
         ["methods.m: robust_eta does not apply", "posterior kde takes no option 'robust_eta'",
          "posterior likelihood does"]),
        ({"posterior": "kde", "robust": False}, ["methods.m: robust does not apply"]),
        ({"posterior": "kde", "robot": {"robust_blurs": [1.0]}},
         ["methods.m: robust_blurs does not apply"]),
        ({"robust": False, "redundancy_radius": 2.0},
         ["methods.m: redundancy_radius does not apply", "robust = false"]),
        ({"ml_ties": "random", "strategies": ["random", "infogain"]},
         ["methods.m: ml_ties does not apply", "the estimator is mean", "stop_ml is not set"]),
        ({"hypotheses": 64}, ["hypotheses does not apply", "no strategy of it takes it",
                              "strategy infogain does"]),
        ({"posterior": "kde", "kde_sampler": "raster"},
         ["kde_sampler does not apply", 'kde_draw = "fresh"']),
        ({"kde_floor": 0.0}, ["kde_floor does not apply", "posterior kde does"]),
    ],
)
def test_a_method_option_its_parts_do_not_read_is_refused(runner, tmp_path, model_path, method,
                                                          fragments):
    """An option no part of the method reads is refused in one line naming the method, the option
    and why, never silently recorded as in force (in Python and from a TOML file, exit 1)."""
    strategies = method.pop("strategies", ["random", "active"])
    table = {"m": {"strategies": strategies, **method}}
    with pytest.raises(ConfigError) as exc:
        small_config(methods=table)
    assert "\n" not in str(exc.value) and all(f in str(exc.value) for f in fragments)
    lines = ["[evaluate]", "judged = \"m\"", "modes = [\"ideal\"]", "[evaluate.methods.m]",
             f"strategies = {json.dumps(strategies)}"]
    robot = method.pop("robot", None)
    lines += [f"{k} = {json.dumps(v)}" for k, v in method.items()]
    if robot:
        lines += ["[evaluate.methods.m.robot]", *(f"{k} = {json.dumps(v)}" for k, v in robot.items())]
    conf = tmp_path / "e.toml"
    conf.write_text("\n".join(lines) + "\n")
    out = tmp_path / "e.h5"
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(out)])
    _one_line_error(r, *fragments)
    assert not out.exists()


def test_options_the_method_reads_are_accepted_and_recorded():
    cfg = small_config(methods={"m": {"strategies": ["random", "paper-active"], "posterior": "kde",
                                      "kde_draw": "fresh", "kde_sampler": "raster",
                                      "kde_floor": 0.0, "estimator": "ml", "ml_ties": "random",
                                      "random_actions": "model", "candidates": 32,
                                      "active_keep": 4, "stop_ml": 0.02, "stop_mass": 0.0}})
    r = stage.adapt_config(cfg, "m", "paper-active", "ideal").robot
    assert (r.posterior.kde_floor, r.kde_sampler, r.strategy.candidates,
            r.strategy.active_keep) == (0.0, "raster", 32, 4)
    # every resolved option of the chosen parts stays recorded; each strategy its own
    opts = stage.resolved_methods(cfg)["m"]["options"]["ideal"]
    assert opts["random"]["robot"]["strategy"] == {"name": "random", "random_actions": "model"}
    assert opts["paper-active"]["robot"]["strategy"]["candidates"] == 32
    assert opts["random"]["robot"]["posterior"]["kde_bandwidth"] is None
