"""The structure search of [`PWARX.auto`][pwa_pipeline.PWARX.auto]: a machine's
model structure chosen from its data alone (`search`)."""

from .search import (
    SEARCH_LOG,
    SearchBudgetSpent,
    SearchReport,
    SearchTimeLimit,
    StructureSearch,
)

__all__ = ["SEARCH_LOG", "SearchBudgetSpent", "SearchReport", "SearchTimeLimit",
           "StructureSearch"]
