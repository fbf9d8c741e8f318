"""Command line (``python -m pwa_pipeline``): ``run`` materialises the pipeline end to end.

Runs go to the Dagster instance in ``$DAGSTER_HOME`` (default ``<project>/.dagster_home``) and
MLflow's embedded store ``<project>/mlflow.db`` (or ``$MLFLOW_TRACKING_URI``), so the Dagster
UI (``dagster dev -w workspace.yaml``) and the MLflow UI show them afterwards.
"""

import argparse
import os
import sys

from .paths import dagster_home, default_storage_dir, default_tracking_uri
from .resources import mask_credentials

DAGSTER_YAML = """telemetry:
  enabled: false
nux:
  enabled: false
"""


def _prepare_dagster_home() -> str:
    home = dagster_home()
    home.mkdir(parents=True, exist_ok=True)
    if not (home / "dagster.yaml").exists():
        (home / "dagster.yaml").write_text(DAGSTER_YAML)
    os.environ["DAGSTER_HOME"] = str(home)
    return str(home)


def run(args: argparse.Namespace) -> int:
    """Materialise the requested partitions and print their comparison tables."""
    import dagster as dg

    from ..scoring.comparison import mean_scores
    from .definitions import defs, partitions_of
    from .partitions import all_keys, check_keys, default_keys
    from .resources import MLflowTracker

    home = _prepare_dagster_home()
    partitions_def = partitions_of(defs)
    keys = all_keys(partitions_def) if args.all else (args.partition
                                                     or default_keys(partitions_def))
    check_keys(partitions_def, keys)  # a clear error for a mistyped key before anything runs
    resources = dict(defs.resources)
    if args.tracking_uri:
        resources["mlflow"] = MLflowTracker(tracking_uri=args.tracking_uri)
    uri = mask_credentials(resources["mlflow"].uri())
    instance = dg.DagsterInstance.get()
    quiet = {"loggers": {"console": {"config": {"log_level": "WARNING"}}}}
    failed = []
    for key in keys:
        print(f"\n=== materialising {key} ===", flush=True)
        result = dg.materialize(list(defs.assets), partition_key=key, resources=resources,
                                instance=instance, run_config=quiet, raise_on_error=False)
        if not result.success:
            failed.append(key)
            print(f"FAILED: {key} (see the run {result.run_id} in the Dagster UI)")
            continue
        table = result.output_for_node("comparison")
        print(mean_scores(table).to_markdown(floatfmt=".4g"))
    print(f"""
Stores
  Dagster instance : {home}
  assets           : {default_storage_dir()}
  MLflow tracking  : {uri}
Open the UIs on the same stores:
  DAGSTER_HOME={home} dagster dev -w workspace.yaml        # http://127.0.0.1:3000
  mlflow ui --backend-store-uri {uri} --workers 1          # http://127.0.0.1:5000""")
    return 1 if failed else 0


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
    p_run.add_argument("--tracking-uri", default="",
                       help=f"MLflow tracking URI (default: "
                            f"{mask_credentials(default_tracking_uri())})")
    sub.add_parser("partitions", help="list the partition keys")
    args = parser.parse_args(argv)
    if args.command == "partitions":
        from .definitions import defs, partitions_of
        from .partitions import all_keys

        print("\n".join(all_keys(partitions_of(defs))))
        return 0
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
