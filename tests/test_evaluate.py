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
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.cli import app
from kbcli.core import stats
from kbcli.core.keyboard import Keyboard, KeyboardConfig
from kbcli.errors import ConfigError, KbcliError
from kbcli.io.artifact import read_artifact, sha256_file, write_artifact
from kbcli.io.runner import Checkpoint, Job, execute, source_digest
from kbcli.stages import evaluate as stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages.models import exact_artifact

FAKE = "test_evaluate:fake_experiment"


def fake_experiment(cfg, model, keyboard, true_params, *, rng, table=None, snapshot_steps=()):
    """A deterministic stand-in for ``kbcli.stages.adapt.experiment``: the error shrinks with the
    step, faster for non-random strategies, with seeded noise. Its wall time per step is real (and
    must stay out of the artifact)."""
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
    out["step_ms"] = np.full(steps, (time.perf_counter() - t0) * 1e3 / steps)
    return out


def small_config(**kw) -> stage.EvaluateConfig:
    d = {
        "seed": 7,
        "experiments": 3,
        "strategies": ["random", "active"],
        "modes": ["ideal"],
        "max_steps": 6,
        "thresholds": [10.0, 4.0, 1.0],
        "categories": {
            "small": {"limit": 10.0, "displacements": [[3.0, 4.0], [-6.0, 0.0]]},
            "large": {"limit": 40.0, "displacements": [[20.0, -25.0]]},
        },
    }
    d.update(kw)
    return stage.EvaluateConfig.from_dict(d)


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
    body.pop("adapt")
    noise = body.pop("reach_noise")
    arms = body.pop("arm")
    for k, v in body.items():
        lines.append(f"{k} = {json.dumps(v)}")
    lines += ["[evaluate.reach_noise]"] + [f"{m} = {v}" for m, v in noise.items()]
    lines += ["[evaluate.arm]"] + [f'{m} = "{a["preset"]}"' for m, a in arms.items()]
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


def test_ranksum_direction_and_ties():
    a = np.array([[1], [2], [2], [3]] * 5)
    b = a + 5
    stat, p = stats.ranksum_pvalues(a, b)
    assert stat[0] < 0 and p[0] < 1e-3
    stat, p = stats.ranksum_pvalues(a, a)
    assert stat[0] == 0 and p[0] == pytest.approx(1.0)
    _, p = stats.ranksum_pvalues(np.full((6, 1), 41), np.full((6, 1), 41))  # nobody got there
    assert p[0] == 1.0


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


def test_play_success_known_answers():
    kb = Keyboard(KeyboardConfig())
    true = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, -5.0]])
    np.testing.assert_allclose(stage.play_success(kb, "translation", true, true), 1.0)
    got = stage.play_success(kb, "translation", true, np.zeros_like(true), per_key=10)
    # aiming uniformly inside 50 px keys, a (dx, dy) shift keeps (1 - dx/50)(1 - dy/50) on target
    np.testing.assert_allclose(got, [1.0, 0.8, 0.8 * 0.9])


# -- config and plan ------------------------------------------------------------------------------
def test_paper_config_parses_and_plans():
    from kbcli.io.config import load_toml

    cfg = stage.EvaluateConfig.from_dict(load_toml("pipelines/paper.toml", "evaluate"))
    assert cfg.experiments == 50 and [c.name for c in cfg.categories] == ["small", "medium", "large"]
    assert [c.limit for c in cfg.categories] == [10.0, 20.0, 40.0]
    tasks = stage.plan(cfg.with_overrides(experiments=2))
    assert len(tasks) == 2 * 12 * len(cfg.strategies) * 2
    assert cfg == stage.EvaluateConfig.from_dict(cfg.to_dict())
    import pickle

    assert pickle.loads(pickle.dumps(cfg)) == cfg


