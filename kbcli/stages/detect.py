"""Stage ``detect``: run a failure detector online over a play history (paper Sect. III-C, Eq. 4-6).

Feeds the history's MATCH (0) / NO_MATCH (1) results one at a time to a detector of
:mod:`kbcli.core.detection.detectors` (the paper's binomial test by default), as the robot would
while playing, and records its score at every step and where it fired (it resets after firing).
With the history's perturbation step it also reports the first firing after it, its delay (the
post-perturbation results seen when it fires: 1 on the first action after the move) and the false
alarms before it.
"""

from __future__ import annotations

import numpy as np

from kbcli.core.detection.detectors import DetectorConfig, detect_stream
from kbcli.errors import ArtifactError
from kbcli.stages.artifact import Artifact, ref


def run(cfg: DetectorConfig, history_art: Artifact) -> Artifact:
    """The detection artifact of a history artifact (ArtifactError for any other kind)."""
    if history_art.kind != "history":
        raise ArtifactError(f"expected a history artifact (kbcli play), got a {history_art.kind}")
    results = history_art.array("result").astype(np.int8)
    scores = np.ones(len(results))
    fired = np.zeros(len(results), dtype=bool)
    for i, (score, f) in enumerate(detect_stream(cfg, results)):
        scores[i] = score
        fired[i] = f
    firings = np.flatnonzero(fired)
    perturb_at = history_art.attrs.get("perturb_at")
    summary = summarize(firings, perturb_at)
    return Artifact(
        kind="detection",
        config={**cfg.to_dict(), "perturb_at": perturb_at},
        seed=None,
        data={"score": scores, "fired": fired, "firings": firings.astype(np.int64)},
        attrs={**summary, "steps": len(results)},
        inputs={"history": ref(history_art)},
    )


def summarize(firings: np.ndarray, perturb_at: int | None) -> dict:
    """``first_firing`` (step or None), ``n_firings`` and, when ``perturb_at`` is known,
    ``detected_at`` (first firing at or after it, or None), ``delay`` (``detected_at - perturb_at
    + 1``) and ``false_alarms`` (firings before it)."""
    firings = np.asarray(firings, dtype=np.int64)
    out: dict = {
        "first_firing": int(firings[0]) if len(firings) else None,
        "n_firings": len(firings),
        "perturb_at": perturb_at,
        "detected_at": None,
        "delay": None,
        "false_alarms": None,
    }
    if perturb_at is not None:
        after = firings[firings >= perturb_at]
        out["false_alarms"] = int((firings < perturb_at).sum())
        if len(after):
            out["detected_at"] = int(after[0])
            out["delay"] = int(after[0] - perturb_at + 1)
    return out
