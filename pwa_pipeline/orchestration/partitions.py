"""The partitions: data set × hyper-parameter set, keys like ``"kuka_robot|paper"``."""

from pathlib import Path

import dagster as dg

from ..config import HParamsFile
from ..datasets import DATASETS, default_kuka_path
from ..datasets.kuka import find_kuka
from .settings import PipelineSettings

#: What ``python -m pwa_pipeline run`` materialises unless told otherwise.
DEFAULT_SETS = ("paper", "default")


def build_partitions(hparams: HParamsFile, registered: list[str]
                     ) -> dg.MultiPartitionsDefinition:
    """Every data set (built-in, then the ``registered`` ones) × every set of ``hparams``
    (the same files the ``settings`` resource reads)."""
    return dg.MultiPartitionsDefinition({
        "dataset": dg.StaticPartitionsDefinition([*DATASETS, *registered]),
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


def unavailable_datasets(settings: PipelineSettings) -> dict[str, str]:
    """The data sets whose files are missing, with the reason (the simulated one never is)."""
    missing = {}
    if find_kuka(settings.kuka_path or None) is None:
        where = settings.kuka_path or default_kuka_path()
        missing["kuka_robot"] = f"no KUKA data at {where} (set PWA_KUKA_DATA)"
    registry = settings.registry()
    for name in registry.names():
        path = Path(registry.get(name).path)
        if not path.is_file():
            missing[name] = f"its file {path} is missing (registered in {registry.path})"
    return missing


def runnable_keys(partitions_def: dg.MultiPartitionsDefinition, settings: PipelineSettings,
                  sets: tuple[str, ...] | None = None) -> tuple[list[str], dict[str, str]]:
    """The partition keys that can run, data set by data set, and why the others cannot.

    Parameters
    ----------
    partitions_def : MultiPartitionsDefinition
    settings : PipelineSettings
        The resource of the same definitions (files and registry).
    sets : tuple of str, optional
        Only these hyper-parameter sets, in this order (default: every set).

    Returns
    -------
    keys : list of str
    skipped : dict
        Reason by data set (its data are missing) or by key (the set has no values for a
        data set, e.g. the paper's set for a user's data set).
    """
    dims = {d.name: d.partitions_def.get_partition_keys()
            for d in partitions_def.partitions_defs}
    hparams = settings.hparams()
    registered = set(settings.registry().names())
    skipped = unavailable_datasets(settings)
    keys = []
    for dataset in dims["dataset"]:
        if dataset in skipped:
            continue
        for hp in sets or dims["hparams"]:
            key = f"{dataset}|{hp}"
            if hp not in dims["hparams"]:
                continue
            if hparams.covers(hp, dataset, dataset in registered):
                keys.append(key)
            else:
                skipped[key] = (f"set {hp!r} has no values for {dataset!r} in {hparams.path}"
                                + (f' (add [{hp}."*"])' if dataset in registered else ""))
    return keys, skipped
