"""scikit-learn's estimator checks that apply to a time-series estimator.

The others call ``predict(X)`` or ``transform(X)`` with the inputs alone; prediction here needs
past outputs (``predict(u, y)``), so they do not apply. The step objects are fitted on other
steps' results (e.g. ``DBSCANClustering.fit(local, target)``), so only the checks on
parameters apply to them.
"""

import pytest
from sklearn.utils import estimator_checks as ec

from pwa_pipeline import PWARX, LinearARX, SubspaceSS
from pwa_pipeline.pwa import (
    ClusterCentres,
    DBSCANClustering,
    LocalLeastSquares,
    RefinedSubModels,
    SVMRegions,
)

PARAMETER_CHECKS = [
    ec.check_no_attributes_set_in_init,
    ec.check_parameters_default_constructible,
    ec.check_get_params_invariance,
    ec.check_set_params,
    ec.check_do_not_raise_errors_in_init_or_set_params,
    ec.check_estimator_cloneable,
    ec.check_estimator_repr,
    ec.check_mixin_order,
    ec.check_valid_tag_types,
    ec.check_estimator_tags_renamed,
]
FIT_CHECKS = [
    ec.check_dont_overwrite_parameters,
    ec.check_estimators_overwrite_params,
    ec.check_fit_score_takes_y,
]
ESTIMATORS = [PWARX(), PWARX.default(na=1, nb=1), LinearARX(), SubspaceSS(horizon=3)]
STEPS = [LocalLeastSquares(), DBSCANClustering(), RefinedSubModels(), ClusterCentres(),
         SVMRegions()]


def _id(value):
    return getattr(value, "__name__", None) or type(value).__name__


@pytest.mark.parametrize("check", PARAMETER_CHECKS + FIT_CHECKS, ids=_id)
@pytest.mark.parametrize("estimator", ESTIMATORS, ids=_id)
def test_estimator_checks(estimator, check):
    check(type(estimator).__name__, estimator)


@pytest.mark.parametrize("check", PARAMETER_CHECKS, ids=_id)
@pytest.mark.parametrize("step", STEPS, ids=_id)
def test_step_checks(step, check):
    check(type(step).__name__, step)


def test_every_step_parameter_is_visible_and_settable():
    model = PWARX.default(na=2, nb=1)
    params = model.get_params(deep=True)
    for key in ("local_models__n_rho", "local_models__standardize", "local_models__ridge",
                "clustering__eps", "clustering__min_pts", "clustering__embedding",
                "clustering__unit_free", "clustering__confidence",
                "clustering__max_clustered", "clustering__random_state",
                "submodels__merge_tol", "submodels__copy_tol", "submodels__n_refine",
                "submodels__n_search", "regions__C"):
        assert key in params
    model.set_params(clustering__eps=0.3, regions__C=5.0)
    assert model.clustering.eps == 0.3 and model.regions.C == 5.0
    from sklearn.base import clone
    assert clone(model).get_params()["clustering__eps"] == 0.3
