"""pwa-pipeline: identification of MIMO piecewise-affine ARX models.

The numerical core (this package's top-level modules) depends only on numpy, scipy and
scikit-learn; the Dagster/MLflow orchestration lives in :mod:`pwa_pipeline.pipeline`.
"""

from .identification import PWARX

__all__ = ["PWARX"]
__version__ = "0.1.0"
