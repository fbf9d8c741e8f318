"""The paper's method, one module per step: regressors (eq. 2–3), local models (eq. 6–7),
the Vθ embedding (eq. 8–10), clustering (DBSCAN), sub-models (step 5), regions (step 6), and
the :class:`PWARX` estimator built from those step objects, and the structure search of
:meth:`PWARX.auto`."""

from .boundaries import ResidualRegions
from .clustering import DBSCANClustering
from .estimator import PWARX, STEPS
from .local_models import LocalLeastSquares
from .memory import FitMemoryError
from .regions import SVMRegions
from .structure_search import SearchReport, SearchTimeLimit, StructureSearch
from .submodels import ClusterCentres, RefinedSubModels

__all__ = ["PWARX", "STEPS", "ClusterCentres", "DBSCANClustering", "FitMemoryError",
           "LocalLeastSquares", "RefinedSubModels", "ResidualRegions", "SVMRegions",
           "SearchReport", "SearchTimeLimit", "StructureSearch"]
