"""The built-in data sets by name: what the pipeline offers as ``dataset`` partitions beside
the data sets a user registers."""

import os

from .dataset import Dataset
from .kuka import load_kuka
from .measured import MEASURED
from .simulated import make_hure_vasak

#: The built-in data sets' names.
DATASETS = ("hure_vasak", "kuka_robot", *MEASURED)


def load_dataset(name: str, kuka_path: str | os.PathLike | None = None, seed: int = 0
                 ) -> Dataset:
    """A built-in data set with its training and held-out parts.

    ``hure_vasak``: the section 5 system at 30 dB, 4,000 training samples of ``seed`` and
    4,000 held-out ones of a fresh record (seed + 1000), with its ground truth, unit-free
    ([`make_hure_vasak`][pwa_pipeline.datasets.make_hure_vasak]). ``kuka_robot``:
    [`load_kuka`][pwa_pipeline.datasets.load_kuka] (train / test), joint positions in degrees and motor
    torques in N·m. ``cascaded_tanks`` and ``emps``: the measured benchmarks of
    `pwa_pipeline.datasets.measured` (estimation / test record), from their default
    folders.

    Raises
    ------
    ValueError
        For another name (the message lists the built-in ones).
    FileNotFoundError
        When a measured data set's files are missing (naming the path and the official
        download).
    """
    if name == "hure_vasak":
        return make_hure_vasak(n_samples=4000, n_test=4000, seed=seed)
    if name == "kuka_robot":
        return load_kuka(kuka_path)
    if name in MEASURED:
        return MEASURED[name][1]()
    raise ValueError(f"unknown data set {name!r}; the built-in ones are {list(DATASETS)}")
