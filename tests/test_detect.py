"""Failure detectors (Sect. III-C, Eq. 4-6), ``kbcli detect`` and the detector benchmark's parts."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import typer
from hypothesis import given, settings
from hypothesis import strategies as st

from kbcli.bench import detect as bench
from kbcli.cli import app
from kbcli.core.detection import detectors as det
from kbcli.core.detection.detectors import DETECTORS, Detector, DetectorConfig, run_batch
from kbcli.errors import ArtifactError, ConfigError
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.stages import detect as stage
from kbcli.stages.artifact import Artifact

SMALL = {"n_lt": 20, "n_st": 5}  # short windows keep the tests quick


def cfg(name: str = "binomial", **kw) -> DetectorConfig:
    return DetectorConfig(detector=name, **{**SMALL, **kw})


def fake_history(result, perturb_at=None) -> Artifact:
    result = np.asarray(result, dtype=np.uint8)
    n = len(result)
    xy = np.zeros((n, 2))
    ints = np.zeros(n, np.int64)
    data = {"result": result, "target": ints, "action": xy, "landed": xy, "perceived": xy,
            "cls": ints, "heard": ints, "perturbed": np.zeros(n, bool),
            "melody": {"midi": np.array([69]), "durations": np.array([1.0]),
                       "keys": np.array([0])}}  # every dataset a history holds (kbcli.io.schema)
    return Artifact(kind="history", config={"steps": n, "keyboard": {}}, seed=0, data=data,
                    attrs={"perturb_at": perturb_at, "steps": n})


# -- config and registry ----------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kw", "word"),
    [
        ({"n_st": 100, "n_lt": 100}, "n_st must be smaller"),
        ({"n_st": 120, "n_lt": 100}, "n_st must be smaller"),
        ({"n_st": 0}, "n_st must be a whole number in [1, 1000]"),
        ({"n_lt": 0}, "n_lt must be"),
        ({"threshold": 0.0}, "threshold must be a number in (0, 1)"),
        ({"threshold": 1.0}, "threshold must be a number in (0, 1)"),
        ({"threshold": float("nan")}, "threshold"),
        ({"detector": "page"}, "valid: binomial, cusum, bocpd"),
        ({"prior": (0.0, 1.0)}, "prior"),
        ({"detector": "cusum", "shift": 1.5}, "detector.detector.shift must be a number in (0, 1)"),
        ({"detector": "bocpd", "hazard": 0.0}, "detector.detector.hazard must be a number in (0, 1)"),
        # an option of another detector is refused by the chosen one, naming it and its own
        ({"detector": "cusum", "hazard": 0.1},
         "detector cusum takes no option 'hazard' (detector bocpd does); its options: shift"),
        ({"shift": 0.2}, "detector binomial takes no option 'shift' (detector cusum does)"),
        ({"detector": {"name": "bocpd", "shift": 0.2}}, "detector bocpd takes no option 'shift'"),
    ],
)
def test_bad_config_rejected(kw, word):
    with pytest.raises(ConfigError, match=re.escape(word)):
        DetectorConfig(**kw)


def test_registry_has_the_three_detectors_and_round_trips():
    assert set(DETECTORS) == {"binomial", "cusum", "bocpd"}
    c = DetectorConfig(detector="cusum", n_lt=50, n_st=7, threshold=0.02, prior=(0.5, 2.0))
    assert DetectorConfig.from_dict(c.to_dict()) == c
    with pytest.raises(ConfigError, match="unknown detector option"):
        DetectorConfig.from_dict({"windows": 3})


# -- the paper's binomial detector: known answers -------------------------------------------
def test_binomial_tail_known_answer():
    table = det.binomial_tail_table(100, 10, (1.0, 1.0))
    p = 1 / 102  # no failure in the long-term window: Laplace's rule
    assert table[0, 0] == 1.0
    assert math.isclose(table[0, 1], 1 - (1 - p) ** 10)
    assert math.isclose(table[0, 2], 1 - (1 - p) ** 10 - 10 * p * (1 - p) ** 9)
    p3 = 4 / 102
    assert math.isclose(table[3, 10], p3**10)
    assert np.all(np.diff(table, axis=1) <= 0)  # more recent failures: smaller tail
    assert np.all(np.diff(table, axis=0) >= 0)  # higher p_fail: larger tail


def test_binomial_fires_on_the_second_failure_after_a_perfect_history():
    d = Detector(DetectorConfig())  # the paper's defaults: N_LT 100, N_ST 10, threshold 0.01
    fired = [d.update(x) for x in [0] * 110 + [1, 1]]
    assert fired.index(True) == 111  # one failure: tail 0.094 > 0.01; two: 0.0042 < 0.01


def test_the_detector_defaults_have_one_source():
    """``kbcli detect`` and ``kbcli run`` default to the config's own defaults, which are those the
    golden closed loop (``make data``: ``kbcli run`` with no detector option) was recorded with: a
    changed default is a changed product, to be rebuilt (``make data``) on purpose."""
    cfg = DetectorConfig()
    golden = Path(__file__).resolve().parent.parent / "data" / "golden" / "closed_loop.h5"
    assert read_artifact(golden).config["loop"]["detector"] == cfg.to_dict()
    root = typer.main.get_command(app)
    for name in ("detect", "run"):
        params = {p.name: p.default for p in root.commands[name].params}
        for field in ("n_lt", "n_st", "threshold"):
            if field in params:
                assert params[field] == getattr(cfg, field), (name, field)
        assert params["detector"] == cfg.detector.name
    # a detector's own options: given only when set (the chosen detector refuses another's)
    params = {p.name: p for p in root.commands["detect"].params}
    assert params["shift"].default is None and params["hazard"].default is None
    assert params["shift"].show_default == str(DetectorConfig(detector="cusum").detector.shift)
    assert params["hazard"].show_default == str(DetectorConfig(detector="bocpd").detector.hazard)


def test_binomial_counts_windows_like_eq_4_and_5():
    c = DetectorConfig(n_lt=6, n_st=3, threshold=1e-9)
    bank = det.make_bank(c, 1)
    stream = [1, 0, 0, 1, 1, 0, 1, 0, 1, 1, 0, 0, 1]
    for i, x in enumerate(stream):
        bank.step(np.array([x]))
        hist = stream[: i + 1]
        assert bank.n_f[0] == sum(hist[-3:])  # Eq. 5: the last N_ST results
        assert bank.k_lt[0] == sum(hist[-9:-3])  # Eq. 4: the N_LT results before them
        assert bank.k_old[0] == sum(hist[:-3])


@pytest.mark.parametrize("name", list(DETECTORS))
def test_silent_during_warmup(name):
    c = cfg(name, threshold=0.5)
    scores, fired = run_batch(c, np.ones((2, c.warmup - 1), np.int8))
    assert not fired.any() and np.all(scores == 1.0)


@pytest.mark.parametrize("name", list(DETECTORS))
def test_never_fires_without_failures_and_fires_on_a_burst(name):
    c = cfg(name)
    zeros = np.zeros((1, 300), np.int8)
    assert not run_batch(c, zeros)[1].any()
    burst = zeros.copy()
    burst[0, 200:] = 1
    fired = run_batch(c, burst)[1][0]
    first = int(np.argmax(fired))
    assert fired.any() and 200 <= first < 210


@pytest.mark.parametrize("name", list(DETECTORS))
def test_fewer_failures_never_fire(name):
    """Upper tail / one-sided: a drop of the failure rate is not a failure event."""
    c = cfg(name, threshold=0.05)
    x = np.zeros((1, 400), np.int8)
    x[0, :200:2] = 1  # a failure rate of 0.5, then none
    fired = run_batch(c, x)[1][0]
    assert not fired[200:].any()


@pytest.mark.parametrize("name", list(DETECTORS))
def test_online_form_equals_batch_form(name):
    rng = np.random.default_rng(3)
    x = (rng.random((3, 260)) < np.r_[0.03, 0.1, 0.3][:, None]).astype(np.int8)
    x[:, 150:] |= (rng.random((3, 110)) < 0.5).astype(np.int8)
    c = cfg(name, threshold=0.02)
    scores, fired = run_batch(c, x)
    for s in range(3):
        online = list(det.detect_stream(c, x[s].tolist()))
        np.testing.assert_allclose([o[0] for o in online], scores[s], rtol=1e-10)
        assert [o[1] for o in online] == fired[s].tolist()
        # one stream alone gives the same as within the batch (no cross-talk between streams)
        alone = run_batch(c, x[s : s + 1])
        np.testing.assert_allclose(alone[0][0], scores[s], rtol=1e-10)


@settings(max_examples=25, deadline=None)
@given(bits=st.lists(st.integers(0, 1), min_size=1, max_size=120),
       name=st.sampled_from(sorted(DETECTORS)))
def test_scores_are_probabilities_and_firing_resets(bits, name):
    c = cfg(name, threshold=0.2)
    d = Detector(c)
    since_reset = 0
    for x in bits:
        fired = d.update(x)
        since_reset += 1
        assert 0.0 <= d.score <= 1.0
        if fired:
            assert since_reset >= c.warmup  # never fires during a warm-up
            since_reset = 0


def test_reset_and_first_crossing():
    d = Detector(cfg())
    for x in [0] * 30:
        d.update(x)
    d.reset()
    assert not any(d.update(1) for _ in range(cfg().warmup - 1))
    scores = np.array([[1.0, 0.5, 0.01, 0.001], [1.0, 1.0, 1.0, 1.0]])
    np.testing.assert_array_equal(det.first_crossing(scores, 0.02), [2, -1])


# -- the detect stage and CLI -----------------------------------------------------------------
def test_summary_delay_convention():
    s = stage.summarize(np.array([40, 105, 300]), perturb_at=100)
    assert s["first_firing"] == 40 and s["false_alarms"] == 1
    assert s["detected_at"] == 105 and s["delay"] == 6  # fired on the 6th post-move result
    assert stage.summarize(np.array([100]), 100)["delay"] == 1
    none = stage.summarize(np.zeros(0, int), None)
    assert none["first_firing"] is None and none["delay"] is None


def test_stage_on_a_history_and_round_trip(tmp_path):
    result = np.r_[np.zeros(150), np.ones(20), np.zeros(30)]
    art = stage.run(DetectorConfig(), fake_history(result, perturb_at=150))
    assert art.kind == "detection"
    assert art.attrs["detected_at"] == 151 and art.attrs["delay"] == 2
    path = tmp_path / "d.h5"
    write_artifact(art, path)
    back = read_artifact(path, "detection")
    np.testing.assert_array_equal(back.array("firings"), art.array("firings"))
    assert back.config["detector"] == {"name": "binomial"} and back.config["n_lt"] == 100
    with pytest.raises(ArtifactError, match="expected a history"):
        stage.run(DetectorConfig(), Artifact(kind="scene", config={}))


@pytest.fixture
def history_path(tmp_path):
    path = tmp_path / "history.h5"
    write_artifact(fake_history(np.r_[np.zeros(150), np.ones(10), np.zeros(40)], 150), path)
    return path


@pytest.mark.parametrize("name", list(DETECTORS))
def test_cli_detect(runner, history_path, tmp_path, name):
    out = tmp_path / f"{name}.h5"
    r = runner.invoke(app, ["detect", str(history_path), "--detector", name, "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "delay" in r.output and out.exists()
    assert read_artifact(out, "detection").attrs["delay"] is not None


@pytest.mark.parametrize(
    ("args", "word"),
    [
        (["--n-st", "100"], "n_st must be smaller"),
        (["--n-st", "0"], "n_st must be"),
        (["--threshold", "1"], "threshold must be a number in (0, 1)"),
        (["--threshold", "0"], "threshold must be a number in (0, 1)"),
        (["--detector", "adwin"], "unknown detector 'adwin'"),
        (["--detector", "cusum", "--hazard", "0.1"], "detect: --hazard does not apply to detector "
         "cusum: detector cusum takes no option 'hazard' (detector bocpd does)"),
        (["--shift", "0.2"], "--shift does not apply to detector binomial"),
        (["--detector", "bocpd", "--hazard", "1"], "hazard must be a number in (0, 1)"),
    ],
)
def test_cli_detect_bad_input(runner, history_path, tmp_path, args, word):
    out = tmp_path / "bad.h5"
    r = runner.invoke(app, ["detect", str(history_path), *args, "-o", str(out)])
    assert r.exit_code == 1
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kbcli: error:") and word in lines[0]
    assert not out.exists()


def test_cli_detect_own_options_reach_the_detector(runner, history_path, tmp_path):
    out = tmp_path / "c.h5"
    r = runner.invoke(app, ["detect", str(history_path), "--detector", "cusum", "--shift", "0.3",
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    art = read_artifact(out, "detection")
    assert art.config["detector"] == {"name": "cusum", "shift": 0.3}
    flat = DetectorConfig(detector="cusum", shift=0.3)
    assert DetectorConfig.from_dict({k: v for k, v in art.config.items() if k != "perturb_at"}) \
        == flat
    np.testing.assert_array_equal(art.array("score"),
                                  [s for s, _ in det.detect_stream(flat, art_results(history_path))])


def art_results(path):
    return read_artifact(path, "history").array("result").astype(np.int8)


def test_a_flat_stored_detector_config_reads_nested():
    """Detection 1 and closed loop 4 recorded every detector's options flat: read now, the chosen
    detector holds its own, the others' are dropped (kbcli.io.schema.migrate)."""
    data = Path(__file__).resolve().parent.parent / "data"
    old = read_artifact(data / "schema" / "v1" / "detection.h5", "detection")
    assert old.schema_version == 1
    assert old.config["detector"] == {"name": "binomial"} and "hazard" not in old.config
    assert old.config["perturb_at"] == 60
    loop = read_artifact(data / "schema" / "flat" / "closed_loop.h5", "closed_loop")
    assert loop.config["loop"]["detector"] == DetectorConfig().to_dict()
    from kbcli.io.schema.migrate import nest_detector

    flat = {"detector": "bocpd", "shift": 0.15, "hazard": 0.01, "n_lt": 50, "n_st": 5}
    assert DetectorConfig.from_dict(nest_detector(flat)) == DetectorConfig(
        detector="bocpd", hazard=0.01, n_lt=50, n_st=5)


