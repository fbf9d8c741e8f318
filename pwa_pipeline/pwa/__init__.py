"""The paper's method, one module per step: regressors (eq. 2–3), local models (eq. 6–7),
the Vθ embedding (eq. 8–10), clustering (DBSCAN), sub-models (step 5), regions (step 6), and
the :class:`PWARX` estimator built from those step objects, and the structure search of
:meth:`PWARX.auto`."""

from .estimator import PWARX, STEPS
from .memory import FitMemoryError
from .search.search import SearchReport, SearchTimeLimit, StructureSearch
from .steps.boundaries import ResidualRegions
from .steps.clustering import DBSCANClustering
from .steps.local_models import LocalLeastSquares
from .steps.regions import SVMRegions
from .steps.submodels import ClusterCentres, RefinedSubModels

__all__ = ["PWARX", "STEPS", "ClusterCentres", "DBSCANClustering", "FitMemoryError",
           "LocalLeastSquares", "RefinedSubModels", "ResidualRegions", "SVMRegions",
           "SearchReport", "SearchTimeLimit", "StructureSearch"]
