"""Figures of fitted models and their scores, in the manner of scikit-learn's displays: each
``…Display`` computes what it draws from a fitted model (or an evaluation, a state-space
model), draws it with `plot` into a matplotlib figure (``figure_``, built without
pyplot), and is usable from a notebook as the pipeline uses it. matplotlib is imported only
when a figure is drawn (``pip install pwa-pipeline[plot]``).
"""

from .clusters import ParameterClustersDisplay
from .partition import PartitionDisplay
from .prediction import PredictionDisplay
from .regions import RegionsDisplay
from .style import context_title
from .switching import SwitchingDisplay

__all__ = ["ParameterClustersDisplay", "PartitionDisplay", "PredictionDisplay",
           "RegionsDisplay", "SwitchingDisplay", "context_title"]
