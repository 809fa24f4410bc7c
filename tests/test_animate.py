"""``kbcli animate`` and what it needs recorded: joint angles per touch, the closed loop's posteriors."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib import animation
from PIL import Image

from kbcli.cli import app
from kbcli.core.instrument.keyboard import KeyboardConfig
from kbcli.io.artifact import read_artifact, write_artifact
from kbcli.sim import SimConfig, forward_kinematics
from kbcli.stages import adapt as adapt_stage
from kbcli.stages import keyboard as keyboard_stage
from kbcli.stages import perturb
from kbcli.stages.models import exact_artifact
from kbcli.stages.run import LoopConfig, LoopSession
from kbcli.viz.replay import frame_plan, load_replay

KB_ART = keyboard_stage.run(KeyboardConfig())
MODEL_ART = exact_artifact(KB_ART)
SCENE = perturb.run(perturb.PerturbConfig(params=(9.0, -6.0)), KB_ART,
                    rng=np.random.default_rng(0))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("anim")
    cfg = adapt_stage.AdaptConfig(mode="dynamics", max_steps=6, resolution=1.0,
                                  prior_halfwidth=20.0)
    run = adapt_stage.run(cfg, MODEL_ART, SCENE, rng=np.random.default_rng(0), seed=0,
                          snapshot_steps=(0, 1, 2, 4))
    write_artifact(run, d / "run.h5")
    loop = LoopSession(LoopConfig(steps=160, perturb_at=120,
                                  adapt=adapt_stage.AdaptConfig(stop=True, resolution=1.0,
                                                                prior_halfwidth=20.0)),
                       MODEL_ART, SCENE, rng=np.random.default_rng(2), seed=2)
    list(loop)
    write_artifact(loop.artifact(), d / "loop.h5")
    write_artifact(KB_ART, d / "kb.h5")
    return d


def test_dynamics_run_records_the_arm_pose_of_each_touch(files):
    art = read_artifact(files / "run.h5", "run")
    assert art.schema_version >= 2  # 3: the adapt config nests the robot's options
    q = art.data["joint_angles"]
    assert q.shape == (6, 2)
    # the recorded pose puts the fingertip where the finger landed
    tip = forward_kinematics(SimConfig(), q)
    np.testing.assert_allclose(tip, art.data["landed"], atol=0.01)  # joint slack: ~0.002 px
    assert art.attrs["arm"] == {"base": [400.0, 0.0], "link_lengths": [320.0, 280.0]}


def test_closed_loop_records_posteriors_and_estimates(files):
    art = read_artifact(files / "loop.h5", "closed_loop")
    st, post = art.data["steps"], art.data["posterior"]
    adapt_touches = np.flatnonzero(st["phase"] == 1)
    assert len(adapt_touches) >= 1
    np.testing.assert_array_equal(post["touch"], adapt_touches)
    assert post["log_translation"].shape == (len(adapt_touches), 41, 41)
    assert np.isnan(st["estimate"][st["phase"] == 0]).all()
    assert np.isfinite(st["estimate"][adapt_touches]).all()
    # the last adaptation touch's estimate is the correction the robot plays on with
    np.testing.assert_allclose(st["estimate"][adapt_touches[-1]],
                               st["correction"][adapt_touches[-1]])
    assert "joint_angles" not in st  # ideal mode: no arm simulated


def test_frame_plans(files):
    run = load_replay(read_artifact(files / "run.h5"))
    assert frame_plan(run, 100) == list(range(7))  # the prior, then every touch
    assert frame_plan(run, 4) == [0, 2, 4, 6]
    loop = load_replay(read_artifact(files / "loop.h5"))
    plan = frame_plan(loop, 40)
    adapt = set((np.flatnonzero(loop.data["phase"] == 1) + 1).tolist())
    assert adapt <= set(plan) and plan == sorted(set(plan))
    assert plan[0] == 1 and plan[-1] == loop.n and len(plan) <= 40
    moved = loop.attrs["perturbed_at"]
    assert {moved, moved + 1, loop.attrs["detected_at"] + 1} <= set(plan)


def test_animate_an_adaptation(files, runner):
    out = files / "run.gif"
    r = runner.invoke(app, ["animate", str(files / "run.h5"), "-o", str(out), "--fps", "4"])
    assert r.exit_code == 0, r.output
    assert "7 frames" in r.output
    im = Image.open(out)
    assert im.n_frames == 7 and im.size == (800, 496)  # 10 x 6.2 in at 80 dpi
    durations, frames = [], []
    for i in range(im.n_frames):
        im.seek(i)
        durations.append(im.info["duration"])
        frames.append(np.asarray(im.convert("RGB")))
    assert durations[:-1] == [250] * 6 and durations[-1] > 250  # the last frame is held
    assert all((a != b).any() for a, b in zip(frames, frames[1:], strict=False))


def test_animate_a_closed_loop(files, runner):
    out = files / "loop.gif"
    r = runner.invoke(app, ["animate", str(files / "loop.h5"), "-o", str(out),
                            "--max-frames", "30"])
    assert r.exit_code == 0, r.output
    art = read_artifact(files / "loop.h5")
    n = len(frame_plan(load_replay(art), 30))
    assert Image.open(out).n_frames == n


def test_animate_reads_schema_1(files, tmp_path, runner):
    """Artifacts written before joint angles and posteriors were recorded still animate."""
    art = read_artifact(files / "loop.h5")
    art.schema_version = 1
    del art.data["posterior"]
    del art.data["steps"]["estimate"]
    for k in ("arm", "mode"):
        art.attrs.pop(k)
    write_artifact(art, tmp_path / "old.h5")
    r = runner.invoke(app, ["animate", str(tmp_path / "old.h5"), "-o", str(tmp_path / "o.gif"),
                            "--max-frames", "10"])
    assert r.exit_code == 0, r.output
    assert Image.open(tmp_path / "o.gif").n_frames >= 10


def test_animate_bad_input(files, tmp_path, runner):
    def one_line(r, fragment):
        assert r.exit_code == 1, r.output
        lines = [ln for ln in r.output.strip().splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("kbcli: error:") and fragment in lines[0]

    run = str(files / "run.h5")
    one_line(runner.invoke(app, ["animate", str(files / "kb.h5"), "-o",
                                 str(tmp_path / "a.gif")]), "expected run or closed_loop")
    one_line(runner.invoke(app, ["animate", run, "-o", str(tmp_path / "a.png")]),
             "animate writes .gif or .mp4")
    one_line(runner.invoke(app, ["animate", run, "-o", str(tmp_path / "no" / "a.gif")]),
             "does not exist")
    if not animation.writers.is_available("ffmpeg"):
        one_line(runner.invoke(app, ["animate", run, "-o", str(tmp_path / "a.mp4")]),
                 "needs ffmpeg")
    else:  # where ffmpeg is installed, an MP4 is written
        r = runner.invoke(app, ["animate", run, "-o", str(tmp_path / "a.mp4")])
        assert r.exit_code == 0 and (tmp_path / "a.mp4").stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == (
        ["a.mp4"] if animation.writers.is_available("ffmpeg") else [])


def test_bench_animate_prints_a_table(files, runner):
    write_artifact(MODEL_ART, files / "model.h5")
    r = runner.invoke(app, ["bench", "animate", "--model", str(files / "model.h5"), "--repeats",
                            "1", "--touches", "3", "--no-loop"])
    assert r.exit_code == 0, r.output
    row = next(ln for ln in r.output.splitlines() if "adaptation, 3 touches" in ln)
    cells = [c.strip() for c in row.strip("│ ").split("│")]
    assert cells[1] == "4" and float(cells[2]) > 0  # the prior and 3 touches; CPU seconds
