"""Command line (``python -m pwa_pipeline``): ``run`` materialises the pipeline end to end
(`partition_runs`); ``add-dataset``, ``list-datasets``
and ``remove-dataset`` manage the user's data sets.

Runs go to the Dagster instance in ``$DAGSTER_HOME`` (default ``<project>/.dagster_home``) and
MLflow's embedded store ``<project>/mlflow.db`` (or ``$MLFLOW_TRACKING_URI``), so the Dagster
UI (``dagster dev -w workspace.yaml``) and the MLflow UI show them afterwards.
"""

import argparse
import contextlib
import logging
import math
import os
import sys
import time
from typing import TYPE_CHECKING

from ..datasets.user import DEFAULT_TEST_FRACTION
from .credentials import mask_credentials
from .files import check_writable
from .instance import prepare_instance, retries_in_one_line
from .jobs import SCHEDULER_ENV
from .partition_runs import (
    LOCATION,
    ServiceLost,
    cli_definitions,
    run_tags,
    was_interrupted,
)
from .paths import (
    dagster_home,
    default_datasets_path,
    default_storage_dir,
    default_tracking_uri,
)
from .run_lock import exclusive_run
from .signed_pickles import signing_key

if TYPE_CHECKING:
    import dagster as dg

#: Loggers whose INFO lines are a library's own bookkeeping, not the run's ("Creating
#: initial MLflow database tables", "Updating database tables"): the command shows their
#: warnings and errors only (MLflow itself sets alembic's migration steps to WARNING).
BOOKKEEPING_LOGGERS = ("mlflow.store",)


def run(args: argparse.Namespace) -> int:
    """Materialise the requested partitions and print their comparison tables, once another
    ``run`` on the same Dagster home has ended (`exclusive_run`: this one waits and says
    so)."""
    with contextlib.ExitStack() as held:
        return _run(args, held)