def test_cli_detect_wrong_kind(runner, kb_path, tmp_path):
    out = tmp_path / "bad.h5"
    r = runner.invoke(app, ["detect", str(kb_path), "-o", str(out)])
    assert r.exit_code == 1 and "expected history" in r.output and not out.exists()


# -- benchmark building blocks (tiny sizes: the benchmark itself is not a test) ----------------
def test_bench_streams_and_tuning_meet_the_target():
    rng = np.random.default_rng(0)
    x = bench.make_streams(0.0, np.array([1.0, 1.0]), np.array([3, 5]), 8, rng=rng)
    np.testing.assert_array_equal(x, [[0, 0, 0, 1, 1, 1, 1, 1], [0, 0, 0, 0, 0, 1, 1, 1]])
    bc = bench.BenchConfig(tune_actions=20_000, change_min=100, change_max=300)
    tx, lengths = bench.tuning_streams(bc, rng=rng)
    assert tx.shape == (len(lengths), 300) and lengths.min() >= 100
    for name in DETECTORS:
        thr, r = bench.tune_ours(cfg(name), tx, lengths, target=20.0)
        assert 0 < thr < 1 and r <= 20.0


def test_bench_river_detectors_find_a_jump():
    pytest.importorskip("river", reason="river is in the bench extra (make test installs it)")
    rng = np.random.default_rng(1)
    x = bench.make_streams(0.01, np.full(4, 0.9), np.full(4, 150), 260, rng=rng)
    change = np.full(4, 150)
    for name in bench.RIVER:
        alarms = bench.river_run(name, {"ddm": 3.0, "fhddm": -6.0, "adwin": -3.0}[name], x,
                                 stop_after=change)
        row = bench._summary("g", name, "", 0.0, alarms, change, horizon=100)
        assert row.missed == 0 and row.median < 40  # a jump to 0.9 is found by everyone


