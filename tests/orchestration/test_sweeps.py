"""Sweeps: the jobs the runs belong to, the schedule, the leaderboard (the dask executor on a
real cluster: tests/system/test_dask_sweep.py)."""

import shutil

import dagster as dg
import numpy as np
import pandas as pd
import pytest

from pwa_pipeline.config import BUNDLED_HPARAMS
from pwa_pipeline.definitions import defs
from pwa_pipeline.methods import METHODS
from pwa_pipeline.orchestration.definitions import partitions_of
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.jobs import LEADERBOARD, SCHEDULER_ENV, build_jobs
from pwa_pipeline.orchestration.partitions import all_keys
from pwa_pipeline.orchestration.reporting import leaderboard_markdown
from pwa_pipeline.scoring.comparison import leaderboard

from .._results import materialization

KEYS = ["hure_vasak|paper", "hure_vasak|default"]


def _jobs_of(asset: str) -> set[str]:
    repo = defs.get_repository_def()
    return {job.name for job in repo.get_all_jobs()
            if dg.AssetKey(asset) in job.asset_layer.selected_asset_keys}


def test_every_partitioned_asset_belongs_to_the_sweep_jobs_and_the_leaderboard_to_its_own():
    repo = defs.get_repository_def()
    partitioned = [k.to_user_string() for a in defs.assets if a.partitions_def is not None
                   for k in a.keys]
    assert len(partitioned) == len(defs.resolve_asset_graph().get_all_asset_keys()) - 1
    for asset in partitioned:
        assert _jobs_of(asset) == {"__ASSET_JOB", "sweep", "sweep_dask"}, asset
    assert _jobs_of(LEADERBOARD) == {"__ASSET_JOB", "refresh_leaderboard"}
    sweep = repo.get_job("sweep")
    assert sweep.partitions_def == partitions_of(defs)
    assert sweep.executor_def.name == "in_process"  # a UI launch costs one process start
    assert repo.get_job("sweep_dask").executor_def.name == "dask"
    assert repo.get_job("refresh_leaderboard").partitions_def is None


def test_sweep_dask_uses_a_local_cluster_unless_a_scheduler_is_configured(monkeypatch):
    def cluster():
        job = dg.Definitions(assets=list(defs.assets), jobs=build_jobs(),
                             resources=defs.resources).resolve_job_def("sweep_dask")
        config = job.get_run_config_for_partition_key(KEYS[0])  # what a launch starts from
        return config["execution"]["config"]["cluster"]

    monkeypatch.delenv(SCHEDULER_ENV, raising=False)
    assert cluster() == {"local": {"n_workers": 2, "threads_per_worker": 1}}
    monkeypatch.setenv(SCHEDULER_ENV, "tcp://127.0.0.1:8786")
    assert cluster() == {"existing": {"address": "tcp://127.0.0.1:8786"}}


def test_schedule_requests_are_sweep_runs_with_partition_keys():
    repo = defs.get_repository_def()
    schedule = repo.get_schedule_def("sweep_schedule")
    assert schedule.job_name == "sweep"
    ctx = dg.build_schedule_context(scheduled_execution_time=pd.Timestamp("2026-11-21T02:00"))
    requests = list(schedule(ctx))
    assert requests and all(r.job_name in (None, "sweep") for r in requests)
    assert {r.partition_key for r in requests} <= set(all_keys(partitions_of(defs)))
    # what the daemon launches: sweep runs tagged with the partition
    sweep = repo.get_job("sweep")
    for request in requests:
        tags = request.with_resolved_tags_and_config(
            target_definition=sweep, dynamic_partitions_requests=[],
            dynamic_partitions_store=None).tags
        assert tags["dagster/partition"] == request.partition_key


def test_leaderboard_says_what_a_searched_model_is_in_its_row():
    rows = [{"dataset": "robot", "hparams": "auto", "method": method, "mode": mode,
             "output": "mean", "nrmse": 0.6, "r2": 0.64, "diverged": False, "model": note}
            for method, note in (("pwa", "linear kept: the search stopped at its time limit "
                                         "before a switching structure beat it"),
                                 ("linear_arx", "affine: with a constant term"))
            for mode in ("one_step", "free_run")]
    table = leaderboard(pd.DataFrame(rows), list(METHODS))
    assert table["model"].tolist() == [rows[0]["model"], "affine: with a constant term"]
    cells = [[c.strip() for c in line.strip("|").split("|")]
             for line in leaderboard_markdown(table).splitlines() if line.startswith("|")]
    assert cells[2][:3] == ["1", "pwa — linear kept: the search stopped at its time limit "
                                 "before a switching structure beat it", "auto"]
    # which linear baseline it is: with a constant (another set's may have none)
    assert cells[3][:3] == ["1", "linear_arx — affine: with a constant term", "auto"]
    # scores stored before the column existed: no note, the method alone
    old = leaderboard(pd.DataFrame(rows).drop(columns="model"), list(METHODS))
    assert old["model"].tolist() == ["", ""] and "—" not in leaderboard_markdown(old)


