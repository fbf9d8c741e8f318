"""The partitions: the pairs of a data set and a hyper-parameter set that has values for it,
keys like ``"kuka_robot|paper"`` (`PartitionKey`, the one place a key is joined and
split: the command line and the assets that receive Dagster's key parse it here once and pass
the typed value, or the partition's `Configuration`, on).

Only pairs that can run are offered: a set's own table for the data set, or, for a data set
a user registered, its ``[<set>."*"]`` table (see `pwa_pipeline.config`). The paper's
sets give values per data set and no rule, so ``hure_vasak|robot`` or ``<your data>|paper``
are not partitions.
"""

from dataclasses import dataclass
from pathlib import Path

import dagster as dg

from ..config import HParamsFile
from ..datasets import DATASETS, MEASURED, default_kuka_path
from ..datasets.kuka import find_kuka
from .settings import PipelineSettings

#: What ``python -m pwa_pipeline run`` materialises unless told otherwise.
DEFAULT_SETS = ("paper", "default", "auto")


@dataclass(frozen=True)
class PartitionKey:
    """One partition: a data set and a hyper-parameter set.

    Examples
    --------
    >>> key = PartitionKey.parse("kuka_robot|paper")
    >>> key.dataset, key.hparams, str(key)
    ('kuka_robot', 'paper', 'kuka_robot|paper')
    """

    dataset: str
    hparams: str

    #: Between the data set and the set in a key.
    SEPARATOR = "|"

    @classmethod
    def parse(cls, key: object) -> "PartitionKey":
        """The partition of a key such as ``"kuka_robot|paper"`` (Dagster's key, a string).

        Raises
        ------
        ValueError
            When the key is not of the form ``dataset|hparams``.
        """
        parts = str(key).split(cls.SEPARATOR)
        if len(parts) != 2 or not all(parts):
            raise ValueError(f"partition key {str(key)!r} is not of the form 'dataset|hparams'")
        return cls(*parts)

    def __str__(self) -> str:
        return f"{self.dataset}{self.SEPARATOR}{self.hparams}"


def build_partitions(hparams: HParamsFile, registered: list[str]
                     ) -> dg.StaticPartitionsDefinition:
    """``dataset|set`` for every data set (built-in, then the ``registered`` ones) and every
    set of ``hparams`` (the same file the ``settings`` resource reads) that has values for
    it, in that order."""
    return dg.StaticPartitionsDefinition([
        str(PartitionKey(dataset, name)) for dataset, user in [*((d, False) for d in DATASETS),
                                                   *((d, True) for d in registered)]
        for name in hparams.sets if hparams.covers(name, dataset, registered=user)])


def check_keys(partitions_def: dg.StaticPartitionsDefinition, keys: list[str]) -> None:
    """Raise a ValueError naming the first key that is not a partition, and the valid ones."""
    known = all_keys(partitions_def)
    for key in keys:
        if key not in known:
            raise ValueError(f"unknown partition {key!r}; the partitions are {known} (a set "
                             f"that has no values for a data set gives it no partition)")


def check_runnable(keys: list[str], settings: PipelineSettings) -> None:
    """Raise a ValueError, in one line, naming the requested partitions whose data set's files
    are missing and why (before any run, rather than a failed run's stack traces).

    Parameters
    ----------
    keys : list of str
        Partition keys, each a partition of the definitions (`check_keys`).
    settings : PipelineSettings
        The resource of the same definitions (files and registry).
    """
    missing = unavailable_datasets(settings)
    blocked: dict[str, list[str]] = {}
    for key in keys:
        dataset = PartitionKey.parse(key).dataset
        if dataset in missing:
            blocked.setdefault(dataset, []).append(key)
    if blocked:
        raise ValueError("; ".join(f"{', '.join(found)} cannot run: {missing[dataset]}"
                                   for dataset, found in blocked.items()))


def all_keys(partitions_def: dg.StaticPartitionsDefinition) -> list[str]:
    """Every partition key, as strings."""
    return [str(k) for k in partitions_def.get_partition_keys()]


def unavailable_datasets(settings: PipelineSettings) -> dict[str, str]:
    """The data sets whose files are missing, or whose registration breaks a rule made since
    it was written, with the reason (the simulated one never is)."""
    missing = {}
    if find_kuka(settings.kuka_path or None) is None:
        where = settings.kuka_path or default_kuka_path()
        missing["kuka_robot"] = f"no KUKA data at {where} (set PWA_KUKA_DATA)"
    for name, (source, _) in MEASURED.items():
        if absent := source.missing():
            missing[name] = f"no {name} data: {absent[0]} is missing (set {source.env})"
    registry = settings.registry()
    for name in registry.names():
        try:
            path = Path(registry.get(name).path)
        except ValueError as exc:
            missing[name] = str(exc)
            continue
        if not path.is_file():
            missing[name] = f"its file {path} is missing (registered in {registry.path})"
    return missing


def runnable_keys(partitions_def: dg.StaticPartitionsDefinition, settings: PipelineSettings,
                  sets: tuple[str, ...] | None = None) -> tuple[list[str], dict[str, str]]:
    """The partition keys that can run, data set by data set, and why the others cannot.

    Parameters
    ----------
    partitions_def : StaticPartitionsDefinition
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
    offered = all_keys(partitions_def)
    hparams = settings.hparams()
    registered = set(settings.registry().names())
    skipped = unavailable_datasets(settings)
    parsed = [PartitionKey.parse(k) for k in offered]
    keys = []
    for dataset in dict.fromkeys(p.dataset for p in parsed):
        if dataset in skipped:
            continue
        for name in sets or [p.hparams for p in parsed if p.dataset == dataset]:
            key = str(PartitionKey(dataset, name))
            if key in offered:
                keys.append(key)
            elif name in hparams.sets:
                skipped[key] = (f"set {name!r} has no values for {dataset!r} in {hparams.path}"
                                + (f' (add [{name}."*"])' if dataset in registered else ""))
    return keys, skipped