def test_bench_post_change_rates():
    rates = bench.post_rates("large", 5, rng=np.random.default_rng(1))
    assert np.all((rates > 0.3) & (rates <= 1.0))


def test_bench_config_rejects_bad_values():
    with pytest.raises(ConfigError, match="p_pre"):
        bench.BenchConfig(p_pre=0.0)
    with pytest.raises(ConfigError, match="unknown detector"):
        bench.BenchConfig(detectors=("kswin",))
    with pytest.raises(ConfigError, match="n_st must be smaller"):
        bench.BenchConfig(n_lt=10, n_st=10)


def test_a_toy_detector_owns_its_option():
    """A detector with an option of its own is one class and one registration: the option given
    flat reaches it, another detector's is refused by it, and it runs online."""
    from kbcli.core.detection.detectors.base import Bank
    from kbcli.core.options import Options

    class ToyOptions(Options):
        level: float = 0.5

    class ToyBank(Bank):
        def _score(self, x):
            return np.where(self.n_f > 0, self.cfg.detector.level, 1.0)

    with DETECTORS.temporarily("toy", ToyBank, traits={"options": ToyOptions}):
        cfg = DetectorConfig(detector="toy", level=0.25, n_lt=5, n_st=2, threshold=0.3)
        assert cfg.detector == ToyOptions(name="toy", level=0.25)
        assert DetectorConfig.from_dict(cfg.to_dict()) == cfg
        with pytest.raises(ConfigError, match="detector toy takes no option 'shift' "
                                              r"\(detector cusum does\); its options: level"):
            DetectorConfig(detector="toy", shift=0.2)
        with pytest.raises(ConfigError, match="detector cusum takes no option 'level'"):
            DetectorConfig(detector="cusum", level=0.2)
        for level, fires in ((0.25, True), (0.5, False)):  # its own option decides
            d = Detector(cfg.replace(detector={"name": "toy", "level": level}))
            assert [d.update(x) for x in [0] * 7 + [1]] == [False] * 7 + [fires]