def test_leaderboard_ranks_by_free_run_and_puts_diverged_runs_last():
    rows = []
    for method, hparams, one, free, diverged in [
            ("pwa", "paper", 0.2, 0.5, False), ("linear_arx", "paper", 0.3, 0.4, False),
            ("subspace", "paper", 0.1, 1e30, True), ("pwa", "default", 0.1, 0.4, False),
            ("linear_arx", "default", 0.3, np.nan, True)]:
        for mode, nrmse in (("one_step", one), ("free_run", free)):
            rows += [{"dataset": "sim", "hparams": hparams, "method": method, "mode": mode,
                      "output": out, "nrmse": nrmse, "r2": 1 - nrmse**2,
                      "diverged": diverged and mode == "free_run"} for out in ("y1", "mean")]
    rows.append({**rows[1], "dataset": "robot", "nrmse": 0.123456789})  # one-step mean
    rows.append({**rows[3], "dataset": "robot", "nrmse": 0.87654321})  # free-run mean
    table = leaderboard(pd.DataFrame(rows), list(METHODS))
    sim = table[table["dataset"] == "sim"]
    assert list(zip(sim["method"], sim["hparams"], sim["rank"], strict=True)) == [
        ("pwa", "default", 1), ("linear_arx", "paper", 1), ("pwa", "paper", 3),
        ("linear_arx", "default", 4), ("subspace", "paper", 4)]  # diverged: last, NaN too
    assert sim["free_run_diverged"].tolist() == [False, False, False, True, True]
    assert table["free_run_nrmse"].iloc[4] == 1e30  # the table keeps the exact value
    assert list(table["dataset"]) == ["sim"] * 5 + ["robot"]
    text = leaderboard_markdown(table, {"robot|default": ["pwa", "subspace"]})
    line = next(row for row in text.splitlines() if "subspace" in row)
    assert "≥ 10 (diverged)" in line and "≤ -99 (diverged)" in line and "1e+30" not in line
    assert "0.1235" in text and "0.8765" in text and "0.12346" not in text  # 4 digits
    assert "### sim" in text and "### robot" in text
    assert "- `robot|default`: pwa, subspace" in text


def test_the_command_line_ends_with_the_leaderboard(tmp_path, mlflow_template, monkeypatch,
                                                    capsys):
    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.cli import main

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    monkeypatch.setenv("PWA_PIPELINE_HOME", str(tmp_path))  # stores, MLflow and Dagster home
    for name in ("MLFLOW_TRACKING_URI", "PWA_HPARAMS", "PWA_DATASETS"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    assert main(["run", "--partition", "hure_vasak|paper"]) == 0
    out = capsys.readouterr().out
    summary, board = out.split("\nLeaderboard (the 1 partition(s) with results in the store, ")
    assert "hure_vasak|paper: " in summary
    others = len(all_keys(partitions_of(defs))) - 1
    assert summary.rstrip().endswith(
        f"  1 partition(s) run, all succeeded; {others} other(s) not run in this command "
        f"(`python -m pwa_pipeline partitions` lists them, `run --all` runs every one)")
    assert board.startswith(f"from this command and earlier ones; {others} have none yet)")
    rows = [line for line in board.splitlines() if line.startswith("|") and "paper" in line]
    assert sorted(row.split("|")[2].strip().split(" — ")[0] for row in rows) == sorted(METHODS)
    assert any("| linear_arx — no constant term |" in row for row in rows)  # the paper's
    assert (tmp_path / "storage" / "leaderboard.parquet").is_file()
    # the stores, with where the control models were written
    exports = tmp_path / "storage" / "exports"
    assert f"  control models   : {exports} (JSON, MPT3 scripts)" in board
    assert (exports / "hure_vasak" / "paper" / "pwa_state_space.json").is_file()
    # and it ends with the pages to open, MLflow's in its model-training view
    assert "http://127.0.0.1:3000/locations/pwa_pipeline/jobs/sweep" in board
    experiment = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}"
                              ).get_experiment_by_name("pwa-pipeline/hure_vasak").experiment_id
    assert board.endswith(f"     hure_vasak: http://127.0.0.1:5000/#/experiments/{experiment}"
                          f"/runs?workflowType=machine_learning\n")
    # its runs are listed on their jobs' pages in the UI, as the UI's own runs
    with dg.DagsterInstance.get() as instance:
        runs = instance.get_runs()
    assert sorted(r.job_name for r in runs) == ["refresh_leaderboard", "sweep"]
    assert {r.tags[".dagster/repository"] for r in runs} == {"__repository__@pwa_pipeline"}


