"""Command line (``python -m pwa_pipeline``): ``run`` materialises the pipeline end to end.

Runs go to the Dagster instance in ``$DAGSTER_HOME`` (default ``<project>/.dagster_home``) and
MLflow's embedded store ``<project>/mlflow.db`` (or ``$MLFLOW_TRACKING_URI``), so the Dagster
UI (``dagster dev -w workspace.yaml``) and the MLflow UI show them afterwards.
"""

import argparse
import sys
import time

from .instance import prepare_instance
from .paths import default_storage_dir, default_tracking_uri
from .resources import mask_credentials


def run(args: argparse.Namespace) -> int:
    """Materialise the requested partitions and print their comparison tables."""
    import dagster as dg

    from ..scoring.comparison import mean_scores
    from .definitions import defs, partitions_of
    from .jobs import LEADERBOARD, SWEEP_SELECTION
    from .partitions import all_keys, check_keys, default_keys
    from .reporting import leaderboard_markdown
    from .resources import MLflowTracker

    partitions_def = partitions_of(defs)
    keys = all_keys(partitions_def) if args.all else (args.partition
                                                     or default_keys(partitions_def))
    check_keys(partitions_def, keys)  # a clear error for a mistyped key before anything runs
    instance = prepare_instance()
    home = instance.root_directory
    resources = dict(defs.resources)
    if args.tracking_uri:
        resources["mlflow"] = MLflowTracker(tracking_uri=args.tracking_uri)
    uri = mask_credentials(resources["mlflow"].uri())
    # INFO shows each step's one-line summary; Dagster's own events are DEBUG
    quiet = {"loggers": {"console": {"config": {"log_level": "INFO"}}}}
    failed = []
    summaries = []
    for key, result, t0 in _partition_runs(args, defs, keys, instance, resources, quiet,
                                           SWEEP_SELECTION):
        if not result.success:
            failed.append(key)
            summaries.append(f"{key}: FAILED after {time.perf_counter() - t0:.1f} s (run "
                             f"{result.run_id} in the Dagster UI)")
            print(summaries[-1])
            continue
        table = result.output_for_node("comparison")
        print(mean_scores(table).to_markdown(floatfmt=".4g"))
        summaries.append(_summary(key, result, table, time.perf_counter() - t0))
    print("\nSummary\n  " + "\n  ".join(summaries))
    # the leaderboard ranks every partition stored so far, not only the ones just run
    board = dg.materialize(list(defs.assets), selection=[LEADERBOARD], resources=resources,
                           instance=instance, run_config=quiet, raise_on_error=False)
    if board.success:
        meta = board.asset_materializations_for_node(LEADERBOARD)[0].metadata
        print(f"\nLeaderboard (every partition stored so far; "
              f"{meta['partitions_missing'].value} not materialised)\n")
        print(leaderboard_markdown(board.output_for_node(LEADERBOARD)), end="")
    else:
        failed.append(LEADERBOARD)
        print(f"\nLeaderboard: FAILED (run {board.run_id} in the Dagster UI)")
    experiments = "" if uri.startswith(("http://", "https://")) else \
        "      then open http://127.0.0.1:5000/#/experiments (the runs of each data set)\n"
    print(f"""
Stores
  Dagster instance : {home}
  assets           : {default_storage_dir()}
  MLflow tracking  : {uri}
Open the UIs on the same stores:
  DAGSTER_HOME={home} dagster dev -w workspace.yaml        # http://127.0.0.1:3000
  mlflow ui --backend-store-uri {uri} --workers 1          # http://127.0.0.1:5000
{experiments}""", end="")
    return 1 if failed else 0


def _partition_runs(args: argparse.Namespace, defs, keys: list[str], instance, resources: dict,
                    run_config: dict, selection):
    """``(key, result, start time)`` of each partition's run, in one process
    (``dg.materialize``) or, with ``--executor dask``, as ``sweep_dask`` runs on a dask
    cluster (a LocalCluster unless ``--scheduler``)."""
    import dagster as dg

    def announce(key: str) -> None:
        print(f"\n=== materialising {key} ===", flush=True)

    if args.executor != "dask":
        for key in keys:
            announce(key)
            t0 = time.perf_counter()
            yield key, dg.materialize(list(defs.assets), partition_key=key, selection=selection,
                                      resources=resources, instance=instance,
                                      run_config=run_config, raise_on_error=False), t0
        return
    from .dask_sweep import dask_scheduler, sweep_on_dask

    if args.tracking_uri:  # the workers build their resources from run configuration
        run_config = {**run_config,
                      "resources": {"mlflow": {"config": {"tracking_uri": args.tracking_uri}}}}
    with dask_scheduler(args.scheduler, n_workers=args.workers) as address:
        print(f"dask scheduler {address}" + ("" if args.scheduler else
              f" (a LocalCluster of {args.workers} worker processes; dashboard on port "
              f"8787 if it was free)"), flush=True)
        t0 = time.perf_counter()
        for key, result in sweep_on_dask(keys, instance, address, run_config, before=announce,
                                         io_manager=resources["io_manager"]):
            yield key, result, t0
            t0 = time.perf_counter()


