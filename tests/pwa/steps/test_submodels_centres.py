"""The paper's step 5: sub-models as cluster centres (pwa.submodels.centres)."""

import numpy as np

from pwa_pipeline.config import HParamsFile
from pwa_pipeline.pwa.steps.submodels.centres import ClusterCentres, cluster_centres


def test_paper_sub_models_are_the_cluster_means(sim_30db):
    model = HParamsFile().configuration("paper", "hure_vasak").pwa.fit(sim_30db.u_train[0],
                                                                       sim_30db.y_train[0])
    theta, labels = model.steps_["local_models"].theta_, model.steps_["clustering"].labels_
    assert model.n_submodels_ == labels.max() + 1 >= 2
    for i in range(model.n_submodels_):
        members = theta[labels == i]
        np.testing.assert_allclose(model.thetas_[i], members.sum(axis=0) / len(members),
                                   rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(model.steps_["submodels"].labels_, labels)


def test_cluster_centres_are_the_mean_local_model_of_each_cluster():
    theta = np.arange(24.0).reshape(6, 2, 2)
    labels = np.array([1, 0, 1, 0, 2, 1])
    centres = cluster_centres(theta, labels)
    assert centres.shape == (3, 2, 2)
    np.testing.assert_array_equal(centres[0], (theta[1] + theta[3]) / 2)
    np.testing.assert_array_equal(centres[1], (theta[0] + theta[2] + theta[5]) / 3)
    np.testing.assert_array_equal(centres[2], theta[4])


def test_noise_rows_keep_their_label_and_weigh_in_no_centre():
    """ClusterCentres averages θ_k over the clustered rows only; a row DBSCAN labelled −1
    (here with NaN θ_k, as a sample without a local model) stays −1 and moves no centre."""
    from types import SimpleNamespace

    theta = np.array([[[1.0]], [[3.0]], [[np.nan]], [[10.0]], [[-5.0]]])
    labels = np.array([0, 0, -1, 1, -1])
    step = ClusterCentres().fit(None, None, SimpleNamespace(theta_=theta),
                                SimpleNamespace(labels_=labels))
    np.testing.assert_array_equal(step.thetas_[:, 0, 0], [2.0, 10.0])
    np.testing.assert_array_equal(step.labels_, labels)
    assert step.weights_ is None and step.n_submodels_ == 2
    assert step.n_merged_ == step.n_split_ == step.n_iter_ == 0
