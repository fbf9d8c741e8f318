"""The structure search of :meth:`PWARX.auto <pwa_pipeline.pwa.PWARX.auto>`: a machine's
model structure chosen from its data alone (:mod:`.search`)."""

from .search import (
    SEARCH_LOG,
    SearchBudgetSpent,
    SearchReport,
    SearchTimeLimit,
    StructureSearch,
)

__all__ = ["SEARCH_LOG", "SearchBudgetSpent", "SearchReport", "SearchTimeLimit",
           "StructureSearch"]
