"""Figure of a play history (Algorithm 1) and, optionally, of the failure detector run over it
(Sect. III-C, Fig. 4): the note aimed for and each result, the running success rate, and the
detector's score against its threshold, with the perturbation step and the firings marked."""

from __future__ import annotations

import os

import matplotlib.pyplot as plt
import numpy as np

from kbcli.core.instrument.keyboard import midi_to_name
from kbcli.stages.artifact import Artifact
from kbcli.viz.common import save


def running_rate(x: np.ndarray, window: int) -> np.ndarray:
    """Mean of the last ``window`` values at each step (fewer at the start), (T,)."""
    x = np.asarray(x, float)
    c = np.concatenate([[0.0], np.cumsum(x)])
    i = np.arange(1, len(x) + 1)
    lo = np.maximum(i - window, 0)
    return (c[i] - c[lo]) / (i - lo)


def plot_play(history: Artifact, path: str | os.PathLike, detection: Artifact | None = None,
              window: int = 20) -> None:
    """Draw a history (and a detection over it) to a PNG."""
    result = history.array("result").astype(int)
    target = history.array("target")
    t = np.arange(len(result))
    perturb_at = history.attrs.get("perturb_at")
    firings = detection.array("firings") if detection is not None else np.zeros(0, int)
    n_panels = 3 if detection is not None else 2
    fig, axes = plt.subplots(n_panels, 1, figsize=(10, 2.4 * n_panels + 0.6), sharex=True)

    ax = axes[0]
    ax.step(t, target, where="post", color="0.6", lw=0.8, label="note aimed for")
    ok = result == 0
    ax.scatter(t[ok], target[ok], s=10, c="tab:green", label="MATCH")
    ax.scatter(t[~ok], target[~ok], s=18, c="tab:red", marker="x", label="NO_MATCH")
    ax.set_ylabel("note aimed for")
    midi = history.array("melody/midi")
    beats = history.array("melody/durations")
    every = max(1, int(np.ceil(len(midi) / 24)))  # at most 24 labels
    ticks = np.arange(0, len(midi), every)
    ax.set_yticks(ticks)
    ax.set_yticklabels([f"{i + 1}. {midi_to_name(int(midi[i]))} ({beats[i]:g})" for i in ticks],
                       fontsize=8 if len(ticks) <= 12 else 6.5)
    ax.set_ylim(-0.6, len(midi) - 0.4)
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=7, ncol=3, frameon=False)
    ax.set_title(f"melody {history.attrs.get('melody', '')} -- {len(result)} actions", loc="left",
                 fontsize=10)

    ax = axes[1]
    ax.plot(t, 1.0 - running_rate(result, window), color="tab:blue",
            label=f"success rate, last {window} actions")
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("success rate")
    ax.legend(loc="lower left", fontsize=7)

    if detection is not None:
        ax = axes[2]
        score = np.clip(detection.array("score"), 1e-300, 1.0)
        thr = detection.config["threshold"]
        ax.semilogy(t, score, color="tab:purple", lw=1, label=f"{detection.config['detector']['name']} score")
        ax.axhline(thr, color="tab:red", ls=":", lw=1, label=f"threshold {thr:g}")
        ax.set_ylim(max(score.min(), 1e-12) / 3, 2.0)
        ax.set_ylabel("score (fires below)")
        ax.legend(loc="lower left", fontsize=7)

    for ax in axes:
        if perturb_at is not None:
            ax.axvline(perturb_at, color="black", ls="--", lw=1)
        for f in firings:
            ax.axvline(f, color="tab:red", lw=1.2, alpha=0.8)
    axes[-1].set_xlabel("step (action)")
    notes = []
    if perturb_at is not None:
        notes.append(f"dashed: keyboard moved at step {perturb_at}")
    if detection is not None:
        notes.append("red: detector fired" + ("" if len(firings) else " (never)"))
    if notes:
        fig.text(0.01, 0.005, "; ".join(notes), fontsize=8)
    save(fig, path)
