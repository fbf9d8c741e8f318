"""Scores (NRMSE, R², eq. 21–24), the evaluation protocol, and comparison tables."""

from .evaluation import Evaluation, evaluate
from .metrics import match_submodels, nrmse, r2_score, rmse

__all__ = ["Evaluation", "evaluate", "match_submodels", "nrmse", "r2_score", "rmse"]
