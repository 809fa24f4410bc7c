"""The robot's model of the instrument, M_INST = p(sound, action), and how it is learned (paper
Sect. III-A, ref. [11]).

Contract: a model class (:mod:`~kbcli.core.model.classes`, a registry of scikit-learn
estimators) is fitted on where the finger landed and what was heard there
(``fit(actions, perceived)``), then answers ``predict_proba``, ``classify`` and
``sample_actions`` (p(action | sound)); the exact model is the keyboard's own geometry. Learning
by exploration (:mod:`~kbcli.core.model.explore`), the discovery of sounds
(:mod:`~kbcli.core.model.sounds`), the model's own estimate of its quality
(:mod:`~kbcli.core.model.reliability`), its score against the instrument
(:mod:`~kbcli.core.model.accuracy`) and the model rasterised for the adaptation
(:mod:`~kbcli.core.model.table`, :mod:`~kbcli.core.model.sampling`) live here.
"""