def test_runs_launched_from_the_sweep_page_of_the_ui_are_sweep_runs(tmp_path):
    """What the UI sends when *Materialize all…* is clicked on *Jobs → sweep*: one partition
    is a run of ``sweep``, several a backfill of ``sweep``; both on the job's Runs tab."""
    from dagster_graphql.client.query import (
        LAUNCH_PARTITION_BACKFILL_MUTATION,
        LAUNCH_PIPELINE_EXECUTION_MUTATION,
    )
    from dagster_graphql.test.utils import (
        define_out_of_process_context,
        execute_dagster_graphql,
        infer_repository_selector,
    )

    workspace = tmp_path / "workspace.yaml"
    workspace.write_text("load_from:\n  - python_module:\n      module_name: "
                         "pwa_pipeline.definitions\n      location_name: pwa_pipeline\n")
    (tmp_path / "home").mkdir()
    queued = {"run_coordinator": {"module": "dagster.core.run_coordinator",
                                  "class": "QueuedRunCoordinator"}}  # runs wait, none executes
    with dg.DagsterInstance.local_temp(str(tmp_path / "home"), overrides=queued) as instance, \
            define_out_of_process_context(str(workspace), None, instance) as ctx:
        nodes = execute_dagster_graphql(
            ctx, "{ assetNodes { assetKey { path } jobNames } }").data["assetNodes"]
        jobs = {"/".join(n["assetKey"]["path"]): n["jobNames"] for n in nodes}
        # the UI launches the first job in this list unless it is on a job's own page
        assert jobs[LEADERBOARD] == ["__ASSET_JOB", "refresh_leaderboard"]
        swept = [n["assetKey"] for n in nodes if n["assetKey"]["path"] != [LEADERBOARD]]
        assert all(jobs["/".join(a["path"])] == ["__ASSET_JOB", "sweep", "sweep_dask"]
                   for a in swept)
        repository = infer_repository_selector(ctx)
        single = execute_dagster_graphql(ctx, LAUNCH_PIPELINE_EXECUTION_MUTATION, variables={
            "executionParams": {
                "selector": {**repository, "pipelineName": "sweep", "assetSelection": swept},
                "runConfigData": "{}", "mode": "default",
                "executionMetadata": {"tags": [{"key": "dagster/partition",
                                                "value": KEYS[0]}]}}})
        assert single.data["launchPipelineExecution"]["__typename"] == "LaunchRunSuccess"
        backfill = execute_dagster_graphql(ctx, LAUNCH_PARTITION_BACKFILL_MUTATION, variables={
            "backfillParams": {
                "selector": {"partitionSetName": "sweep_partition_set",
                             "repositorySelector": repository},
                "assetSelection": swept, "partitionNames": KEYS, "fromFailure": False,
                "forceSynchronousSubmission": True}}).data["launchPartitionBackfill"]
        assert backfill["__typename"] == "LaunchBackfillSuccess"
        runs = instance.get_runs(dg.RunsFilter(job_name="sweep"))  # the job's Runs tab
        assert sorted(r.tags["dagster/partition"] for r in runs) == sorted([KEYS[0], *KEYS])
        assert {r.run_id for r in runs} >= set(backfill["launchedRunIds"])
        assert not instance.get_runs(dg.RunsFilter(job_name="__ASSET_JOB"))


def test_a_leaderboard_with_nothing_scored_yet_lists_every_partition_as_missing(
        tmp_path, mlflow_template):
    from pwa_pipeline.orchestration.settings import PipelineSettings
    from pwa_pipeline.orchestration.tracking import MLflowTracker

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    resources = {"io_manager": PartitionedFileIOManager(base_dir=str(tmp_path / "storage")),
                 "settings": PipelineSettings(cache_dir=str(tmp_path / "cache"),
                                              hparams_path=str(BUNDLED_HPARAMS)),
                 "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")}
    board = dg.materialize(list(defs.assets), selection=[LEADERBOARD], resources=resources)
    assert board.success and board.asset_value(LEADERBOARD).empty
    meta = materialization(board, LEADERBOARD).metadata
    assert meta["partitions_scored"].value == 0
    assert meta["partitions_missing"].value == len(all_keys(partitions_of(defs)))
    assert "No partition has been materialised yet." in meta["leaderboard"].value