def _run(args: argparse.Namespace, held: contextlib.ExitStack) -> int:
    """`run`'s body; the run lock is entered on ``held`` once the partitions and stores were
    checked (a command refused for those leaves nothing, not even the Dagster home)."""
    import dagster as dg
    from mlflow.exceptions import MlflowException

    from .dask_sweep import step_failures
    from .definitions import partitions_of
    from .jobs import LEADERBOARD, LEADERBOARD_JOB
    from .partitions import (
        DEFAULT_SETS,
        PartitionKey,
        all_keys,
        check_keys,
        check_runnable,
        runnable_keys,
    )
    from .reporting import leaderboard_markdown, mean_scores_markdown

    defs = cli_definitions(args.tracking_uri)
    partitions_def = partitions_of(defs)
    if args.partition:
        keys = args.partition
        check_keys(partitions_def, keys)  # a clear error for a mistyped key before any run
        registry = defs.resources["settings"].registry()
        for dataset in sorted({PartitionKey.parse(k).dataset for k in keys}
                              & set(registry.names())):
            registry.get(dataset)  # an entry breaking a rule made since: refused in one line
        check_runnable(keys, defs.resources["settings"])  # and for data that are not there
    else:
        keys, skipped = runnable_keys(partitions_def, defs.resources["settings"],
                                      None if args.all else DEFAULT_SETS)
        for what, reason in skipped.items():
            print(f"note: {what} left out: {reason}", file=sys.stderr)
    resources = defs.resources
    for folder, what in ((dagster_home(), "Dagster home"),
                         (resources["io_manager"].root(), "asset store"),
                         (resources["settings"].cache_root(), "cache folder")):
        check_writable(folder, what)  # before any run: a refused store leaves nothing half-done
    held.enter_context(exclusive_run(  # one run at a time per store: a second one waits
        dagster_home(), on_wait=lambda line: print(f"pwa-pipeline run: {line}",
                                                   file=sys.stderr, flush=True)))
    try:
        resources["mlflow"].check_reachable()
    except dg.Failure as exc:  # said in one line, before any run
        raise ValueError(exc.description) from None
    for store in (resources["io_manager"].root(), resources["settings"].cache_root()):
        signing_key(store)  # made here, once, before workers on other machines read the store
    instance = prepare_instance()
    home = instance.root_directory
    uri = mask_credentials(resources["mlflow"].uri())
    # INFO shows each step's one-line summary; Dagster's own events are DEBUG
    quiet = {"loggers": {"console": {"config": {"log_level": "INFO"}}}}
    failed, ended, interrupted, summaries = [], [], [], []
    held.enter_context(retries_in_one_line())
    try:
        for key, result, seconds in _partition_runs(args, defs, keys, instance, quiet):
            ended.append(key)
            if not result.success:
                failed.append(key)
                stopped = was_interrupted(result)
                summaries.append(f"{key}: {'INTERRUPTED' if stopped else 'FAILED'} after "
                                 f"{seconds:.1f} s (run {result.run_id} in the Dagster UI)"
                                 + "".join(f"\n    {reason}" for reason in
                                           step_failures(instance, result.run_id)[:3]))
                print(summaries[-1])
                if stopped and not interrupted:
                    print("interrupted: no further partition starts; the runs in flight end",
                          flush=True)
                if stopped:
                    interrupted.append(key)
                continue
            table = result.asset_value("comparison")
            print(f"\n{key}: mean over the outputs\n\n"
                  f"{mean_scores_markdown(table)}")
            summaries.append(_summary(key, result, table, seconds, instance))
    except KeyboardInterrupt:  # one that came outside a run (Dagster records those inside)
        interrupted.append(None)
    except ServiceLost:  # said in one line by main, after what was done
        _print_summary(summaries, [k for k in keys if k not in ended])
        raise
    if interrupted:
        _print_summary(summaries, [k for k in keys if k not in ended])
        return 130  # as a shell reports SIGINT; the leaderboard is left as it was
    _print_summary([*summaries,
                    _outcome(len(keys), len(failed), len(all_keys(partitions_def)))], [])
    # the leaderboard ranks every partition stored so far, not only the ones just run
    board = defs.resolve_job_def(LEADERBOARD_JOB).execute_in_process(
        instance=instance, run_config=quiet, tags=run_tags(), raise_on_error=False)
    if board.success:
        meta = board.asset_materializations_for_node(LEADERBOARD)[0].metadata
        print(f"\nLeaderboard (the {meta['partitions_scored'].value} partition(s) with "
              f"results in the store, from this command and earlier ones; "
              f"{meta['partitions_missing'].value} have none yet)\n")
        print(leaderboard_markdown(board.asset_value(LEADERBOARD)), end="")
    else:
        failed.append(LEADERBOARD)
        print(f"\nLeaderboard: FAILED (run {board.run_id} in the Dagster UI)")
    server = uri.startswith(("http://", "https://"))
    tracker = resources["mlflow"]
    serve = "" if server else (f"  mlflow ui --backend-store-uri {uri} --workers 1          "
                               f"# serves {tracker.ui_base()}\n")
    datasets = dict.fromkeys(PartitionKey.parse(key).dataset for key in keys)
    try:
        tracker.check_reachable()  # at once, where a gone server's requests would retry
        links = "".join(f"     {dataset}: {url}\n" for dataset in datasets
                        if (url := tracker.experiment_url(dataset)) is not None)
    except dg.Failure as exc:  # a tracking server gone since the start: the runs say so
        links = f"     (none: {exc.description})\n"
    except MlflowException as exc:  # one that answers its probe but not its API
        links = (f"     (none: MLflow tracking server {uri} answers its health probe but "
                 f"not its API: {str(exc).splitlines()[0]})\n")
    print(f"""
Stores
  Dagster instance : {home}
  assets           : {mask_credentials(str(resources["io_manager"].root()))}
  control models   : {resources["settings"].exports_root()} (JSON, MPT3 scripts)
  MLflow tracking  : {uri}
Open the UIs on the same stores:
  DAGSTER_HOME={home} dagster dev -w workspace.yaml        # http://127.0.0.1:3000
{serve}  then open http://127.0.0.1:3000/locations/{LOCATION}/jobs/sweep (launch partitions)
   and the runs of each data set in MLflow:
{links}""", end="")
    return 1 if failed else 0


