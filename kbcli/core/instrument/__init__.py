"""The instrument (paper Sect. III-A, Fig. 2): a virtual keyboard laid on a tactile pad.

Contract: a :class:`~kbcli.core.instrument.keyboard.Keyboard` built from a
:class:`~kbcli.core.instrument.keyboard.KeyboardConfig` answers where its keys are (shapes in pad
pixels, :mod:`~kbcli.core.instrument.geometry`), what each sounds like (pitch and tempo features)
and which key lies under a point; a layout (:mod:`~kbcli.core.instrument.layouts`, a registry)
shapes and tunes the keys. Melodies (:mod:`~kbcli.core.instrument.melody`), notes and scales
(:mod:`~kbcli.core.instrument.notes`) and what the robot heard as audio
(:mod:`~kbcli.core.instrument.audio`) complete it. Pure numpy and shapely: no I/O.
"""
