"""The paper's step 5: sub-models as the centres of the clusters of local models."""

import numpy as np
from sklearn.base import _fit_context

from ...._typing import Float2D
from ..base import BaseSubModels


def cluster_centres(local_theta: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """The paper's sub-models: the mean local θ_k of each cluster (step 5).

    Parameters
    ----------
    local_theta : ndarray of shape (n, d, m)
        θ_k of the clustered samples (eq. 6).
    labels : ndarray of shape (n,)
        Their clusters 0 … s−1.

    Returns
    -------
    ndarray of shape (s, d, m)
    """
    s = int(labels.max()) + 1
    return np.stack([local_theta[labels == i].mean(axis=0) for i in range(s)])


class ClusterCentres(BaseSubModels):
    """The paper's step 5: each sub-model θ_i is the mean of the local θ_k of cluster i.

    Rows of local models DBSCAN labelled noise keep the label −1 (the region SVM leaves them
    out). No parameters.

    Attributes
    ----------
    thetas_ : ndarray of shape (s, d, m)
    labels_ : ndarray of shape (n,)
        DBSCAN's cluster of each row (−1: noise).
    weights_ : None
        Every clustered row weighs alike in the region SVM.
    n_submodels_ : int
    n_merged_, n_split_, n_iter_ : int
        0 (nothing is merged, split or refined).
    """

    _parameter_constraints: dict = {}

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, phi: Float2D, target: Float2D, local, clustering, regions=None
            ) -> "ClusterCentres":
        """Average the fitted ``local`` models (``theta_``) over ``clustering.labels_``.

        ``phi``, ``target`` and ``regions`` are not used; the signature is that of every
        sub-model step.
        """
        self.labels_ = clustering.labels_
        clustered = self.labels_ >= 0
        self.thetas_ = cluster_centres(local.theta_[clustered], self.labels_[clustered])
        self.weights_ = None
        self.n_submodels_ = self.thetas_.shape[0]
        self.n_merged_ = self.n_split_ = self.n_iter_ = 0
        return self