def _partition_runs(args: argparse.Namespace, defs, keys: list[str], instance,
                    run_config: dict):
    """``(key, result, seconds)`` of each partition's run, one after the other: a ``sweep``
    run in this process, or, with ``--executor dask``, a ``sweep_dask`` run whose
    steps are tasks on a dask cluster (a LocalCluster unless ``--scheduler``). No partition
    starts after a run was interrupted (Ctrl-C)."""
    from .partition_runs import materialize_partition

    def announce(key: str) -> None:
        print(f"\n=== materialising {key} ===", flush=True)

    if args.executor != "dask":
        for key in keys:
            announce(key)
            t0 = time.perf_counter()
            result = materialize_partition(defs, key, instance, run_config)
            yield key, result, time.perf_counter() - t0
            if was_interrupted(result):
                return
        return
    from .dask_sweep import (
        check_scheduler,
        dask_scheduler,
        quiet_client_logs,
        sweep_on_dask,
        worker_run_config,
    )

    # the workers build their resources from run configuration: this process's stores
    run_config = {**run_config, **worker_run_config(defs.resources)}
    stores = [str(defs.resources["io_manager"].root()),
              str(defs.resources["settings"].cache_root())]
    with dask_scheduler(args.scheduler, n_workers=args.workers, stores=stores) as address, \
            quiet_client_logs():  # a scheduler lost is said in one line (check_scheduler)
        print(f"dask scheduler {address}" + ("" if args.scheduler else
              f" (a LocalCluster of {args.workers} worker processes; dashboard on port "
              f"8787 if it was free)"), flush=True)
        t0, runs = time.perf_counter(), sweep_on_dask(
            keys, instance, address, run_config, before=announce,
            io_manager=defs.resources["io_manager"])
        for key in keys:
            try:
                _, result = next(runs)
            except Exception:  # raised out of the run: a scheduler gone is said in one line
                check_scheduler(address, key)
                raise
            yield key, result, time.perf_counter() - t0
            if was_interrupted(result):
                return
            if not result.success:  # no further partition against a scheduler gone
                check_scheduler(address, key)
            t0 = time.perf_counter()


def _print_summary(lines: list[str], left: list[str]) -> None:
    """The command's summary: a line per partition run (and the outcome), then the
    partitions `left` that a stop (Ctrl-C, a service lost) kept from running to the end."""
    print("\nSummary\n  " + "\n  ".join(
        [*lines, *([f"not run to the end: {', '.join(left)}"] if left else [])]))


def _outcome(run: int, failed: int, total: int) -> str:
    """The summary's last line: how many partitions this command ran and how they ended, and
    that the others of the `total` were not run by it (not that they failed)."""
    ended = "all succeeded" if not failed else (
        "all failed" if failed == run else f"{run - failed} succeeded, {failed} failed")
    others = total - run
    return (f"{run} partition(s) run, {ended}" + (
        f"; {others} other(s) not run in this command (`python -m pwa_pipeline partitions` "
        f"lists them, `run --all` runs every one)" if others else ""))


def _summary(key: str, result, table, seconds: float, instance: "dg.DagsterInstance"
             ) -> str:
    """One line per partition: sub-models found (and what the model is, `model_note`) and
    free-run NRMSE of every method (a diverged run as `score_text` shows it), and
    whether the PWA model was reused (`REUSED`, read from the run's materialisation in
    ``instance``, so that a run in process and one on dask workers say it alike)."""
    import dagster as dg

    from ..scoring.evaluation import score_text
    from .assets.identification import REUSED
    from .model_facts import model_note

    free = table[(table["mode"] == "free_run") & (table["output"] == "mean")]
    scores = ", ".join(f"{m} {score_text(v, 'nrmse', d)}" for m, v, d in zip(
        free["method"], free["nrmse"], free["diverged"], strict=True))
    model = result.asset_value("pwa_model")
    note = model_note(model)
    records = instance.fetch_materializations(
        dg.AssetRecordsFilter(asset_key=dg.AssetKey("pwa_model"), asset_partitions=[key]),
        limit=1).records
    reused = f" ({REUSED})" if any(
        r.run_id == result.run_id and getattr(
            r.asset_materialization.metadata.get("fit"), "value", None) == REUSED
        for r in records) else ""
    return (f"{key}: {model.n_submodels_} PWA sub-model(s){reused}"
            f"{f' — {note}' if note else ''}; free-run NRMSE {scores} ({seconds:.1f} s)")


