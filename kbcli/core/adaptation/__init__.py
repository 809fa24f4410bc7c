"""Adaptation of the action space (paper Sect. III-B, III-D, III-E): where did the keyboard go?

Contract: an :class:`~kbcli.core.adaptation.adapter.Adapter`, made from a model and an
:class:`~kbcli.core.adaptation.config.AdapterConfig`, keeps a posterior over the transform
(:mod:`~kbcli.core.instrument.transforms`) on a hypothesis grid
(:mod:`~kbcli.core.adaptation.grid`), suggests the next touch by its strategy
(:mod:`~kbcli.core.adaptation.strategies`), multiplies in each observed touch by its kind of
posterior (:mod:`~kbcli.core.adaptation.posteriors`: the likelihood, robust or not, and the
paper's KDE), and reads its estimate by its estimator (:mod:`~kbcli.core.adaptation.estimators`).
Every part is a registry entry; the adapter never asks a part's name. It never sees the true pose.
"""
