"""The instrument (paper Sect. III-A, Fig. 2): a virtual keyboard laid on a tactile pad.

Contract: a :class:`~kbcli.core.instrument.keyboard.Keyboard` built from a
:class:`~kbcli.core.instrument.keyboard.KeyboardConfig` answers where its keys are, what each
sounds like and which key lies under a point; a layout (:mod:`~kbcli.core.instrument.layouts`)
shapes and tunes the keys. Melodies, notes and scales, and audio complete it. Pure numpy and
shapely: no I/O.
"""