def add_dataset(args: argparse.Namespace) -> int:
    """Check a CSV/Parquet file and register it as a data set (nothing is registered when
    the check fails)."""
    from ..config import load_hparams
    from ..datasets.user import UserDataset, parse_units
    from .registry import DatasetRegistry

    registry = DatasetRegistry(default_datasets_path())
    spec = UserDataset(
        name=args.name, path=args.file, u=tuple(args.u), y=tuple(args.y),
        experiment=args.experiment, time=args.time,
        test_experiments=tuple(args.test_experiments or ()), test_fraction=args.test_fraction,
        na=args.na, nb=args.nb, affine=args.affine, units=parse_units(args.units))
    hparams = load_hparams()  # read and checked first: a broken file registers nothing
    data = registry.add(spec, replace=args.replace, one_record=args.no_experiment)
    sets = [s for s in hparams.sets if hparams.covers(s, spec.name, registered=True)]
    others = [s for s in hparams.sets if s not in sets]
    print(f"registered {spec.name!r} in {registry.path}\n"
          f"  file     : {spec.path}\n"
          f"  inputs   : {', '.join(spec.u)}; outputs: {', '.join(spec.y)}; na = {spec.na}, "
          f"nb = {spec.nb}, affine = {spec.affine}\n"
          f"  units    : {spec.describe_units()}\n"
          f"  training : {len(data.u_train)} experiment(s), {data.n_train:,} samples\n"
          f"  held out : {len(data.u_test)} experiment(s), {data.n_test:,} samples")
    if sets:
        print(f"  partitions: {', '.join(f'{spec.name}|{s}' for s in sets)}")
    if others:
        print(f"  sets {others} have no values for it: add a [<set>.\"*\"] or "
              f"[<set>.{spec.name}] table to {hparams.path}")
    if sets:
        print(f"Run it:  python -m pwa_pipeline run --partition '{spec.name}|{sets[0]}'")
    print("In a running Dagster UI, reload the code location (Deployment → Reload) to see it.")
    return 0


def list_datasets(args: argparse.Namespace) -> int:
    """Print the registered data sets with their columns, split, orders and units; an entry
    that breaks a rule made since it was registered is listed with the rule and the fix."""
    from pathlib import Path

    from .registry import DatasetRegistry

    registry = DatasetRegistry(default_datasets_path())
    names = registry.names()
    print(f"{len(names)} registered data set(s) in {registry.path}")
    for name in names:
        try:
            spec = registry.get(name)
        except ValueError as exc:
            print(f"  {name}: [CANNOT BE RUN] {exc}")
            continue
        split = (f"test experiments {list(spec.test_experiments)}" if spec.test_experiments
                 else f"test fraction {spec.test_fraction or DEFAULT_TEST_FRACTION:g}")
        state = "" if Path(spec.path).is_file() else "  [FILE MISSING]"
        print(f"  {name}: {spec.path}{state}\n    u = {list(spec.u)}, y = {list(spec.y)}, "
              f"experiment = {spec.experiment}, time = {spec.time}, {split}, na = {spec.na}, "
              f"nb = {spec.nb}, affine = {spec.affine}\n    units = {spec.describe_units()}")
    return 0


def remove_dataset(args: argparse.Namespace) -> int:
    """Unregister a data set; its file and any results already computed stay."""
    from .registry import DatasetRegistry

    registry = DatasetRegistry(default_datasets_path())
    file = registry.remove(args.name)
    print(f"removed {args.name!r} from {registry.path} (its file {file} and its results "
          f"in the stores are kept); reload the code location in a running Dagster UI")
    return 0


def partitions(args: argparse.Namespace) -> int:
    """Print every partition key, one per line."""
    from .definitions import build_definitions, partitions_of
    from .partitions import all_keys

    print("\n".join(all_keys(partitions_of(build_definitions()))))
    return 0


def doctor(args: argparse.Namespace) -> int:
    """Report (and with ``--repair`` fix) what interrupted runs left behind; exit 1 when
    something is found and not repaired."""
    import dagster as dg

    from .doctor import find_orphans, repair
    from .tracking import MLflowTracker, move_store_aside, store_problem

    tracker = MLflowTracker(tracking_uri=args.tracking_uri)
    if tracker.uri().startswith(("http://", "https://")):
        try:
            tracker.check_reachable()
        except dg.Failure as exc:  # said in one line, not after MLflow's retries
            raise ValueError(exc.description) from None
    instance = prepare_instance()
    broken = None
    if (db := tracker._sqlite_db()) is not None and (problem := store_problem(db)):
        if args.repair and problem.half_made:
            print(f"Moved the half-made MLflow store {db} aside to {move_store_aside(db)}; "
                  f"the next run creates a new one.")
        else:
            print(problem.message)
            broken = problem
    client = None if broken else tracker.client()
    older = args.older_than * 60
    orphans = find_orphans(instance, client, [default_storage_dir()], older)
    print("What interrupted or killed runs left (runs whose processes are gone; runs of other "
          "machines, temporary files and models left pending older than "
          f"{args.older_than:g} minutes):")
    print(f"  Dagster runs not ended     : {orphans.dagster_runs or 'none'}")
    print(f"  MLflow runs still RUNNING  : {orphans.mlflow_runs or 'none'}")
    print(f"  temporary files            : {[str(p) for p in orphans.temporary_files] or 'none'}")
    print(f"  logged models PENDING      : {orphans.pending_models or 'none'}")
    print("  model versions PENDING_REGISTRATION: "
          f"{[f'{n} version {v}' for n, v in orphans.pending_versions] or 'none'}")
    if orphans and args.repair:
        repair(orphans, instance, client, older)
        print("Repaired: Dagster runs marked failed, MLflow runs KILLED, temporary files "
              "deleted.")
        return 1 if broken else 0
    if orphans:
        print("Run again with --repair to fix them.")
    return 1 if orphans or broken else 0


