"""pwa-pipeline: identification of MIMO piecewise-affine ARX models.

The numerical core (`pwa_pipeline.pwa`, `pwa_pipeline.baselines`,
`pwa_pipeline.scoring`, `pwa_pipeline.datasets`, `pwa_pipeline.config`)
depends only on numpy, scipy, scikit-learn and pandas; everything that imports Dagster or
MLflow lives in `pwa_pipeline.orchestration`.
"""

from importlib.metadata import PackageNotFoundError, version

from .baselines import LinearARX, SubspaceSS
from .datasets import load_kuka, load_table, make_hure_vasak
from .pwa import PWARX
from .scoring import evaluate

try:
    __version__ = version("pwa-pipeline")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["PWARX", "LinearARX", "SubspaceSS", "evaluate", "load_kuka", "load_table",
           "make_hure_vasak", "__version__"]
