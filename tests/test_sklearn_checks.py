"""scikit-learn's own estimator checks on every learned model class (``parametrize_with_checks``).

The checks that apply to a model of the pad run and must pass: parameters stored untouched by
``__init__``, ``get_params`` / ``set_params`` / ``clone``, ``fit`` returning ``self``, predicting
before fitting raising ``NotFittedError``, a refit giving the same predictions, read-only input,
... The others are listed with the reason they do not apply (a model of the pad is fitted on
where the finger landed, ``(n, 2)`` pad positions, and what was heard there, ``(n, D)`` sound
features with NaN rows for silence: it is not a classifier of ``n_features`` columns and 1-D
labels). The ``exact`` class is the keyboard's own geometry, never fitted: no estimator check
applies to it.
"""

from __future__ import annotations

import pytest
from sklearn.utils.estimator_checks import parametrize_with_checks

from kbcli.core.model.classes import MODEL_CLASSES, learned_classes

#: A model of the pad is fitted on (n, 2) pad positions and (n, D) heard features: sklearn's
#: generated data (X of 3 or more columns, y of 1-D labels or strings) is not such a sample.
PAD = ("fit(actions, perceived) takes (n, 2) pad positions and (n, D) heard features (NaN rows: "
       "silence), not X of any width and 1-D labels")
#: Eq. 2 finds the sound classes from the heard features: there is no label set to check.
SOUNDS = "the sound classes are found from the heard features (Eq. 2), not given as labels"
#: Pad positions come from the arm's proprioception: dense float pairs.
DENSE = "pad positions are dense float pairs from the arm (no sparse, complex or object input)"

REASONS = {
    "check_classifiers_classes": SOUNDS,
    "check_classifiers_one_label": SOUNDS,
    "check_classifiers_regression_target": SOUNDS,
    "check_classifiers_train": PAD,
    "check_supervised_y_2d": PAD,
    "check_requires_y_none": PAD,
    "check_fit_score_takes_y": PAD,
    "check_dict_unchanged": PAD,
    "check_dont_overwrite_parameters": PAD,
    "check_estimators_dtypes": PAD,
    "check_estimators_pickle": PAD,
    "check_f_contiguous_array_estimator": PAD,
    "check_fit2d_1sample": PAD,
    "check_fit2d_predict1d": PAD,
    "check_fit1d": PAD,
    "check_methods_sample_order_invariance": PAD,
    "check_methods_subset_invariance": PAD,
    "check_n_features_in": PAD,
    "check_n_features_in_after_fitting": PAD,
    "check_pipeline_consistency": PAD,
    "check_estimators_empty_data_messages": PAD,
    "check_estimators_nan_inf": PAD,
    "check_positive_only_tag_during_fit": PAD,
    "check_dtype_object": DENSE,
    "check_complex_data": DENSE,
    "check_estimator_sparse_array": DENSE,
    "check_estimator_sparse_matrix": DENSE,
    "check_estimator_sparse_tag": DENSE,
}


def _name(check) -> str:
    return getattr(check, "func", check).__name__


@parametrize_with_checks([MODEL_CLASSES.get(n).estimator()() for n in learned_classes()])
def test_sklearn_estimator_checks(estimator, check):
    if _name(check) in REASONS:
        pytest.skip(REASONS[_name(check)])
    check(estimator)

