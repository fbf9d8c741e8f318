"""Sub-model parameter matrices θ_i from clusters (paper step 5) and their refinement.

Two step objects: [`ClusterCentres`][pwa_pipeline.pwa.ClusterCentres], the paper's step 5 (`centres`), and
[`RefinedSubModels`][pwa_pipeline.pwa.RefinedSubModels], the library default (`refined`), built from
least-squares refits (`least_squares`), merging (`merge`), re-assignment by residual and region
(`reassign`) and the split search (`split_search`). Bias-compensated least
squares for noisy output lags (`bias_compensation`) serves step 6's residual
boundaries. The region estimator (step 6) is passed in by the caller, so this package
imports no other step.
"""

from .bias_compensation import bias_compensated_refit, output_lag_columns
from .centres import ClusterCentres, cluster_centres
from .least_squares import least_squares, refit
from .merge import merge_indistinguishable, separable
from .reassign import refine, theta_shift
from .refined import RefinedSubModels
from .residuals import margin_weights, robust_noise_var, unexplained_cost
from .split_search import split_gain

__all__ = ["ClusterCentres", "RefinedSubModels", "bias_compensated_refit", "cluster_centres",
           "least_squares", "margin_weights", "merge_indistinguishable", "output_lag_columns",
           "refine", "refit", "robust_noise_var", "separable", "split_gain", "theta_shift",
           "unexplained_cost"]
