"""The identification pipeline as software-defined assets.

configuration, raw_benchmark → regressors → local_models → clusters → sub_models →
svm_regions → output_error_refinement (a no-op unless the set asks for it) → pwa_model →
control_model (its PWA state-space form, logged with the PWA scores); linear_arx_model and
subspace_model beside it; each model scored by ``<method>_scores``
(the evaluation protocol, one MLflow run each); ``comparison`` puts them side by side.
Every asset is partitioned by data set × hyper-parameter set, and every partition's
configuration is resolved once, by the ``configuration`` asset; only ``leaderboard`` is
not: it ranks the stored scores of every partition. Methods come from
``pwa_pipeline.methods.METHODS``.
"""

import dagster as dg

from ...methods import METHODS
from .baselines import baseline_model_asset
from .control import control_model_asset
from .identification import identification_assets
from .leaderboard import leaderboard_asset
from .scores import comparison_asset, scores_asset


def build_assets(partitions_def: dg.PartitionsDefinition) -> list[dg.AssetsDefinition]:
    """Every asset of the pipeline on ``partitions_def``: the partitioned ones, then the
    unpartitioned ``leaderboard``."""
    baselines = [m for m in METHODS.values() if m.name != "pwa"]
    return [*identification_assets(partitions_def),
            control_model_asset(partitions_def),
            *(baseline_model_asset(m, partitions_def) for m in baselines),
            *(scores_asset(m, partitions_def) for m in METHODS.values()),
            comparison_asset(partitions_def), leaderboard_asset(partitions_def)]