def test_seeds_do_not_depend_on_selected_modes():
    both = stage.plan(small_config(modes=["ideal", "dynamics"]))
    ideal = stage.plan(small_config(modes=["ideal"]))
    dyn = stage.plan(small_config(modes=["dynamics"]))
    key = lambda t: (t.mode, t.category, t.param_index, t.strategy, t.rep)  # noqa: E731
    seeds = {key(t): t.seed.generate_state(4).tolist() for t in both}
    for t in ideal + dyn:
        assert t.seed.generate_state(4).tolist() == seeds[key(t)]
    assert len({str(s) for s in seeds.values()}) == len(both)  # all distinct
    assert sum(t.example for t in both) == 2 * 2  # one per mode and strategy


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ({"bogus": 1}, "unknown evaluate option(s) bogus"),
        ({"strategies": ["random", "psychic"]}, "unknown strategy 'psychic'"),
        ({"experiments": 0}, "experiments must be a whole number >= 1"),
        ({"modes": ["telepathy"]}, "unknown mode 'telepathy'"),
        ({"baseline": "infogain"}, "baseline 'infogain' must be one of"),
        ({"thresholds": [-1.0]}, "thresholds"),
        ({"categories": {"small": {"limit": 10.0, "displacements": [[30.0, 0.0]]}}}, "beyond"),
        ({"categories": {"small": {"limit": 10.0, "displacements": [[1.0]]}}}, "parameters"),
        ({"categories": {"small": {"limit": 10.0, "shifts": [[1.0, 1.0]]}}}, "unknown: shifts"),
        ({"adapt": {"strategy": "active"}}, "set per experiment"),
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
    return a.keys() == b.keys() and all(
        np.array_equal(a[i][k], b[i][k]) for i in a for k in stage.STEP_KEYS
    )


def test_backends_bit_identical(model_path, cluster):
    """serial == 2 loky processes == a 2-worker Dask LocalCluster, bit for bit."""
    cfg = small_config()
    job, tasks = _job(cfg, read_artifact(model_path))
    serial = dict(execute(job, range(len(tasks))))
    assert len(serial) == len(tasks) == 3 * 2 * 3
    local = dict(execute(job, range(len(tasks)), jobs=2))
    assert _same(serial, local)
    assert _same(serial, dict(execute(job, range(len(tasks)), scheduler=cluster)))
    assert not _same(serial, {i: {**r, "errors": r["errors"] + 1} for i, r in serial.items()})


def test_real_experiment_identical_across_backends(model_path, cluster):
    """The adapt stage's experiment itself (both modes: the pymunk arm too) gives bit-identical
    results serially, on 2 local processes and on a 2-worker Dask LocalCluster."""
    cfg = small_config(strategies=["random", "active", "infogain"], modes=["ideal", "dynamics"],
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
    assert len(serial) == 12
    assert _same(serial, dict(execute(job, range(len(tasks)), jobs=2)))
    assert _same(serial, dict(execute(job, range(len(tasks)), scheduler=cluster)))
    ex = [serial[t.row]["extra"] for t in tasks if t.example]
    assert len(ex) == 6 and all(e["snapshots"].shape[0] == 2 for e in ex)
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
def _one_line_error(result, *fragments):
    assert result.exit_code == 1, result.output
    lines = [ln for ln in result.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kbcli: error:"), result.output
    for f in fragments:
        assert f in lines[0], lines[0]


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
        (["--experiments", "0"], "experiments must be a whole number >= 1"),
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


def test_cli_bad_config_file(runner, tmp_path, model_path):
    conf = tmp_path / "bad.toml"
    conf.write_text("[evaluate]\nstrategies = ['random', 'psychic']\n")
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(tmp_path / "e.h5")])
    _one_line_error(r, "unknown strategy 'psychic'")
    conf.write_text("[evaluate]\nexperimentz = 3\n")
    r = runner.invoke(app, ["evaluate", "--config", str(conf), "--model", str(model_path),
                            "-o", str(tmp_path / "e.h5")])
    _one_line_error(r, "unknown evaluate option(s) experimentz")
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
    cur = art.data["curves"]["ideal"]["small"]["active"]
    assert cur["rmse"].shape == (6,) and cur["rmse_by_param"].shape == (2, 6)
    assert cur["samples_to_threshold"].shape == (2 * 3, 3)
    p = art.data["pvalues"]["ideal"]["small"]["active"]["pvalue"]
    assert p.shape == (3,) and np.all((p >= 0) & (p <= 1))
    assert "random" not in art.data["pvalues"]["ideal"]["small"]
    ex = art.data["examples"]["ideal"]["active"]
    assert ex["snapshots"].shape == (3, 5, 5) and art.array("experiments/category")[ex["row"]] == "small"
    assert "step_ms" not in art.data["steps"]
    write_artifact(art, tmp_path / "a.h5")
    back = read_artifact(tmp_path / "a.h5", "evaluation")
    np.testing.assert_array_equal(back.array("curves/ideal/small/active/rmse"), cur["rmse"])
    np.testing.assert_array_equal(back.array("steps/errors"), art.array("steps/errors"))
    assert back.config == cfg.to_dict()