def _minutes(text: str) -> float:
    """``--older-than``'s value: a finite number of minutes >= 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number of minutes >= 0, got "
                                         f"{text!r}")
    return value


def _workers(text: str) -> int:
    """``--workers``' value: a whole number of worker processes >= 1 (a LocalCluster of none
    would only wait for a worker that never comes)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number of worker processes >= 1, "
                                         f"got {text!r}")
    return value


def _os_error_line(exc: OSError) -> str:
    """An OSError that stopped a command, in one line: the file, the reason and what to do
    about it."""
    import errno

    where = f"{exc.filename}: " if exc.filename else ""
    reason = exc.strerror or str(exc) or type(exc).__name__
    if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOTDIR):
        advice = ("make it writable, or set $PWA_PIPELINE_HOME (or $DAGSTER_HOME, "
                  "$PWA_STORAGE, $PWA_DATASETS) to a folder this user can write")
    elif exc.errno in (errno.ENOSPC, errno.EDQUOT):
        advice = "free space on that disk and run again (files are replaced whole, never half)"
    else:
        advice = "check the stores' folders ($PWA_PIPELINE_HOME) and run again"
    return f"{where}{reason}; {advice}"


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m pwa_pipeline`` and the ``pwa-pipeline`` script."""
    for name in BOOKKEEPING_LOGGERS:
        logging.getLogger(name).setLevel(logging.WARNING)
    parser = argparse.ArgumentParser(
        prog="pwa-pipeline",
        description="Identify MIMO piecewise-affine ARX models with the Dagster pipeline.")
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser(
        "run", help="materialise every asset of the default partitions and print the "
                    "comparison (PWA vs linear ARX vs subspace, one-step and free-run)")
    p_run.add_argument("--partition", action="append", metavar="DATASET|HPARAMS",
                       help="a partition key such as 'kuka_robot|paper' (repeatable; one "
                            "whose data set's files are missing stops the command before any "
                            "run, saying why); default: every data set whose data are present "
                            "(built-in and registered) with the 'paper', 'default' and 'auto' "
                            "sets")
    p_run.add_argument("--all", action="store_true", help="every partition (the full sweep)")
    p_run.add_argument("--executor", choices=("in-process", "dask"), default="in-process",
                       help="in-process (default): each partition one run, every step in "
                            "this process; dask: each partition one run of the sweep_dask job "
                            "whose steps are tasks on a dask cluster (--scheduler, else "
                            "$PWA_DASK_SCHEDULER, else a LocalCluster started here). "
                            "Partitions run one after the other (on a shared scheduler, the "
                            "runs of several clients take turns); to run several at once on "
                            "one machine, launch a backfill in the Dagster UI")
    p_run.add_argument("--scheduler", default="", metavar="ADDRESS",
                       help=f"address of a running dask scheduler (`dask scheduler`), e.g. "
                            f"tcp://10.0.0.5:8786 (implies --executor dask; default with "
                            f"--executor dask: ${SCHEDULER_ENV}, else a LocalCluster). Its "
                            f"workers (`dask worker ADDRESS`) need pwa-pipeline installed and "
                            f"the same stores: $PWA_STORAGE, a folder or fsspec URL such as "
                            f"s3://bucket/pwa, the Dagster instance on PostgreSQL "
                            f"($PWA_DAGSTER_POSTGRES_URL) and an MLflow tracking server")
    p_run.add_argument("--workers", type=_workers, default=2, metavar="N",
                       help="worker processes of the LocalCluster, when no scheduler is given "
                            "(at least 1; default 2)")
    p_run.add_argument("--tracking-uri", default="",
                       help=f"MLflow tracking URI (default: "
                            f"{mask_credentials(default_tracking_uri())})")
    sub.add_parser("partitions", help="list the partition keys")
    p_add = sub.add_parser(
        "add-dataset", help="check a CSV or Parquet file and register it as a data set: it "
                            "becomes a 'dataset' partition",
        description="Check a CSV or Parquet file and register it as a data set, a new "
                    "'dataset' partition of the pipeline (with every hyper-parameter set "
                    "that has a [<set>.\"*\"] table). The whole file is read and checked "
                    "first; on any problem nothing is registered. The registry is "
                    "$PWA_DATASETS or <project>/storage/datasets.json.")
    p_add.add_argument("name", help="the data set's name (letters, digits, '_', '-')")
    p_add.add_argument("file", help="a .csv or .parquet file")
    p_add.add_argument("--u", nargs="+", required=True, metavar="COL", help="input columns")
    p_add.add_argument("--y", nargs="+", required=True, metavar="COL", help="output columns")
    records = p_add.add_mutually_exclusive_group()
    records.add_argument("--experiment", metavar="COL",
                         help="column of experiment ids (lags never span two experiments); "
                              "without it, a file with a column named like experiment ids "
                              "(run, run_id, trial, …) or a time that goes back is refused")
    records.add_argument("--no-experiment", action="store_true",
                         help="the file is one record, even if a column or its time looks "
                              "like several experiments")
    p_add.add_argument("--time", metavar="COL",
                       help="numeric or date-time column; must increase strictly within "
                            "each experiment (rows are not reordered)")
    split = p_add.add_mutually_exclusive_group()
    split.add_argument("--test-experiments", nargs="+", metavar="ID",
                       help="experiment ids held out for testing")
    split.add_argument("--test-fraction", type=float, metavar="F",
                       help=f"share held out: the last experiments in file order, or the end "
                            f"of a single record (default {DEFAULT_TEST_FRACTION})")
    p_add.add_argument("--na", type=int, default=1, help="output order (default 1)")
    p_add.add_argument("--nb", type=int, default=1, help="input order (default 1)")
    p_add.add_argument("--affine", action="store_true", help="add a constant term")
    p_add.add_argument("--units", nargs="+", metavar="NAME=UNIT",
                       help="units of input or output columns, shown on the figures' axes "
                            "(e.g. --units y1=deg u1=N·m); a column left out has none. They "
                            "change no fit or score")
    p_add.add_argument("--replace", action="store_true",
                       help="replace a data set registered under the same name")
    sub.add_parser("list-datasets", help="list the registered data sets")
    p_rm = sub.add_parser("remove-dataset",
                          help="unregister a data set (its file and results are kept)")
    p_rm.add_argument("name")
    p_doc = sub.add_parser(
        "doctor", help="list the Dagster runs (not ended) and MLflow runs (RUNNING) whose "
                       "processes are gone, the temporary files and pending MLflow models "
                       "that interrupted runs left, and a half-made MLflow store; --repair "
                       "marks the runs failed/killed and the models failed, deletes the "
                       "files and pending model versions, and moves the store aside")
    p_doc.add_argument("--repair", action="store_true", help="fix what is found")
    p_doc.add_argument("--older-than", type=_minutes, default=60.0, metavar="MINUTES",
                       help="temporary files, and runs of other machines (whose processes "
                            "cannot be seen from here), only when older than this (default "
                            "60)")
    p_doc.add_argument("--tracking-uri", default="", help="MLflow tracking URI (default as "
                                                          "for run)")
    args = parser.parse_args(argv)
    if args.command == "run" and args.scheduler:
        args.executor = "dask"
    if args.command == "run" and args.executor == "dask" and not args.scheduler:
        args.scheduler = os.environ.get(SCHEDULER_ENV, "")
    commands = {"doctor": doctor, "add-dataset": add_dataset, "list-datasets": list_datasets,
                "remove-dataset": remove_dataset, "run": run, "partitions": partitions}
    try:
        return commands[args.command](args)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"pwa-pipeline {args.command}: error: {message}", file=sys.stderr)
        return 2
    except OSError as exc:  # a store that cannot be written: read-only, full, not a folder
        print(f"pwa-pipeline {args.command}: error: {_os_error_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # before or between runs (a run records its own)
        print(f"pwa-pipeline {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