def _summary(key: str, result, table, seconds: float) -> str:
    """One line per partition: sub-models found and free-run NRMSE of every method."""
    free = table[(table["mode"] == "free_run") & (table["output"] == "mean")]
    scores = ", ".join(f"{m} {v:.4g}" for m, v in zip(free["method"], free["nrmse"],
                                                      strict=True))
    model = result.output_for_node("pwa_model")
    return (f"{key}: {model.n_submodels_} PWA sub-model(s); free-run NRMSE {scores} "
            f"({seconds:.1f} s)")


def doctor(args: argparse.Namespace) -> int:
    """Report (and with ``--repair`` fix) what interrupted runs left behind; exit 1 when
    something is found and not repaired."""
    from .doctor import find_orphans, repair
    from .resources import MLflowTracker

    instance = prepare_instance()
    client = MLflowTracker(tracking_uri=args.tracking_uri).client()
    older = args.older_than * 60
    orphans = find_orphans(instance, client, [default_storage_dir()], older)
    print(f"Runs and files older than {args.older_than:g} minutes that interrupted runs left:")
    print(f"  Dagster runs still STARTED : {orphans.dagster_runs or 'none'}")
    print(f"  MLflow runs still RUNNING  : {orphans.mlflow_runs or 'none'}")
    print(f"  temporary files            : {[str(p) for p in orphans.temporary_files] or 'none'}")
    if orphans and args.repair:
        repair(orphans, instance, client, older)
        print("Repaired: Dagster runs marked failed, MLflow runs KILLED, temporary files deleted.")
        return 0
    if orphans:
        print("Run again with --repair to fix them.")
    return 1 if orphans else 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m pwa_pipeline`` and the ``pwa-pipeline`` script."""
    parser = argparse.ArgumentParser(
        prog="pwa-pipeline",
        description="Identify MIMO piecewise-affine ARX models with the Dagster pipeline.")
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser(
        "run", help="materialise every asset of the default partitions and print the "
                    "comparison (PWA vs linear ARX vs subspace, one-step and free-run)")
    p_run.add_argument("--partition", action="append", metavar="DATASET|HPARAMS",
                       help="a partition key such as 'kuka_robot|paper' (repeatable); "
                            "default: hure_vasak and kuka_robot (if its data are present) "
                            "with the 'paper' and 'default' sets")
    p_run.add_argument("--all", action="store_true", help="every partition (the full sweep)")
    p_run.add_argument("--executor", choices=("in-process", "dask"), default="in-process",
                       help="in-process (default): each partition one run, every step in "
                            "this process; dask: each partition one run of the sweep_dask "
                            "job whose steps are tasks on a dask cluster (a LocalCluster "
                            "started here, or --scheduler); partitions run one at a time")
    p_run.add_argument("--scheduler", default="", metavar="ADDRESS",
                       help="address of a running dask scheduler, e.g. tcp://10.0.0.5:8786 "
                            "(implies --executor dask; its workers need pwa-pipeline installed "
                            "and the same stores)")
    p_run.add_argument("--workers", type=int, default=2, metavar="N",
                       help="worker processes of the LocalCluster (default 2)")
    p_run.add_argument("--tracking-uri", default="",
                       help=f"MLflow tracking URI (default: "
                            f"{mask_credentials(default_tracking_uri())})")
    sub.add_parser("partitions", help="list the partition keys")
    p_doc = sub.add_parser(
        "doctor", help="list Dagster runs left STARTED, MLflow runs left RUNNING and temporary "
                       "files left by interrupted runs; --repair marks the runs failed/killed "
                       "and deletes the files")
    p_doc.add_argument("--repair", action="store_true", help="fix what is found")
    p_doc.add_argument("--older-than", type=float, default=60.0, metavar="MINUTES",
                       help="only what is older than this (a younger run may be live; "
                            "default 60)")
    p_doc.add_argument("--tracking-uri", default="", help="MLflow tracking URI (default as "
                                                          "for run)")
    args = parser.parse_args(argv)
    if args.command == "run" and args.scheduler:
        args.executor = "dask"
    if args.command == "partitions":
        from .definitions import defs, partitions_of
        from .partitions import all_keys

        print("\n".join(all_keys(partitions_of(defs))))
        return 0
    if args.command == "doctor":
        return doctor(args)
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
