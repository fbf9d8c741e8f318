"""The step interfaces (pwa.base): every step kind is fitted alike by PWARX.fit_step."""

import numpy as np
import pytest

from pwa_pipeline import PWARX, make_hure_vasak
from pwa_pipeline.pwa import (
    ClusterCentres,
    DBSCANClustering,
    LocalLeastSquares,
    RefinedSubModels,
    ResidualRegions,
    SVMRegions,
)
from pwa_pipeline.pwa.steps.base import BaseClustering, BaseLocalModels, BaseRegions, BaseSubModels
from pwa_pipeline.pwa.steps.submodels import output_lag_columns


def test_the_library_steps_implement_their_kinds_interface():
    assert isinstance(LocalLeastSquares(), BaseLocalModels)
    assert isinstance(DBSCANClustering(), BaseClustering)
    assert isinstance(RefinedSubModels(), BaseSubModels)
    assert isinstance(ClusterCentres(), BaseSubModels)
    assert isinstance(SVMRegions(), BaseRegions) and isinstance(ResidualRegions(), BaseRegions)
    for base in (BaseLocalModels, BaseClustering, BaseSubModels, BaseRegions):
        with pytest.raises(TypeError, match="abstract"):
            base()


class _RecordingRegions(SVMRegions):
    """The SVM's regions, recording what fit_step passes."""

    calls: list = []

    def fit(self, phi, labels, n_regions=None, sample_weight=None, **given):
        type(self).calls.append(given)
        return super().fit(phi, labels, n_regions, sample_weight)


def test_a_region_step_is_given_the_outputs_sub_models_output_lags_and_experiments():
    data = make_hure_vasak(n_samples=1500, snr_db=30.0, seed=0)
    _RecordingRegions.calls = []
    model = PWARX(na=1, nb=1, regions=_RecordingRegions()).fit(data.u_train[0], data.y_train[0])
    # step 5 fits the region step on its own too (with the labels alone); step 6 is last
    given = _RecordingRegions.calls[-1]
    assert not any(_RecordingRegions.calls[:-1])
    assert set(given) == {"target", "thetas", "output_lags", "experiment"}
    np.testing.assert_array_equal(given["thetas"], model.steps_["submodels"].thetas_)
    np.testing.assert_array_equal(given["output_lags"], output_lag_columns(2, 1, 4))
    assert given["target"].shape == (len(data.y_train[0]) - 1, 2)
    np.testing.assert_array_equal(given["experiment"], np.zeros(len(data.y_train[0]) - 1, int))


def test_the_svm_regions_ignore_what_only_residual_regions_use():
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(300, 2))
    labels = (phi[:, 0] > 0).astype(int)
    plain = SVMRegions().fit(phi, labels, 2)
    given = SVMRegions().fit(phi, labels, 2, target=rng.normal(size=(300, 1)),
                             thetas=rng.normal(size=(2, 2, 1)), output_lags=[0, -1],
                             experiment=np.zeros(300, int))
    np.testing.assert_array_equal(given.coef_, plain.coef_)
    np.testing.assert_array_equal(given.intercept_, plain.intercept_)


class _KMeansClustering(BaseClustering):
    """A step 4 of one's own: k-means on the local parameter vectors."""

    def __init__(self, n_clusters: int = 4):
        self.n_clusters = n_clusters

    def fit(self, local, target):
        from sklearn.cluster import KMeans

        theta = local.theta_.reshape(len(local.theta_), -1)
        labels = KMeans(self.n_clusters, n_init=4, random_state=0).fit_predict(theta)
        self.labels_, self.min_pts_ = labels, 10
        return self


def test_a_step_of_ones_own_that_implements_the_interface_is_used_by_pwarx():
    data = make_hure_vasak(n_samples=2000, snr_db=None, seed=1)
    model = PWARX(na=1, nb=1, clustering=_KMeansClustering(), submodels=ClusterCentres(),
                  regions=SVMRegions()).fit(data.u_train[0], data.y_train[0])
    assert isinstance(model.steps_["clustering"], _KMeansClustering)
    assert model.get_params()["clustering__n_clusters"] == 4
    assert model.n_submodels_ == 4 and np.isfinite(model.thetas_).all()
