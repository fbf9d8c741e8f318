"""The named data sets the pipeline and benchmarks use, each split into training and held-out
experiments."""

import os
from dataclasses import dataclass

from .._typing import Float2D
from .kuka import load_kuka
from .simulated import make_hure_vasak


@dataclass(frozen=True)
class Dataset:
    """Training and held-out experiments of one data set, with channel names."""

    name: str
    u_train: list[Float2D]
    y_train: list[Float2D]
    u_test: list[Float2D]
    y_test: list[Float2D]
    u_names: list[str]
    y_names: list[str]

    @property
    def n_train(self) -> int:
        """Training samples."""
        return sum(len(u) for u in self.u_train)

    @property
    def n_test(self) -> int:
        """Held-out samples."""
        return sum(len(u) for u in self.u_test)


DATASETS = ("hure_vasak", "kuka_robot")


def load_dataset(name: str, kuka_path: str | os.PathLike | None = None, seed: int = 0) -> Dataset:
    """A named data set with its training and held-out parts.

    ``hure_vasak``: the section 5 system at 30 dB, N = 4000, ``seed`` for training and a fresh
    record (seed + 1000) for validation. ``kuka_robot``: :func:`load_kuka` (train / test).
    """
    if name == "hure_vasak":
        train, test = make_hure_vasak(seed=seed), make_hure_vasak(seed=seed + 1000)
        return Dataset(name, [train.u], [train.y], [test.u], [test.y], train.u_names,
                       train.y_names)
    if name == "kuka_robot":
        r = load_kuka(kuka_path)
        return Dataset(name, r.u_train, r.y_train, r.u_test, r.y_test, r.u_names, r.y_names)
    raise ValueError(f"unknown data set {name!r}; known: {list(DATASETS)}")
