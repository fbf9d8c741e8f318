"""The cross-partition ranking: the one asset that is not partitioned."""


import dagster as dg
import pandas as pd

from ...methods import METHODS
from ...scoring.comparison import leaderboard as leaderboard_table
from ..io_manager import ALL_PARTITIONS
from ..jobs import LEADERBOARD
from ..partitions import PartitionKey
from ..reporting import (
    leaderboard_markdown,
)
from ..tracking import MLflowTracker

#: Refresh when any partition's scores were updated since the last tick, unless a refresh or a
#: run upstream is in progress: after every sweep run, from the command line or the UI, once
#: the automation sensor ``jobs.LEADERBOARD_SENSOR`` is turned on.
REFRESH = (dg.AutomationCondition.any_deps_updated() & ~dg.AutomationCondition.in_progress()
           & ~dg.AutomationCondition.any_deps_in_progress())


def leaderboard_asset(partitions_def):
    @dg.asset(name=LEADERBOARD, group_name="comparison", kinds={"pandas", "mlflow"},
              ins={f"{name}_scores": dg.AssetIn(metadata={ALL_PARTITIONS: True})
                   for name in METHODS},
              automation_condition=REFRESH)
    def leaderboard(context: dg.AssetExecutionContext, mlflow: MLflowTracker,
                    **scores: dict) -> pd.DataFrame:
        """Every data set × hyper-parameter set × method, one-step and free run, ranked by
        free-run NRMSE within each data set: read from the stored ``<method>_scores`` of
        every partition materialised so far (the others are listed as missing), shown here
        and logged to MLflow (``leaderboard.csv`` and ``.md``, one run per data set in its
        experiment)."""
        keys = [str(k) for k in
                partitions_def.get_partition_keys(dynamic_partitions_store=context.instance)]
        stacked, missing = [], {}
        for key in keys:
            part = PartitionKey.parse(key)
            absent = [m for m in METHODS if key not in scores[f"{m}_scores"]]
            if absent:
                missing[key] = absent
            stacked += [scores[f"{m}_scores"][key].assign(dataset=part.dataset, hparams=part.hparams,
                                                          method=m)
                        for m in METHODS if m not in absent]
        if not stacked:
            context.log.warning("leaderboard: no partition has scores yet")
            table = leaderboard_table(pd.DataFrame(columns=[
                "dataset", "hparams", "method", "mode", "output", "nrmse", "r2", "diverged"]),
                list(METHODS))
        else:
            table = leaderboard_table(pd.concat(stacked, ignore_index=True), list(METHODS))
        text = leaderboard_markdown(table, missing)
        links = {}
        for dataset, rows in table.groupby("dataset", sort=False):
            scored = rows[~rows["free_run_diverged"]]["free_run_nrmse"]
            run = mlflow.log_run(
                dataset=dataset, hparams="all", method=LEADERBOARD, run_name=LEADERBOARD,
                params={"partitions": ", ".join(dict.fromkeys(
                    str(PartitionKey(dataset, h)) for h in rows["hparams"]))},
                metrics={"rows": len(rows), "best_free_run_nrmse":
                         float(f"{scored.min():.4g}") if len(scored) else None},
                tags={"dagster_run_id": context.run.run_id},
                artifacts={"leaderboard.csv": rows.reset_index(drop=True),
                           "leaderboard.md": leaderboard_markdown(rows)})
            links[f"mlflow_run {dataset}"] = dg.MetadataValue.url(mlflow.run_url(run))
        context.log.info(f"leaderboard: {len(table)} rows ranking the {len(keys) - len(missing)} "
                         f"partition(s) with results in the store ({len(missing)} of "
                         f"{len(keys)} have none yet, or not every method's)")
        context.add_output_metadata({
            "leaderboard": dg.MetadataValue.md(text), "rows": len(table),
            "partitions_scored": len(keys) - len(missing), "partitions_missing": len(missing),
            "missing": ", ".join(missing) or "none", **links})
        return table

    return leaderboard
