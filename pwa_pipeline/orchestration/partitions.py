"""The partitions: data set × hyper-parameter set, keys like ``"kuka_robot|paper"``."""

import sys

import dagster as dg

from ..config import HParamsFile
from ..datasets import DATASETS, default_kuka_path
from ..datasets.kuka import find_kuka

#: What ``python -m pwa_pipeline run`` materialises unless told otherwise.
DEFAULT_SETS = ("paper", "default")


def build_partitions(hparams: HParamsFile) -> dg.MultiPartitionsDefinition:
    """Every data set × every set of ``hparams`` (the same file the resource reads)."""
    return dg.MultiPartitionsDefinition({
        "dataset": dg.StaticPartitionsDefinition(list(DATASETS)),
        "hparams": dg.StaticPartitionsDefinition(hparams.sets),
    })


def split_key(key: str | dg.MultiPartitionKey) -> tuple[str, str]:
    """(dataset, hparams) of a partition key such as ``"kuka_robot|paper"``.

    A key can arrive as a plain string (a run launched with only the ``dagster/partition``
    tag), so it is parsed here rather than read from ``keys_by_dimension``; dimensions are in
    alphabetical order.
    """
    parts = str(key).split("|")
    if len(parts) != 2:
        raise ValueError(f"partition key {str(key)!r} is not of the form 'dataset|hparams'")
    return parts[0], parts[1]


def check_keys(partitions_def: dg.MultiPartitionsDefinition, keys: list[str]) -> None:
    """Raise a ValueError naming the first key that is not a partition, and the valid ones."""
    known = set(all_keys(partitions_def))
    for key in keys:
        if key not in known:
            dims = {d.name: d.partitions_def.get_partition_keys()
                    for d in partitions_def.partitions_defs}
            raise ValueError(
                f"unknown partition {key!r}; partitions are 'dataset|hparams' with dataset in "
                f"{dims['dataset']} and hparams in {dims['hparams']}"
            )


def all_keys(partitions_def: dg.MultiPartitionsDefinition) -> list[str]:
    """Every partition key, as strings."""
    return [str(k) for k in partitions_def.get_partition_keys()]


def unavailable_datasets() -> dict[str, str]:
    """The data sets whose files are missing, with the reason (the simulated one never is)."""
    if find_kuka() is not None:
        return {}
    return {"kuka_robot": f"no KUKA data at {default_kuka_path()} (set PWA_KUKA_DATA)"}


def default_keys(partitions_def: dg.MultiPartitionsDefinition) -> list[str]:
    """``<dataset>|<set>`` for :data:`DEFAULT_SETS` and the available data sets (a note on
    stderr says why any is left out)."""
    missing = unavailable_datasets()
    for dataset, reason in missing.items():
        print(f"note: {dataset} partitions left out: {reason}", file=sys.stderr)
    datasets = [d for d in DATASETS if d not in missing]
    known = set(all_keys(partitions_def))
    return [k for k in (f"{ds}|{hp}" for ds in datasets for hp in DEFAULT_SETS) if k in known]
