"""The partitions: data set × hyper-parameter set."""

import dagster as dg

from ..config import set_names
from ..datasets import DATASETS, KUKA_FILES

dataset_partitions = dg.StaticPartitionsDefinition(list(DATASETS))
hparams_partitions = dg.StaticPartitionsDefinition(set_names())
partitions_def = dg.MultiPartitionsDefinition(
    {"dataset": dataset_partitions, "hparams": hparams_partitions}
)

#: What ``python -m pwa_pipeline run`` materialises unless told otherwise.
DEFAULT_SETS = ("paper", "default")


def split_key(key: str | dg.MultiPartitionKey) -> tuple[str, str]:
    """(dataset, hparams) of a partition key such as ``"kuka_robot|paper"``.

    A key can arrive as a plain string (a run launched with only the ``dagster/partition``
    tag), so it is parsed here rather than read from ``keys_by_dimension``.
    """
    text = str(key)
    if text not in set(partitions_def.get_partition_keys()):
        raise ValueError(
            f"unknown partition {text!r}; partitions are 'dataset|hparams' with dataset in "
            f"{list(DATASETS)} and hparams in {set_names()}"
        )
    dims = dict(zip(("dataset", "hparams"), text.split("|"), strict=True))
    return dims["dataset"], dims["hparams"]


def default_keys() -> list[str]:
    """``<dataset>|<set>`` for :data:`DEFAULT_SETS`, with ``kuka_robot`` only if its data are
    present (a note on stderr says why it is left out otherwise)."""
    import sys

    from ..datasets import default_kuka_path

    datasets = ["hure_vasak"]
    kuka = default_kuka_path()
    if any((kuka / f).is_file() for f in KUKA_FILES) or (kuka.suffix == ".mat" and kuka.is_file()):
        datasets.append("kuka_robot")
    else:
        print(f"note: kuka_robot partitions left out: no KUKA data at {kuka}", file=sys.stderr)
    return [f"{ds}|{hp}" for ds in datasets for hp in DEFAULT_SETS]


def all_keys() -> list[str]:
    """Every partition key, as strings."""
    return [str(k) for k in partitions_def.get_partition_keys()]
