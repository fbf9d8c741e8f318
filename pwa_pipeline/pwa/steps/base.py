"""The interfaces of the steps [`PWARX`][pwa_pipeline.PWARX] runs (paper steps 2–6).

Each step kind is an abstract scikit-learn estimator whose ``fit`` takes what the steps
before it produced, so that the estimator calls every step of a kind alike. A step object of
one's own subclasses the base of its kind and implements its abstract methods; its
parameters follow scikit-learn's conventions (``__init__`` stores them, fitted attributes end
in ``_``). A region step is also a region map ([`RegionMap`][pwa_pipeline.pwa.RegionMap]):
with ``fit``, ``predict`` and ``halfspaces`` it predicts, simulates and exports to state space
as the built-in ones do.
"""

from abc import ABCMeta, abstractmethod

import numpy as np
from sklearn.base import BaseEstimator

from ..._typing import Float2D
from ..partitions import Halfspaces, RegionMap


class BaseLocalModels(BaseEstimator, metaclass=ABCMeta):
    """Steps 2–3: a local set around every regressor φ(k) and its parameter matrix θ_k
    (eq. 6–7).

    Attributes
    ----------
    theta_ : ndarray of shape (n, d, m)
        θ_k of every sample (NaN where not estimated).
    residual_var_ : ndarray of shape (n, m)
        Residual variance of each local fit.
    estimated_ : ndarray of shape (n,), bool
        The samples whose local model was estimated.
    """

    @abstractmethod
    def fit(self, phi: Float2D, target: Float2D) -> "BaseLocalModels":
        """Estimate the local models.

        Parameters
        ----------
        phi : ndarray of shape (n, d)
            Regressors φ(k) (eq. 2–3).
        target : ndarray of shape (n, m)
            Outputs y(k).
        """


class BaseClustering(BaseEstimator, metaclass=ABCMeta):
    """Step 4: clusters of the local models (eq. 8–10).

    Attributes
    ----------
    labels_ : ndarray of shape (n,)
        Cluster of each sample's local model, −1 for noise and for local models left out.
    min_pts_ : int
        The MinPts used (the sub-model steps size their sub-models by it).
    """

    @abstractmethod
    def fit(self, local: BaseLocalModels, target: Float2D) -> "BaseClustering":
        """Cluster the local models of the fitted step ``local``.

        Parameters
        ----------
        local : fitted BaseLocalModels
        target : ndarray of shape (n, m)
            Outputs y(k) (for unit-free parameters).
        """


class BaseRegions(RegionMap, BaseEstimator, metaclass=ABCMeta):
    """Step 6: the regions H_i of a partition of the regressor space (eq. 1).

    ``fit`` takes the labelled rows and, by keyword, what a region step may also use: the
    outputs and step 5's sub-models (to place boundaries by the residuals), the output-lag
    columns of φ and the experiment of each row. A step that does not use them ignores them.

    Attributes
    ----------
    n_regions_ : int
    """

    @abstractmethod
    def fit(self, phi: Float2D, labels: np.ndarray, n_regions: int | None = None,
            sample_weight: np.ndarray | None = None, *, target: Float2D | None = None,
            thetas: np.ndarray | None = None, output_lags: np.ndarray | None = None,
            experiment: np.ndarray | None = None) -> "BaseRegions":
        """Fit the regions on the labelled rows.

        Parameters
        ----------
        phi : ndarray of shape (n, d)
        labels : ndarray of shape (n,)
            Sub-model index 0 … s−1 of each row, or −1 (left out).
        n_regions : int, optional
            s (default: the largest label + 1).
        sample_weight : ndarray of shape (n,), optional
            Weight of each row; rows weighted 0 are left out.
        target : ndarray of shape (n, m), optional
            y(k) of each row.
        thetas : ndarray of shape (s, d, m), optional
            The sub-models, one per region.
        output_lags : ndarray of shape (d,), optional
            Output of each column of φ, −1 for the others
            (`output_lag_columns`).
        experiment : ndarray of shape (n,), optional
            Experiment of each row (rows in time order within each).
        """

    @abstractmethod
    def predict(self, phi: Float2D) -> np.ndarray:
        """The region 0 … s−1 of each row of ``phi``."""

    @abstractmethod
    def halfspaces(self) -> list[Halfspaces]:
        """Each region as rows (G, q) of G φ ≤ q (None: never chosen), for the state-space
        form ([`RegionMap.halfspaces`][pwa_pipeline.pwa.RegionMap.halfspaces])."""


class BaseSubModels(BaseEstimator, metaclass=ABCMeta):
    """Step 5: one parameter matrix θ_i per sub-model, and the rows that train the regions.

    Attributes
    ----------
    thetas_ : ndarray of shape (s, d, m)
    labels_ : ndarray of shape (n,)
        Sub-model of every row (−1: left out of the regions' fit).
    weights_ : ndarray of shape (n,) or None
        Weight of each row in the regions' fit (None: all alike).
    n_submodels_, n_merged_, n_split_, n_iter_ : int
    """

    @abstractmethod
    def fit(self, phi: Float2D, target: Float2D, local: BaseLocalModels,
            clustering: BaseClustering, regions: BaseRegions | None = None
            ) -> "BaseSubModels":
        """Estimate the sub-models.

        Parameters
        ----------
        phi : ndarray of shape (n, d)
        target : ndarray of shape (n, m)
        local : fitted BaseLocalModels
        clustering : fitted BaseClustering
        regions : unfitted BaseRegions, optional
            The region step (step 6), for a step that keeps its rows region-consistent.
        """
