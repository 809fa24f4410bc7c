"""The peer benchmark (kbcli.bench.peer): the same task, seeds and scorer for both learners."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("skactiveml", reason="scikit-activeml is in the bench extra (make test installs it)")

from kbcli.bench import peer  # noqa: E402
from kbcli.bench.learn import bench_keyboard  # noqa: E402
from kbcli.errors import ConfigError  # noqa: E402


def test_heard_features_become_keys_and_silence():
    kb = bench_keyboard("grid")
    heard = np.vstack([kb.features[3], np.full(kb.features.shape[1], np.nan), kb.features[0]])
    assert peer._keys_heard(kb, heard).tolist() == [3, -1, 0]


def test_a_peer_learns_and_is_scored_like_kbcli():
    cfg = peer.PeerConfig(layouts=("grid",), peers=("knn-margin",), seeds=1, budgets=(40, 20),
                          pool=400, eval_step=4.0)
    kb = bench_keyboard("grid")
    s = np.random.SeedSequence(0)
    got = peer.peer_run(cfg, kb, "knn-margin", s)
    assert sorted(got) == [20, 40]
    for acc, berr in got.values():
        assert 0.0 <= acc <= 1.0 and berr >= 0.0
    assert peer.peer_run(cfg, kb, "knn-margin", s) == got          # same seed, same numbers
    # a perfect predictor scores 1 and 0 px with the same scorer
    assert peer._scores(lambda p: kb.key_at(p), kb, 4.0) == (1.0, 0.0)


def test_verdicts_compare_with_the_best_peer_on_each_score():
    rows = [{"layout": "grid", "learner": "kbcli", "budget": 150, "accuracy": 0.9, "boundary_error": 2.0},
            {"layout": "grid", "learner": "a", "budget": 150, "accuracy": 0.95, "boundary_error": 3.0},
            {"layout": "grid", "learner": "b", "budget": 150, "accuracy": 0.8, "boundary_error": 1.5}]
    (v,) = peer.verdicts(rows)
    assert (v["peer_accuracy_by"], v["peer_boundary_by"]) == ("a", "b")
    assert v["kbcli_wins"] is False
    rows[0].update(accuracy=0.96, boundary_error=1.5)
    assert peer.verdicts(rows)[0]["kbcli_wins"] is True


def test_bad_settings_are_refused():
    with pytest.raises(ConfigError, match="unknown peer 'svm'; valid: forest-entropy"):
        peer._check(peer.PeerConfig(peers=("svm",)))
    with pytest.raises(ConfigError, match="at least init"):
        peer._check(peer.PeerConfig(budgets=(5,)))
    with pytest.raises(ConfigError):
        peer.PeerConfig(seeds=0)


def test_tables_hold_plain_rows_and_a_verdict_per_cell():
    cfg = peer.PeerConfig(layouts=("grid",), peers=("knn-margin",), seeds=1, budgets=(150,))
    rows = [{"layout": "grid", "learner": "kbcli", "budget": 150, "runs": 1, "accuracy": 0.9,
             "boundary_error": 2.0, "classes": "forest x1"},
            {"layout": "grid", "learner": "knn-margin", "budget": 150, "runs": 1,
             "accuracy": 0.95, "boundary_error": 1.0}]
    learners, verdict = peer.tables(cfg, rows)
    assert [r["learner"] for r in learners["rows"]] == ["kbcli", "knn-margin"]
    assert learners["rows"][0]["accuracy %"] == 90.0
    assert learners["rows"][0]["kbcli classes"] == "forest x1"
    (v,) = verdict["rows"]
    assert v["verdict"] == "peer better" and set(verdict["columns"]) == set(v)


def test_bench_learn_peer_cli_writes_the_result_file(runner, tmp_path):
    import json

    from kbcli.cli import app

    path = tmp_path / "learn-peer.json"
    r = runner.invoke(app, ["bench", "--json", str(path), "learn", "--peer", "--seeds", "1",
                            "--budgets", "20", "--layout", "grid", "--eval-step", "5"])
    assert r.exit_code == 0, r.output
    assert "verdict per layout and budget" in r.output
    d = json.loads(path.read_text())
    assert {"command", "date", "machine", "kbcli_version", "tables"} <= set(d)
    assert [len(t["rows"]) for t in d["tables"]] == [1 + len(peer.PEERS), 1]


def test_runs_in_worker_processes_give_the_same_numbers_in_the_same_order(runner):
    cfg = peer.PeerConfig(layouts=("grid",), peers=("knn-margin",), seeds=2, budgets=(20,),
                          pool=300, eval_step=8.0)
    serial = list(peer.runs(cfg))
    assert [(lay, who, i) for lay, who, i, _ in serial] == [
        ("grid", "kbcli", 0), ("grid", "knn-margin", 0), ("grid", "kbcli", 1),
        ("grid", "knn-margin", 1)]
    assert list(peer.runs(cfg, jobs=2)) == serial
    from kbcli.cli import app

    r = runner.invoke(app, ["bench", "learn", "--jobs", "2", "--seeds", "1"])
    assert r.exit_code == 1 and "--jobs applies to --peer runs only" in r.output
