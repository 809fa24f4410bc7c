"""Render what the robot heard as audio, so a person can hear it go wrong (paper Sect. III-A, Fig. 3).

Each played step becomes a tone at the perceived pitch (equal temperament, A4 = 440 Hz) lasting
the note's beats at the perceived tempo; a missed key is silence for the duration the robot meant
to play. The result is a float array in [-1, 1]; the CLI writes it as a WAV file.
"""

from __future__ import annotations

import numpy as np

SAMPLE_RATE = 22050


def midi_to_hz(midi: np.ndarray | float) -> np.ndarray:
    """Frequency in Hz of (possibly fractional) MIDI note numbers: ``440 * 2 ** ((m - 69) / 12)``."""
    return 440.0 * 2.0 ** ((np.asarray(midi, float) - 69.0) / 12.0)


def render(perceived: np.ndarray, beats: np.ndarray, fallback_tempo: np.ndarray, *,
           sample_rate: int = SAMPLE_RATE, amplitude: float = 0.3, fade: float = 0.01
          ) -> np.ndarray:
    """Synthesize one note per step.

    Parameters
    ----------
    perceived : (n, 2) ndarray
        Perceived (pitch in MIDI units, tempo in bpm) per step; a NaN row is silence.
    beats : (n,) ndarray
        Duration of each step's note in beats (the melody note the robot aimed for).
    fallback_tempo : (n,) ndarray
        Tempo (bpm) used for silent steps (the tempo of the note the robot aimed for).
    sample_rate : int
        Samples per second.
    amplitude : float
        Peak amplitude of a tone (a fundamental plus two soft harmonics).
    fade : float
        Linear fade in and out of each note, seconds (avoids clicks between notes).

    Returns
    -------
    (N,) float32 ndarray
        Samples in [-1, 1].
    """
    perceived = np.atleast_2d(np.asarray(perceived, float))
    beats = np.asarray(beats, float).reshape(-1)
    silent = np.isnan(perceived).any(axis=1)
    tempo = np.where(silent, np.asarray(fallback_tempo, float).reshape(-1), perceived[:, 1])
    tempo = np.where(np.isfinite(tempo) & (tempo > 0), tempo, 60.0)
    seconds = beats * 60.0 / tempo
    lengths = np.maximum(np.rint(seconds * sample_rate).astype(np.int64), 1)
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, np.float32)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    note = np.repeat(np.arange(len(lengths)), lengths)  # (N,) step of each sample
    t = (np.arange(total) - starts[note]) / sample_rate  # time within the note
    freq = midi_to_hz(np.where(silent, 69.0, perceived[:, 0]))[note]
    phase = 2.0 * np.pi * freq * t
    tone = np.sin(phase) + 0.3 * np.sin(2 * phase) + 0.1 * np.sin(3 * phase)
    dur = lengths[note] / sample_rate
    ramp = max(fade, 1.0 / sample_rate)
    env = np.minimum(1.0, np.minimum(t, dur - t) / ramp).clip(0.0, 1.0) * np.exp(-1.5 * t)
    wave = amplitude / 1.4 * tone * env
    wave[silent[note]] = 0.0
    return np.clip(wave, -1.0, 1.0).astype(np.float32)


def to_pcm16(samples: np.ndarray) -> bytes:
    """Float samples in [-1, 1] -> little-endian 16-bit PCM bytes (for the ``wave`` module)."""
    s = np.clip(np.asarray(samples, float), -1.0, 1.0)
    return (np.rint(s * 32767.0).astype("<i2")).tobytes()
