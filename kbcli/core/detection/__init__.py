"""Failure detection (paper Sect. III-C, Eq. 4-6): has the failure rate of the played notes gone up?

Contract: a detector (:mod:`~kbcli.core.detection.detectors`, a registry: the paper's binomial
test, CUSUM, BOCPD) reads a 0/1 stream of MATCH / NO_MATCH results one value at a time and says
when it fires; the same code runs online (a robot's loop) and offline (a recorded history).
"""
