"""The PWARX estimator and what it is built from.

[`PWARX`][pwa_pipeline.PWARX] (`estimator`) fits one shape whatever its parameters: output groups,
each with one region map and its sub-models (`groups`, `partitions`), predicted,
simulated and exported by what every ARX model shares (`arx`). Its parts, each a
sub-package or module of its own: the paper's steps 2–6 (`steps`: local models,
clustering, sub-models, regions), the model structures for machines (`structures`,
`scheduling`, `structure_fit`), the structure search of [`PWARX.auto`][pwa_pipeline.PWARX.auto]
(`search`), simulation-error training (`output_error`) and the compiled kernels
(`kernels`).
"""

from .divergence import DivergenceWarning
from .estimator import PWARX, STEPS
from .groups import OutputGroup
from .memory import FitMemoryError
from .partitions import RegionMap
from .search import SearchBudgetSpent, SearchReport, SearchTimeLimit, StructureSearch
from .steps.boundaries import ResidualRegions
from .steps.clustering import DBSCANClustering
from .steps.local_models import LocalLeastSquares
from .steps.regions import SVMRegions
from .steps.submodels import ClusterCentres, RefinedSubModels

__all__ = ["PWARX", "STEPS", "ClusterCentres", "DBSCANClustering", "DivergenceWarning",
           "FitMemoryError", "LocalLeastSquares", "OutputGroup", "RefinedSubModels",
           "RegionMap", "ResidualRegions", "SVMRegions", "SearchBudgetSpent", "SearchReport",
           "SearchTimeLimit", "StructureSearch"]