def test_the_leaderboard_is_requested_after_a_partitions_scores_change(tmp_path, mlflow_template):
    """The automation condition: nothing to refresh on an empty instance; a materialised
    partition's scores request one leaderboard run; then nothing more until they change."""
    from pwa_pipeline.orchestration.jobs import LEADERBOARD_SENSOR
    from pwa_pipeline.orchestration.settings import PipelineSettings
    from pwa_pipeline.orchestration.tracking import MLflowTracker

    [sensor] = [s for s in defs.sensors if s.name == LEADERBOARD_SENSOR]
    assert sensor.default_status == dg.DefaultSensorStatus.RUNNING  # never stale
    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    resources = {"io_manager": PartitionedFileIOManager(base_dir=str(tmp_path / "storage")),
                 "settings": PipelineSettings(cache_dir=str(tmp_path / "cache"),
                                              hparams_path=str(BUNDLED_HPARAMS)),
                 "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")}
    board = dg.AssetKey(LEADERBOARD)
    with dg.instance_for_test() as instance:
        first = dg.evaluate_automation_conditions(defs=defs, instance=instance)
        assert first.get_num_requested(board) == 0
        swept = dg.AssetSelection.all() - dg.AssetSelection.assets(board)
        assert dg.materialize(list(defs.assets), selection=swept,
                              partition_key="hure_vasak|paper", resources=resources,
                              instance=instance).success
        after = dg.evaluate_automation_conditions(defs=defs, instance=instance,
                                                  cursor=first.cursor)
        assert after.get_num_requested(board) == 1
        again = dg.evaluate_automation_conditions(defs=defs, instance=instance,
                                                  cursor=after.cursor)
        assert again.get_num_requested(board) == 0


def test_a_truncated_or_edited_scores_file_is_named_and_left_out_not_fatal(
        tmp_path, mlflow_template):
    """A stored scores file cut short (``ArrowInvalid: magic bytes not found``) or edited
    (a better NRMSE written in) is named and left out of the leaderboard, as a partition not
    materialised, instead of failing it on every later run or being ranked as it says; a
    step reading it alone fails naming it, and materialising the partition again heals it."""
    from pwa_pipeline.orchestration.settings import PipelineSettings
    from pwa_pipeline.orchestration.signed_pickles import UnsignedFileError
    from pwa_pipeline.orchestration.tracking import MLflowTracker

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    store = PartitionedFileIOManager(base_dir=str(tmp_path / "storage"))
    resources = {"io_manager": store,
                 "settings": PipelineSettings(cache_dir=str(tmp_path / "cache"),
                                              hparams_path=str(BUNDLED_HPARAMS)),
                 "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")}
    scores = pd.DataFrame([{"mode": mode, "output": out, "nrmse": 0.5, "r2": 0.75,
                            "diverged": False} for mode in ("one_step", "free_run")
                           for out in ("y1", "mean")])
    for key in KEYS:
        for method in METHODS:
            store.handle_output(dg.build_output_context(
                asset_key=dg.AssetKey(f"{method}_scores"), partition_key=key), scores)
    folder = tmp_path / "storage" / "pwa_scores" / "hure_vasak"
    cut, edited = folder / "paper.parquet", folder / "default.parquet"
    cut.write_bytes(cut.read_bytes()[:100])
    scores.assign(nrmse=0.01).to_parquet(edited, index=False)
    for path, key in ((cut, KEYS[0]), (edited, KEYS[1])):
        with pytest.raises(UnsignedFileError, match=f"{path}.*Materialise the asset "
                                                    r"\(its partition\) again"):
            store.load(dg.AssetKey("pwa_scores"), key)
    instance = dg.DagsterInstance.ephemeral()
    board = dg.materialize(list(defs.assets), selection=[LEADERBOARD], resources=resources,
                           instance=instance)
    assert board.success
    meta = materialization(board, LEADERBOARD).metadata
    assert meta["partitions_missing"].value == len(all_keys(partitions_of(defs)))
    assert 0.01 not in board.asset_value(LEADERBOARD)["free_run_nrmse"].tolist()
    warned = "\n".join(e.user_message for e in instance.all_logs(board.run_id))
    assert str(cut) in warned and str(edited) in warned
    store.handle_output(dg.build_output_context(asset_key=dg.AssetKey("pwa_scores"),
                                                partition_key=KEYS[0]), scores)
    assert store.load(dg.AssetKey("pwa_scores"), KEYS[0]).equals(scores)
